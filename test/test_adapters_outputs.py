"""Output messages: Topology, LaneletArray, MarkerArray (rclpy and rosbags alike)."""

import copy
import math

import numpy as np
import pytest

from intersection_estimator.bagio import typestore
from intersection_estimator.sim import simulate_scenario
from msg_adapters.lanelets import lanelets_msg, read_lanelets
from msg_adapters.markers import DELETE, NAMESPACES, markers_msg
from msg_adapters.topology import read_topology, topology_msg
from msg_adapters.types import RclpyTypes, RosbagsTypes, make_header


@pytest.fixture(scope='module')
def sc():
    return simulate_scenario(5)


def both_namespaces():
    ts = typestore()
    return [('rclpy', RclpyTypes(), None), ('rosbags', RosbagsTypes(ts), ts)]


def through(ts, msg):
    if ts is None:
        return msg
    name = msg.__msgtype__
    return ts.deserialize_cdr(ts.serialize_cdr(msg, name), name)


@pytest.mark.parametrize('kind,T,ts', both_namespaces())
def test_topology_round_trip(sc, kind, T, ts):
    gt = copy.deepcopy(sc.gt)
    for k, a in enumerate(gt.arms):     # arm axis offsets travel in Arm.offset
        a.offset = 0.75 * k - 1.0
    msg = through(ts, topology_msg(T, make_header(T, 'map', 4.0), gt, samples=5000,
                                   log_posterior=-123.5, n_obs=800, state='CONVERGED'))
    info = read_topology(msg)
    assert (info.frame_id, info.samples, info.observations, info.state) == ('map', 5000, 800, 'CONVERGED')
    assert info.log_posterior == -123.5
    np.testing.assert_allclose(info.intersection.center, sc.gt.center)
    for a, b in zip(info.intersection.arms, gt.arms, strict=True):
        assert (a.lanes_in, a.lanes_out) == (b.lanes_in, b.lanes_out)
        assert (a.angle, a.gap, a.lane_width, a.offset) == pytest.approx(
            (b.angle, b.gap, b.lane_width, b.offset))
    empty = read_topology(through(ts, topology_msg(T, make_header(T, 'map', 1.0), None)))
    assert empty.intersection is None and empty.state == 'NO_DATA' and math.isnan(empty.log_posterior)


@pytest.mark.parametrize('kind,T,ts', both_namespaces())
def test_lanelets_round_trip(sc, kind, T, ts):
    back = read_lanelets(through(ts, lanelets_msg(T, make_header(T, 'map', 4.0), sc.gt_lanelets, 20000)))
    assert [ll.id for ll in back] == [ll.id for ll in sc.gt_lanelets]
    for a, b in zip(back, sc.gt_lanelets):
        assert (a.kind, a.arm, a.arm_to, a.lane_index, a.successors) == \
               (b.kind, b.arm, b.arm_to, b.lane_index, b.successors)
        np.testing.assert_allclose(a.center, b.center)
        np.testing.assert_allclose(a.left, b.left)


@pytest.mark.parametrize('kind,T,ts', both_namespaces())
def test_markers_namespaces_stable_ids_and_deletes(sc, kind, T, ts):
    hdr = make_header(T, 'map', 4.0)
    arr, keys = markers_msg(T, hdr, sc.gt, sc.gt_lanelets)
    arr = through(ts, arr)
    assert {m.ns for m in arr.markers} == set(NAMESPACES)
    assert {m.header.frame_id for m in arr.markers} == {'map'}
    assert len(keys) == len(arr.markers)                         # (ns, id) unique
    assert all(m.action == 0 and m.pose.orientation.w == 1.0 for m in arr.markers)
    n_conn = sum(ll.kind == 'connector' for ll in sc.gt_lanelets)
    assert sum(m.ns == 'connectors' for m in arr.markers) == n_conn
    assert sum(m.ns == 'arm_axes' for m in arr.markers) == len(sc.gt.arms)
    # same lanelets in another order: same keys; dropping lanelets deletes exactly theirs
    arr2, keys2 = markers_msg(T, hdr, sc.gt, list(reversed(sc.gt_lanelets)), keys)
    assert keys2 == keys and all(m.action == 0 for m in arr2.markers)
    kept = sc.gt_lanelets[:3]
    arr3, keys3 = markers_msg(T, hdr, sc.gt, kept, keys)
    deleted = {(m.ns, m.id) for m in arr3.markers if m.action == DELETE}
    assert deleted == keys - keys3 and deleted and keys3 < keys
    arr4, keys4 = markers_msg(T, hdr, None, [], keys3)
    assert keys4 == frozenset() and len(arr4.markers) == len(keys3)


def test_arrows_point_in_driving_direction(sc):
    T = RclpyTypes()
    arr, _ = markers_msg(T, make_header(T, 'map', 0.0), None, sc.gt_lanelets[:1])
    (tri,) = [m for m in arr.markers if m.ns == 'center_line_arrows']
    p = np.array([(q.x, q.y) for q in tri.points]).reshape(-1, 3, 2)
    tip, base = p[:, 0], 0.5 * (p[:, 1] + p[:, 2])
    c = sc.gt_lanelets[0].center
    d = (c[-1] - c[0]) / np.linalg.norm(c[-1] - c[0])
    assert ((tip - base) @ d > 0).all()


def test_line_strips_are_thinned_for_display_only(sc):
    """Line strips keep both ends and a vertex about every DRAW_STEP; the drawn chord of a
    5 m radius turn stays within 3 cm of the lane; ``~/lanelets`` keeps every station."""
    from msg_adapters.markers import DRAW_STEP, thin
    a = np.linspace(0.0, 0.5 * np.pi, 200)                 # 7.85 m of a 5 m radius arc
    arc = 5.0 * np.stack([np.cos(a), np.sin(a)], axis=1)
    drawn = thin(arc, DRAW_STEP)
    assert np.array_equal(drawn[0], arc[0]) and np.array_equal(drawn[-1], arc[-1])
    assert 8 <= len(drawn) <= 10
    mid = 0.5 * (drawn[1:] + drawn[:-1])                      # worst point of each chord
    assert np.all(5.0 - np.hypot(mid[:, 0], mid[:, 1]) < 0.03)
    T = RclpyTypes()
    ll = sc.gt_lanelets[0]
    arr, _ = markers_msg(T, make_header(T, 'map', 0.0), None, [ll])
    (left,) = [m for m in arr.markers if m.ns == 'left_lane_bound']
    assert len(left.points) == len(thin(np.asarray(ll.left, float), DRAW_STEP)) <= len(ll.left)
    msg = lanelets_msg(T, make_header(T, 'map', 0.0), [ll])
    assert len(msg.lanelets[0].left) == len(ll.left)
