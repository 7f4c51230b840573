"""Properties of the scenario simulator (paper §IV, Table I)."""

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings, strategies as st

from intersection_estimator.model import ENTERING, LEAVING, lane_offset, wrap_angle
from intersection_estimator.sim import FALSE_TRACK_ID0, SimConfig, simulate_scenario
from intersection_estimator.sim.scenario import connector_pairs

SETTINGS = settings(max_examples=12, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow])
seeds = st.integers(min_value=0, max_value=2**31 - 1)
sides = st.sampled_from([1, -1])
_CACHE = {}


def scenario(seed, side=1):
    key = (seed, side)
    if key not in _CACHE:
        _CACHE[key] = simulate_scenario(seed, SimConfig(traffic_side=side))
    return _CACHE[key]


@SETTINGS
@given(seeds)
def test_table1_ranges(seed):
    sc = scenario(seed)
    arms = sc.gt.arms
    assert 3 <= len(arms) <= 5
    ang = np.array([a.angle for a in arms])
    assert np.all(np.diff(ang) > 0) and ang[0] >= -math.pi and ang[-1] < math.pi
    between = np.diff(np.concatenate([ang, ang[:1] + 2 * math.pi]))
    assert between.min() >= math.radians(45.0) - 1e-9
    for a in arms:
        assert 1 <= a.lanes_in <= 4 and 1 <= a.lanes_out <= 4
        assert 0.0 <= a.gap < 3.0 and 3.0 <= a.lane_width <= 3.75


@SETTINGS
@given(seeds, sides)
def test_lane_counts_and_geometry_match_model(seed, side):
    sc = scenario(seed, side)
    for i, arm in enumerate(sc.gt.arms):
        for kind, n, d in (('entering', arm.lanes_in, ENTERING), ('leaving', arm.lanes_out, LEAVING)):
            lanes = sorted((ll for ll in sc.gt_lanelets if ll.kind == kind and ll.arm == i),
                           key=lambda ll: ll.lane_index)
            assert [ll.lane_index for ll in lanes] == list(range(n))
            for ll in lanes:
                rel = ll.center - sc.gt.center
                lateral = rel @ arm.normal
                want = lane_offset(arm.gap, arm.lane_width, ll.lane_index, d, side)
                np.testing.assert_allclose(lateral, want, atol=1e-9)
                along = rel @ arm.direction
                # driving direction: entering lanes run towards the center
                assert (np.diff(along) < 0).all() if d == ENTERING else (np.diff(along) > 0).all()
                assert along.min() == pytest.approx(sc.stop[i])
                # left border is on the left in driving direction, w/2 away
                t = np.diff(ll.center, axis=0)
                v = (ll.left - ll.center)[:-1]
                left_side = t[:, 0] * v[:, 1] - t[:, 1] * v[:, 0]
                assert (left_side > 0).all()
                np.testing.assert_allclose(np.linalg.norm(ll.left - ll.center, axis=1),
                                           arm.lane_width / 2, atol=1e-9)


@SETTINGS
@given(seeds, sides)
def test_connectors_join_lanes_exactly_and_successors_consistent(seed, side):
    sc = scenario(seed, side)
    by_id = {ll.id: ll for ll in sc.gt_lanelets}
    assert len(by_id) == len(sc.gt_lanelets)
    has_pred = set()
    for ll in sc.gt_lanelets:
        for s in ll.successors:
            nxt = by_id[s]
            has_pred.add(s)
            # consecutive lanelets share their end points exactly (Lanelet2 routing)
            for a, b in ((ll.center, nxt.center), (ll.left, nxt.left), (ll.right, nxt.right)):
                assert np.array_equal(a[-1], b[0])
        if ll.kind == 'entering':
            assert ll.successors and all(by_id[s].kind == 'connector' for s in ll.successors)
            assert all(by_id[s].arm == ll.arm for s in ll.successors)
        elif ll.kind == 'connector':
            assert len(ll.successors) == 1
            out = by_id[ll.successors[0]]
            assert out.kind == 'leaving' and out.arm == ll.arm_to != ll.arm
        else:
            assert ll.successors == []
    for ll in sc.gt_lanelets:  # every leaving lane is reached, every connector is used
        assert (ll.id in has_pred) == (ll.kind != 'entering')


@SETTINGS
@given(seeds)
@example(seed=1498715030)   # a 129 deg turn between arms 51 deg apart: radius 3.74 m before
def test_connectors_are_smooth(seed):
    sc = scenario(seed)
    for ll in sc.gt_lanelets:
        if ll.kind != 'connector':
            continue
        d = np.diff(ll.center, axis=0)
        assert np.linalg.norm(d, axis=1).max() < 1.5
        yaw = np.unwrap(np.arctan2(d[:, 1], d[:, 0]))
        ds = np.linalg.norm(d, axis=1)
        assert (np.abs(np.diff(yaw)) / ds[1:]).max() < 1 / 4.0   # turn radius > 4 m
        # tangent-continuous with the lanes: first/last segment along the arm axes
        into = -sc.gt.arms[ll.arm].direction
        out = sc.gt.arms[ll.arm_to].direction
        assert d[0] @ into / np.linalg.norm(d[0]) > 0.99
        assert d[-1] @ out / np.linalg.norm(d[-1]) > 0.99


@SETTINGS
@given(seeds, sides)
def test_traffic_limits_and_routes(seed, side):
    sc = scenario(seed, side)
    by_id = {ll.id: ll for ll in sc.gt_lanelets}
    assert max(sc.traffic.values()) <= 6
    counts = dict.fromkeys(by_id, 0)
    for tr in sc.tracks:
        a, c, b = tr.route
        assert c in by_id[a].successors and by_id[c].successors == [b]
        for x in tr.route:
            counts[x] += 1
        assert np.all(np.diff(tr.t) > 0) and tr.t[0] >= 0 and tr.t[-1] <= sc.duration + 1e-9
        assert np.all(tr.speed > 0) and tr.speed.max() <= 14.0 + 1e-9
        step = np.linalg.norm(np.diff(tr.xy, axis=0), axis=1)
        assert step.max() <= 14.0 / sc.config.rate_hz + 1e-6
    assert counts == sc.traffic
    # every lane of the arms carries traffic in the default config
    assert all(sc.traffic[i] > 0 for i, ll in by_id.items() if ll.kind != 'connector')


@SETTINGS
@given(seeds)
def test_ego_stops_before_stop_line(seed):
    sc = scenario(seed)
    ego, arm = sc.ego, sc.gt.arms[sc.ego.arm]
    along = (ego.xy - sc.gt.center) @ arm.direction
    assert np.all(np.diff(along) <= 1e-9)             # approaches
    assert sc.stop[sc.ego.arm] + 1.9 < along[-1] < sc.stop[sc.ego.arm] + 6.1
    assert ego.speed[-1] == 0.0 and ego.speed[0] > 7.9
    lat = (ego.xy - sc.gt.center) @ arm.normal
    want = lane_offset(arm.gap, arm.lane_width, ego.lane_index, ENTERING, 1)
    np.testing.assert_allclose(lat, want, atol=1e-9)


def test_deterministic_per_seed():
    a, b = simulate_scenario(42), simulate_scenario(42)
    assert a.gt.to_json() == b.gt.to_json()
    assert [ll.to_json() for ll in a.gt_lanelets] == [ll.to_json() for ll in b.gt_lanelets]
    for mode in ('tracked', 'raw', 'heading'):
        da, db = a.detections(mode), b.detections(mode)
        assert np.array_equal(da.xy, db.xy) and np.array_equal(da.track_id, db.track_id)
    assert not np.array_equal(a.detections('raw', 1).xy[:50], a.detections('raw').xy[:50])
    assert simulate_scenario(43).gt.to_json() != a.gt.to_json()


def _track_errors(sc, d):
    """Per real track of the tracked detections: its position errors in cycle order."""
    truth = {(tr.id, round(t * 10)): xy for tr in sc.tracks for t, xy in zip(tr.t, tr.xy)}
    out = []
    for tid in np.unique(d.track_id[d.track_id < FALSE_TRACK_ID0]):
        i = np.flatnonzero(d.track_id == tid)
        out.append(np.array([d.xy[k] - truth[(tid, round(d.t[k] * 10))] for k in i]))
    return out


def test_tracked_detections():
    sc = simulate_scenario(5)
    d = sc.detections('tracked')
    real = d.track_id < FALSE_TRACK_ID0
    assert real.sum() > 500 and (~real).sum() > 0
    assert np.isfinite(d.heading).all() and np.isnan(d.doppler).all()
    assert d.heading.min() >= -math.pi and d.heading.max() < math.pi
    # persistent ids: one id per simulated vehicle, stamps strictly increasing per id
    assert set(d.track_id[real]) <= {tr.id for tr in sc.tracks}
    for tid in np.unique(d.track_id)[:10]:
        assert np.all(np.diff(d.t[d.track_id == tid]) > 0)
    # noise N(0, 1 m) around the true positions
    err = np.concatenate(_track_errors(sc, d))
    assert abs(err.std() - 1.0) < 0.1 and np.abs(err.mean(axis=0)).max() < 0.1
    assert np.linalg.norm(d.xy[~real] - sc.gt.center, axis=1).max() < 80 + 5
    assert np.all(np.linalg.norm(d.xy - d.sensor_xy, axis=1) <= sc.sensor_range)  # >= 100 m


def test_tracked_noise_correlated_along_a_track_option():
    """``track_noise_corr``: the same sigma per row, AR(1) along each track (a tracker's
    output); 0 leaves the white draws -- and every other row -- as they were."""
    white, corr = (simulate_scenario(5, SimConfig(track_noise_corr=r)) for r in (0.0, 0.95))
    dw, dc = white.detections('tracked'), corr.detections('tracked')
    assert abs(len(dw) - len(dc)) < 0.01 * len(dw)      # the range cut is on noisy positions
    ew, ec = _track_errors(white, dw), _track_errors(corr, dc)
    lag1 = lambda es: (sum(float(np.sum(e[1:] * e[:-1])) for e in es)
                       / sum(float(np.sum(e[:-1] ** 2)) for e in es))
    assert abs(lag1(ew)) < 0.05 and lag1(ec) == pytest.approx(0.95, abs=0.03)
    assert np.concatenate(ec).std() == pytest.approx(1.0, abs=0.15)
    assert simulate_scenario(5).detections('tracked').xy.tobytes() == dw.xy.tobytes()


def test_corner_turn_shape_option():
    """``turn_shape='corner'``: connectors through the corner of their lanes' lines (handles
    2/3 of the way there; straight on: chord/3), a family the lane course's start does not
    share; the vehicles drive them, and the default draws the arcs as before."""
    from intersection_estimator.sim.scenario import _corner_handles, _handles
    p0, d0, p3, d3 = np.zeros(2), np.array([1.0, 0.0]), np.array([10.0, 10.0]), np.array([0.0, 1.0])
    assert _corner_handles(p0, d0, p3, d3, math.hypot(10, 10)) == pytest.approx((20 / 3, 20 / 3))
    straight = np.array([20.0, 0.0])
    assert _corner_handles(p0, d0, straight, d0, 20.0) == pytest.approx((20 / 3, 20 / 3))
    arc = _handles(p0, d0, p3, d3)[0][0]            # 0.39 chord (a circular arc)
    assert arc == pytest.approx(4 / 3 * math.tan(math.pi / 8) * 10)
    base, corner = simulate_scenario(5), simulate_scenario(5, SimConfig(turn_shape='corner'))
    def bends(c):
        u, v = c[1] - c[0], c[-1] - c[-2]
        return abs(u[0] * v[1] - u[1] * v[0]) > 1e-3
    turns = [(a, b) for a, b in zip(base.gt_lanelets, corner.gt_lanelets)
             if a.kind == 'connector' and bends(a.center)]
    assert turns and all(np.allclose(a.center[[0, -1]], b.center[[0, -1]]) for a, b in turns)
    gap = max(float(np.abs(a.center[len(a.center) // 2] - b.center[len(b.center) // 2]).max())
              for a, b in turns)
    assert gap > 0.3                                # the middles of the turns moved
    assert simulate_scenario(5, SimConfig(turn_shape='arc')).detections('tracked').xy.tobytes() \
        == base.detections('tracked').xy.tobytes()
    with pytest.raises(ValueError, match='turn_shape'):
        simulate_scenario(5, SimConfig(turn_shape='clothoid'))


def test_raw_radar_doppler_sign_and_clutter():
    sc = simulate_scenario(6)
    d = sc.detections('raw')
    assert (d.track_id == -1).all() and np.isnan(d.heading).all()
    assert np.isfinite(d.doppler).all() and np.isfinite(d.rcs).all()
    clutter = d.label == 0
    assert clutter.sum() > 100 and np.abs(d.doppler[clutter]).max() < 1.0
    assert d.rcs[clutter].mean() < d.rcs[~clutter].mean() - 10
    # the radar rides on the ego: it moves, then stops
    sx = d.sensor_xy
    assert np.all(np.diff(d.t) >= 0) and np.linalg.norm(sx[0] - sx[-1]) > 10
    assert np.array_equal(sx[-1], sc.ego.sensor_xy(sc.config.sensor_mount)[-1])
    assert m_count(d) > 2 * len(sc.tracks)


def m_count(d):
    return int((d.label != 0).sum())


def test_radar_doppler_is_radial_velocity():
    cfg = SimConfig(position_noise=0.0, doppler_noise=0.0, vehicle_size=(0.0, 0.0),
                    radar_clutter_per_cycle=0.0)
    sc = simulate_scenario(8, cfg)
    d = sc.detections('raw')
    by_stamp = {}
    for tr in sc.tracks:
        for t, xy, yw, v in zip(tr.t, tr.xy, tr.yaw, tr.speed):
            by_stamp.setdefault(round(t * 10), []).append((xy, yw, v))
    for i in range(0, len(d), 37):
        cands = by_stamp[round(d.t[i] * 10)]
        xy, yw, v = min(cands, key=lambda c: np.linalg.norm(c[0] - d.xy[i]))
        los = (xy - d.sensor_xy[i]) / np.linalg.norm(xy - d.sensor_xy[i])
        assert d.doppler[i] == pytest.approx(v * (math.cos(yw) * los[0] + math.sin(yw) * los[1]))


def test_heading_detections_and_frames():
    sc = simulate_scenario(9)
    d = sc.detections('heading')
    assert (d.track_id == -1).all() and np.isfinite(d.heading).all()
    frames = list(sc.frames('heading'))
    assert len(frames) == len(sc.ego.t)
    assert sum(len(f) for _, f in frames) == len(d)
    stamps = np.array([s for s, _ in frames])
    assert np.allclose(np.diff(stamps), 1 / sc.config.rate_hz)
    for s, f in frames[::20]:
        assert np.all(f.t == s)


def test_left_hand_traffic_mirrors_sides():
    sc = simulate_scenario(3, SimConfig(traffic_side=-1))
    for ll in sc.gt_lanelets:
        if ll.kind == 'entering':
            arm = sc.gt.arms[ll.arm]
            assert ((ll.center - sc.gt.center) @ arm.normal < 0).all()


def test_connector_rules_single_lane_reaches_all_arms():
    sc = simulate_scenario(0, SimConfig(lanes=(1, 1)))
    pairs = connector_pairs(sc.gt)
    n = len(sc.gt.arms)
    assert len(pairs) == n * (n - 1)
    assert len({(a, b) for a, _, b, _ in pairs}) == n * (n - 1)


def test_kerb_lane_turns_to_kerb_side():
    sc = simulate_scenario(11, SimConfig(lanes=(3, 3), arms=(4, 4)))
    pairs = connector_pairs(sc.gt)
    for a in range(4):
        mine = [p for p in pairs if p[0] == a]
        turn = {b: float(wrap_angle(sc.gt.arms[b].angle - sc.gt.arms[a].angle - math.pi))
                for _, _, b, _ in mine}
        right, left = min(turn, key=turn.get), max(turn, key=turn.get)
        assert {k for _, k, b, _ in mine if b == right} == {2}   # kerb lane
        assert {k for _, k, b, _ in mine if b == left} == {0}    # median lane
        assert {k for _, k, _, _ in mine} == {0, 1, 2}


def test_simulate_cli_writes_gt_and_bag(tmp_path, capsys):
    import argparse
    import json
    from intersection_estimator.sim.cli import register
    ap = argparse.ArgumentParser()
    register(ap.add_subparsers())
    args = ap.parse_args(['simulate', '--seed', '4', '--out', str(tmp_path / 's'),
                          '--mode', 'tracked', '--traffic-side', 'left'])
    assert args.func(args) == 0
    gt = json.loads((tmp_path / 's' / 'gt.json').read_text())
    assert gt['seed'] == 4 and gt['traffic_side'] == -1 and gt['sim_config']['traffic_side'] == -1
    sc = simulate_scenario(4, SimConfig(traffic_side=-1))
    assert len(gt['lanes']) == len(sc.gt_lanelets)
    assert {x['id']: x['traffic'] for x in gt['lanes']} == sc.traffic
    try:
        import intersection_estimator.bagio  # noqa: F401
    except ImportError:
        assert 'bag not written' in capsys.readouterr().err
    else:
        assert (tmp_path / 's' / 'bag').is_dir()


def _seen_along(dets, ll, mask, tol=1.0):
    """Detections (rows of ``mask``) within ``tol`` of the straight lane ``ll``'s center line,
    and the length of lane they span [m]."""
    c0, c1 = ll.center[0], ll.center[-1]
    u = (c1 - c0) / np.linalg.norm(c1 - c0)
    rel = dets.xy - c0
    along, lat = rel @ u, rel @ np.array([-u[1], u[0]])
    m = mask & (np.abs(lat) < tol) & (along >= 0) & (along <= np.linalg.norm(c1 - c0))
    return int(m.sum()), float(np.ptp(along[m])) if m.any() else 0.0


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seeds, sides)
def test_every_lane_is_observed_in_tracked_mode(seed, side):
    """Paper Table I: every lane carries observed traffic -- not just a trajectory outside
    the time window or the sensor range (was: ~1 in 4 scenes with a blind lane)."""
    sc = scenario(seed, side)
    d = sc.detections('tracked')
    real = d.track_id < FALSE_TRACK_ID0
    assert np.all(np.linalg.norm(d.xy - d.sensor_xy, axis=1) <= sc.sensor_range)
    assert sc.config.sensor_range <= sc.sensor_range <= 200.0
    for ll in sc.gt_lanelets:
        if ll.kind == 'connector':
            continue
        yaw = math.atan2(*(ll.center[1] - ll.center[0])[::-1])
        same_dir = real & (np.abs(wrap_angle(d.heading - yaw)) < math.radians(30))
        n, span = _seen_along(d, ll, same_dir)
        assert n >= 5 and span >= 15.0, (ll.id, n, span)


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seeds)
def test_raw_radar_sees_every_arm(seed):
    sc = scenario(seed)
    d = sc.detections('raw')
    vehicle = d.label != 0
    for a in range(len(sc.gt.arms)):
        lanes = [ll for ll in sc.gt_lanelets if ll.arm == a and ll.kind != 'connector']
        seen = {ll.kind: _seen_along(d, ll, vehicle, tol=2.0)[0] for ll in lanes}
        assert all(seen.get(k, 0) >= 1 for k in ('entering', 'leaving'))
        assert sum(_seen_along(d, ll, vehicle, tol=2.0)[0] for ll in lanes) >= 20, (a, seen)


def test_observed_routes_keep_table1_traffic_and_fixed_range_option():
    """The observation guarantee only moves start times (same routes, same counts), and
    ``auto_sensor_range=False`` keeps the fixed range."""
    sc = simulate_scenario(16)
    assert max(sc.traffic.values()) <= 6 and sc.sensor_range > 100.0   # a wide 5-arm scene
    fixed = simulate_scenario(16, SimConfig(auto_sensor_range=False))
    assert fixed.sensor_range == 100.0
    assert fixed.traffic == sc.traffic and fixed.gt.to_json() == sc.gt.to_json()
