"""SUMO scenario family (issue 15.1): deterministic per seed, ground truth = the net."""

import math

import numpy as np
import pytest

from intersection_estimator.estimate_io import dumps
from intersection_estimator.evaluate import evaluate
from intersection_estimator.scenarios import gt_doc
from intersection_estimator.scenarios.sumo import sumo_scenario
from intersection_estimator.scenarios.sumo_config import SumoConfig
from intersection_estimator.scenarios.sumo_gt import net_gt, read_net
from intersection_estimator.scenarios.sumo_net import realdata_dir

GEN = SumoConfig(ind_share=0.0, duration=(20.0, 20.0), warmup_s=25.0)


@pytest.fixture(scope='module')
def case(tmp_path_factory):
    work = tmp_path_factory.mktemp('sumo')
    return sumo_scenario(2, GEN, workdir=work), work


def test_same_seed_same_case(case, tmp_path):
    sc, _ = case
    again = sumo_scenario(2, GEN, workdir=tmp_path)
    assert dumps(gt_doc(sc)) == dumps(gt_doc(again))
    for mode in ('tracked', 'raw'):
        a, b = sc.detections(mode), again.detections(mode)
        assert len(a) > 0 and np.array_equal(a.xy, b.xy) and np.array_equal(a.t, b.t)
    other = sumo_scenario(3, GEN, workdir=tmp_path / 'other')
    assert dumps(gt_doc(other)) != dumps(gt_doc(sc))


def _vehicle_lanes(edge):
    if edge.getFunction() not in ('', 'normal'):
        return []
    return [ln for ln in edge.getLanes() if ln.allows('passenger')]


def test_ground_truth_matches_the_net(case):
    sc, work = case
    net = read_net(work / 'net.net.xml')
    node = net.getNode('C')
    incoming = [e for e in node.getIncoming() if _vehicle_lanes(e)]
    outgoing = [e for e in node.getOutgoing() if _vehicle_lanes(e)]
    assert sum(a.lanes_in for a in sc.gt.arms) == sum(len(_vehicle_lanes(e)) for e in incoming)
    assert sum(a.lanes_out for a in sc.gt.arms) == sum(len(_vehicle_lanes(e)) for e in outgoing)
    assert len(sc.gt.arms) == len(incoming) == sc.info['arms']
    n_conn = sum(1 for e in incoming for ln in _vehicle_lanes(e) for c in ln.getOutgoing()
                 if c.getToLane().allows('passenger'))
    assert sum(ll.kind == 'connector' for ll in sc.gt_lanelets) == n_conn
    for e in incoming:     # arm angle = the approach direction at the stop line, reversed
        shape = np.array(_vehicle_lanes(e)[0].getShape())[:, :2]
        d = shape[-2] - shape[-1]
        ang = math.atan2(d[1], d[0])
        assert min(abs(math.remainder(ang - a.angle, 2 * math.pi)) for a in sc.gt.arms) < 0.35


def test_some_traffic_and_a_floor(case):
    sc, _ = case
    doc = gt_doc(sc, arrays=True)
    m = evaluate(doc, doc)
    assert m['topology_observed_correct'] and m['lanes_true_traffic'] > 0
    assert 1.0 < m['floor_cm'] < 60.0          # tracked noise 1 m, smoothed along the lane
    labels = {int(x) for x in sc.detections('tracked').label}
    assert 1 in labels
    # ``present`` (road cases): every vehicle seen on a lane, those that stood through the
    # recording too -- never fewer than ``traffic``, the vehicles that drove it
    present = {x['id']: x['present'] for x in doc['lanes']}
    assert all(present[x['id']] >= x['traffic'] for x in doc['lanes'])
    assert sum(present.values()) >= sum(x['traffic'] for x in doc['lanes']) > 0


def test_neighbouring_junction_is_not_part_of_the_truth(tmp_path):
    """Seed 5 draws a neighbour 34 m out on arm 4, with < 25 m of road between the boxes:
    the truth keeps the junction's own six arms, the neighbour's side road is no arm."""
    sc = sumo_scenario(5, GEN, workdir=tmp_path)
    assert sc.info['neighbour'] and sc.info['junction'] == 'C'
    assert len(sc.gt.arms) == sc.info['arms'] == 6
    net = read_net(tmp_path / 'net.net.xml')
    own, _, _ = net_gt(net, 'C', cluster_m=0.0)
    merged, _, _ = net_gt(net, 'C')                     # edge-length clustering (inD rings)

    def boxes(gt):
        return {seg.split('_')[0] for ids in gt.segments_of.values() for seg in ids
                if seg.startswith(':')}
    assert ':N4' in boxes(merged) and ':N4' not in boxes(own)
    assert max(own.stop) < 30.0 < max(merged.stop)


@pytest.mark.parametrize('k', [1, 2, 3, 4])
def test_ind_networks_give_a_junction(k):
    net = realdata_dir() / 'ind_sumo' / f'inD_{k}.net.xml'
    assert net.exists(), f'{net} missing: ../shared/realdata must lie beside the checkout'
    gt, _, _ = net_gt(net)
    assert 3 <= len(gt.intersection.arms) <= 4
    assert all(a.lanes_in + a.lanes_out >= 1 for a in gt.intersection.arms)
    assert sum(ll.kind == 'connector' for ll in gt.lanelets) >= 5


def test_road_only_case_shows_a_road(tmp_path):
    sc = sumo_scenario(5, SumoConfig(ind_share=0.0, duration=(20.0, 20.0), warmup_s=25.0,
                                     road_only=True), workdir=tmp_path)
    doc = gt_doc(sc, arrays=True)
    m = evaluate(doc, doc)
    assert m['road_case'] and m['arms_true_used'] == 2 and len(sc.gt.arms) >= 3
    assert sc.info['pedestrians'] == 0 and sc.info['vehicles'] > 0


def test_fcd_positions_become_box_centers(tmp_path):
    """SUMO writes a vehicle's front-bumper middle; the family reports its box center (half
    the type's length back along its path; with one row, along its heading), as a perception
    stack would. Persons stay."""
    from intersection_estimator.scenarios.sumo_demand import VTYPE_LENGTH
    from intersection_estimator.scenarios.sumo_run import read_fcd
    fcd = tmp_path / 'fcd.xml'
    fcd.write_text('<fcd-export>\n<timestep time="30.00">\n'
                   '<vehicle id="a" x="10.00" y="5.00" angle="90.00" type="car" speed="3.00" lane="e_0"/>\n'
                   '<vehicle id="b" x="0.00" y="20.00" angle="0.00" type="truck" speed="1.00" lane="f_0"/>\n'
                   '<person id="p" x="1.00" y="2.00" angle="45.00" speed="1.00"/>\n'
                   '</timestep>\n</fcd-export>\n')
    got = {t.id: t for t in read_fcd(fcd, 30.0, 1.0, 0.1)}
    np.testing.assert_allclose(got['a'].xy[0], [10.0 - 0.5 * VTYPE_LENGTH['car'], 5.0], atol=1e-9)
    np.testing.assert_allclose(got['b'].xy[0], [0.0, 20.0 - 0.5 * VTYPE_LENGTH['truck']], atol=1e-9)
    np.testing.assert_allclose(got['p'].xy[0], [1.0, 2.0])
    assert got['a'].yaw[0] == pytest.approx(0.0) and got['b'].yaw[0] == pytest.approx(math.pi / 2)
    assert got['a'].lane[0] == 'e_0' and got['p'].lane[0] == ''


def test_a_queue_waits_behind_the_stop_line(case):
    """The first vehicle of a queue stands behind the stop line by about half its length
    (its box center), not on it."""
    sc, _ = case
    d = sc.detections('tracked')
    still = (d.track_id >= 0) & np.isfinite(d.speed) & (d.speed < 0.2)
    heads = []
    for ll in sc.gt_lanelets:
        if ll.kind != 'entering':
            continue
        end, u = ll.center[-1], ll.center[-1] - ll.center[-2]
        u = u / np.linalg.norm(u)
        rel = d.xy[still] - end
        on = np.abs(rel @ np.array([-u[1], u[0]])) < 1.5
        s = rel[on] @ u
        s = s[(s > -15.0) & (s < 5.0)]
        if len(s):
            heads.append(np.median(np.sort(s)[-20:]))
    assert heads, 'no queue in the case'
    assert -4.0 < float(np.median(heads)) < -1.0


def test_box_center_follows_the_path_through_a_turn():
    """On a turn the center stays on the front bumper's path (a driver keeps the car on the
    lane), half a length of arc behind; before the first row it is straight behind."""
    from intersection_estimator.scenarios.sumo_run import box_center
    a = np.linspace(0.0, math.pi / 2, 200)                 # quarter circle, radius 10 m
    front = 10.0 * np.stack([np.cos(a), np.sin(a)], axis=1)
    yaw = a + math.pi / 2
    c, rows = box_center(front, yaw, 2.5)
    late = a * 10.0 >= 2.5
    assert np.allclose(np.hypot(*c[late].T), 10.0, atol=0.01)       # on the path, not the chord
    np.testing.assert_allclose(np.arctan2(c[late, 1], c[late, 0]) * 10.0, a[late] * 10.0 - 2.5, atol=0.01)
    np.testing.assert_allclose(c[0], front[0] - 2.5 * np.array([math.cos(yaw[0]), math.sin(yaw[0])]))
    # the row the center passes: its front was where the center is now (its lane is the center's)
    assert np.all(rows[~late] == 0) and np.all(np.linalg.norm(front[rows[late]] - c[late], axis=1) < 0.08)
    assert box_center(front, yaw, 0.0)[0] is front


def test_the_ego_radar_sits_at_its_front_bumper(case):
    """The ego's origin is its rear axle (base_link), so the radar ``sensor_mount`` ahead of
    it is where SUMO's ego front bumper is (not a car length ahead of the car)."""
    from intersection_estimator.scenarios.sumo_demand import EGO_ID
    from intersection_estimator.scenarios.sumo_run import read_fcd
    sc, work = case
    ego = next(t for t in read_fcd(work / 'fcd.xml', GEN.warmup_s, sc.duration, GEN.step_s, back={})
               if t.id == EGO_ID)
    radar = sc.ego.sensor_xy(sc.config.sensor_mount)[ego.cycle]
    assert np.median(np.linalg.norm(radar - ego.xy, axis=1)) < 0.1
