"""Stop lines where the vehicles halt (``lanes/halts.py``, beyond the paper)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from intersection_estimator.lanes import LaneConfig, LaneCourseEstimator
from intersection_estimator.lanes.halts import HALF_CAR_M, halt_positions, halt_stops
from intersection_estimator.lanes.init import arm_frames, stop_distances
from intersection_estimator.model import ENTERING, Arm, Intersection
from intersection_estimator.observations import Detections

RATE = 10.0


def _wide_junction():
    """Four arms of three lanes each way: the corner geometry puts the stop lines ~17 m out;
    (topology, the arm along +x, its geometric stop distance)."""
    topo = Intersection(center=[0.0, 0.0], arms=[Arm(angle=k * np.pi / 2, lanes_in=3, lanes_out=3)
                                                   for k in range(4)])
    return topo, 0, stop_distances(topo, LaneConfig())[0]


def _track(tid, s_path, lat, frame, *, speed=True, heading=True, label=1):
    """Detections of one vehicle driving along arm ``frame`` towards the box at axis
    distances ``s_path`` (one per 0.1 s) and lateral position ``lat``."""
    s = np.asarray(s_path, float)
    xy = frame.origin + np.multiply.outer(s, frame.u) + lat * frame.n
    t = np.arange(len(s)) / RATE
    v = np.abs(np.gradient(s, t))
    ang = math.atan2(-frame.u[1], -frame.u[0])
    return Detections.make(xy, t, track_id=np.full(len(s), tid), speed=v if speed else None,
                           heading=np.full(len(s), ang) if heading else None,
                           label=np.full(len(s), label))


def _stops_at(s_halt, hold_s, approach=40.0):
    """Axis distances of a vehicle that drives in from ``s_halt + approach`` at 10 m/s,
    stands at ``s_halt`` for ``hold_s`` and drives on into the box."""
    n_drive = int(approach / 10.0 * RATE)
    return np.concatenate([np.linspace(s_halt + approach, s_halt, n_drive, endpoint=False),
                           np.full(int(hold_s * RATE), s_halt),
                           np.linspace(s_halt, -20.0, n_drive)])


def _merge(ds):
    return Detections.make(np.concatenate([d.xy for d in ds]), np.concatenate([d.t for d in ds]),
                           track_id=np.concatenate([d.track_id for d in ds]),
                           speed=np.concatenate([d.speed for d in ds]),
                           heading=np.concatenate([d.heading for d in ds]),
                           label=np.concatenate([d.label for d in ds]))


def test_a_halt_is_a_stretch_slower_than_the_speed_for_long_enough():
    topo, a, _ = _wide_junction()
    f = arm_frames(topo)[a]
    lat = f.lat[(ENTERING, 0)]
    long, short = _track(1, _stops_at(12.0, 4.0), lat, f), _track(2, _stops_at(30.0, 1.0), lat, f)
    xy, hv, ids = halt_positions(_merge([long, short]), min_s=2.0)
    assert ids.tolist() == [1]
    np.testing.assert_allclose(xy[0], f.origin + 12.0 * f.u + lat * f.n, atol=1e-6)
    np.testing.assert_allclose(hv[0], -f.u, atol=1e-9)
    # the speed read from positions where the sensor gives none; no heading: no halt;
    # a cyclist's halt is none of a lane's
    assert halt_positions(_track(1, _stops_at(12.0, 4.0), lat, f, speed=False))[2].tolist() == [1]
    assert len(halt_positions(_track(1, _stops_at(12.0, 4.0), lat, f, heading=False))[0]) == 0
    assert len(halt_positions(_track(1, _stops_at(12.0, 4.0), lat, f, label=6), skip_labels=(6,))[0]) == 0
    # a row without a finite position is no lane traffic (``Detections.track_mask``): the halt
    # is the one of the other rows, not NaN
    bad = _track(1, _stops_at(12.0, 4.0), lat, f)
    bad.xy[len(bad.xy) // 2] = np.nan
    got = halt_positions(bad)[0]
    assert len(got) == 1 and np.isfinite(got).all()


def test_the_stop_line_is_the_first_halt_another_vehicle_confirms():
    """Two lanes' first vehicles halt side by side 8 m out: the line is half a car ahead of
    them. A vehicle waiting alone inside the box (3 m) moves nothing; a queue standing far
    out (beyond the geometric line) does not move the line out; halts facing away count not."""
    topo, a, s0 = _wide_junction()
    f = arm_frames(topo)[a]
    stops = stop_distances(topo, LaneConfig())
    lat0, lat1 = f.lat[(ENTERING, 0)], f.lat[(ENTERING, 1)]
    cfg = LaneConfig()

    def line(*tracks, max_move=math.inf):
        h = halt_positions(_merge(list(tracks)), cfg.skip_labels, cfg.halt_speed, cfg.halt_min_s)
        return halt_stops(arm_frames(topo), stops, h, cfg.halt_pair_m, cfg.stop_min, max_move)[a]

    heads = (_track(1, _stops_at(8.0, 5.0), lat0, f), _track(2, _stops_at(8.5, 5.0), lat1, f))
    assert s0 > 12.0 and line(*heads) == pytest.approx(8.0 - HALF_CAR_M)
    # ``halt_max_move``: the line moves in by that much at most
    assert line(*heads, max_move=3.0) == pytest.approx(s0 - 3.0)
    in_box = _track(3, _stops_at(3.0, 5.0), lat0, f)
    assert line(*heads, in_box) == pytest.approx(8.0 - HALF_CAR_M)
    assert line(in_box) == s0
    far = (_track(4, _stops_at(s0 + 20.0, 5.0), lat0, f), _track(5, _stops_at(s0 + 20.5, 5.0), lat1, f))
    assert line(*far) == s0
    away = [_track(6 + k, _stops_at(8.0, 5.0), lat, f) for k, lat in enumerate((lat0, lat1))]
    for d in away:
        d.heading[:] += np.pi
    assert line(*away) == s0
    # off the arm's entering lanes (a kerb row two lanes out) is no lane's head either
    kerb = [_track(8 + k, _stops_at(8.0 + 0.5 * k, 5.0), lat0 - 8.0, f) for k in range(2)]
    assert line(*kerb) == s0


def test_the_entering_lanes_reach_the_halted_vehicles():
    """End to end: three lanes of vehicles halt 9 m from the center, then cross the box; the
    estimated entering lanelets end within a metre of the line the halts show, where the
    corner geometry alone ended them at ``s0``; with ``halt_stops`` off they end there. (The
    line moves 11 m here: ``halt_max_move`` raised to let it.)"""
    topo, a, s0 = _wide_junction()
    f = arm_frames(topo)[a]
    tracks = [_track(k, _stops_at(9.0 + 0.3 * k, 4.0), f.lat[(ENTERING, k % 3)], f) for k in range(6)]
    dets = _merge(tracks)
    ends = {}
    for on in (1, 0):
        est = LaneCourseEstimator(LaneConfig(halt_stops=on, halt_max_move=20.0), 0)
        est.initialise(topo, dets)
        ends[on] = [float((l.center[-1] - f.origin) @ f.u) for l in est.lanelets
                    if l.kind == 'entering' and l.arm == a]
    line = 9.0 - HALF_CAR_M
    assert ends[1] and max(abs(e - line) for e in ends[1]) < 2.5
    assert min(ends[0]) > line + 6.0


def _leaves_view(tid, s_from, s_to, lat, frame):
    """A vehicle seen driving in from ``s_from`` to ``s_to`` at 10 m/s (then out of view)."""
    return _track(tid, np.arange(s_from, s_to, -1.0), lat, frame)


def test_a_queue_bends_the_lane_where_nothing_moved():
    """``halt_follow``: the vehicles that drove the approach were seen 45-110 m out only; next
    to the box the lanes' only traffic is a queue that stood through the recording, curving
    up to 1.6 m aside. Each halted vehicle is one point of its lane: the lanes bend towards
    the queue there; with ``halt_follow`` off they run straight past it."""
    topo, a, s0 = _wide_junction()
    f = arm_frames(topo)[a]
    lat = [f.lat[(ENTERING, k)] for k in range(3)]
    movers = [_leaves_view(k, 110.0, 45.0, lat[k % 3], f) for k in range(9)]
    side = np.sign(lat[-1] - lat[0])
    queue = []
    for k in range(3):
        for j, s in enumerate(np.arange(s0 + 1.0, 45.0, 6.5)):
            bend = side * 0.06 * (45.0 - s)
            queue.append(_track(100 + 10 * k + j, np.full(60, s), lat[k] + bend, f))
    dets = _merge(movers + queue)
    off = {}
    for on in (1, 0):
        est = LaneCourseEstimator(LaneConfig(halt_follow=on), 0)
        est.initialise(topo, dets)
        lane = next(l for l in est.lanelets if l.kind == 'entering' and l.arm == a and l.lane_index == 1)
        rel = lane.center - f.origin
        s, across = rel @ f.u, rel @ f.n
        near = (s > s0) & (s < s0 + 12.0)
        off[on] = float(np.mean((across[near] - lat[1]) * side))
    assert off[1] > 0.6 and abs(off[0]) < 0.2
