"""Radar scans in, tracks out (tracking/tracker.py), and the pipeline with it."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from intersection_estimator.observations import Detections
from intersection_estimator.pipeline import OnlineEstimator, PipelineConfig, estimate, radar_tracked
from intersection_estimator.topology import TopologyConfig
from intersection_estimator.tracking import RADAR_TRACK_ID0, RadarTracker, TrackerConfig, track_radar
from intersection_estimator.tracking.tracker import MAX_HELD

from .scenes import RATE, polyline, scans, stop_and_go, straight


def _crossing(rng, clutter=0.0):
    east = straight((-40, 0), (10, 0), 0.0, 8.0)
    north = straight((1.5, -35), (0, 9), 0.5, 8.0)
    return scans([east, north], 8.0, rng, clutter), (east, north)


def _coverage(tracks: Detections, at, tid) -> float:
    """Share of the vehicle's scans where track ``tid`` is within 2 m of it."""
    hit = n = 0
    for t in np.unique(tracks.t):
        s = at(t)
        if s is None:
            continue
        n += 1
        m = (tracks.track_id == tid) & (tracks.t == t)
        hit += bool(m.any() and np.linalg.norm(tracks.xy[m][0] - s[0]) < 2.0)
    return hit / n


def test_two_crossing_vehicles_make_two_tracks_along_their_paths():
    dets, (east, north) = _crossing(np.random.default_rng(0), clutter=3.0)
    tracks = track_radar(dets)
    ids = np.unique(tracks.track_id)
    assert len(ids) == 2 and (ids >= RADAR_TRACK_ID0).all()
    for at, heading in ((east, 0.0), (north, np.pi / 2)):
        tid = max(ids, key=lambda i: _coverage(tracks, at, i))
        assert _coverage(tracks, at, tid) > 0.9
        h = tracks.heading[tracks.track_id == tid]
        assert np.abs(np.angle(np.exp(1j * (h - heading)))).max() < np.radians(10)


def test_static_clutter_makes_no_track():
    rng = np.random.default_rng(1)
    assert len(track_radar(scans([], 20.0, rng, clutter_per_scan=8.0))) == 0


def test_a_vehicle_that_stops_keeps_one_track_and_its_heading():
    rng = np.random.default_rng(2)
    at = stop_and_go((-40, 0), (8, 0), 3.0, 6.0, 10.0)
    tracks = track_radar(scans([at], 10.0, rng))
    assert len(np.unique(tracks.track_id)) == 1
    standing = (tracks.t > 3.8) & (tracks.t < 5.5)
    assert standing.sum() > 10 and (tracks.speed[standing] < 1.5).all()
    assert np.abs(tracks.heading[standing]).max() < np.radians(10)


def test_online_hands_every_row_out_once_in_stamp_order():
    dets, _ = _crossing(np.random.default_rng(3))
    tracker = RadarTracker()
    out = []
    for t in np.unique(dets.t):
        m = dets.t == t
        got = tracker.step(float(t), dets.xy[m], dets.doppler[m], dets.sensor_xy[m])
        assert (got.t <= t).all()
        out.append(got)
    rows = Detections.concat(out)
    assert len(np.unique(rows.track_id)) == 2
    pairs = list(zip(rows.track_id.tolist(), rows.t.tolist()))
    assert len(pairs) == len(set(pairs))
    assert len(rows) >= 0.9 * len(track_radar(dets))


def test_an_older_scan_is_counted_and_ignored():
    tracker = RadarTracker()
    tracker.step(1.0, np.zeros((1, 2)), np.zeros(1), np.zeros((1, 2)))
    out = tracker.step(0.5, np.ones((3, 2)), np.zeros(3), np.zeros((3, 2)))
    assert len(out) == 0 and tracker.scans_late == 1 and len(tracker.live) == 1
    tracker.step(1.0, np.ones((2, 2)), np.zeros(2), np.zeros((2, 2)))   # its stamp was tracked
    assert tracker.scans_late == 2 and len(tracker.live) == 1


def _two_radars_in_arrival_order(dets, latency_b: float):
    """Scans of ``dets`` alternately from radar A (no latency) and radar B (``latency_b``),
    as messages in the order they arrive."""
    msgs = []
    for k, t in enumerate(np.unique(dets.t)):
        msgs.append((t + (latency_b if k % 2 else 0.0), k, dets.subset(dets.t == t)))
    return [m for _, _, m in sorted(msgs, key=lambda m: m[:2])]


def _online(msgs, cfg=None):
    tracker = RadarTracker(cfg)
    rows = Detections.concat([tracker.feed(m) for m in msgs] + [tracker.flush()])
    return rows, tracker


def test_two_radars_arriving_out_of_order_are_tracked_in_stamp_order():
    dets, _ = _crossing(np.random.default_rng(3))
    in_order, _ = _online(_two_radars_in_arrival_order(dets, 0.0))
    late = _two_radars_in_arrival_order(dets, 0.15)     # B's scan arrives after A's next one
    assert [m.t[0] for m in late] != sorted(m.t[0] for m in late)
    rows, tracker = _online(late)
    assert tracker.scans_late == 0 and len(np.unique(rows.track_id)) == 2
    assert np.array_equal(rows.xy, in_order.xy) and np.array_equal(rows.t, in_order.t)
    rows, tracker = _online(late, dataclasses.replace(TrackerConfig(), reorder_s=0.0))
    assert tracker.scans_late > 0.3 * len(late)         # without the hold B's scans are late


def test_scans_of_one_stamp_are_one_scan_and_the_hold_is_capped():
    dets, _ = _crossing(np.random.default_rng(3))
    a, b = dets.subset(np.arange(len(dets)) % 2 == 0), dets.subset(np.arange(len(dets)) % 2 == 1)
    split, _ = _online([p.subset(p.t == t) for t in np.unique(dets.t) for p in (a, b)])
    whole, _ = _online([dets.subset(dets.t == t) for t in np.unique(dets.t)])
    assert split.xy.shape == whole.xy.shape and np.allclose(split.xy, whole.xy, atol=1e-9)
    tracker = RadarTracker(dataclasses.replace(TrackerConfig(), reorder_s=10.0))
    for t in np.arange(400) * 0.01:
        tracker.feed(Detections.make(np.zeros((1, 2)), np.array([t]), doppler=np.array([5.0]),
                                     sensor_xy=np.array([[0.0, -30.0]])))
        assert len(tracker._held) <= MAX_HELD


def test_deterministic():
    dets, _ = _crossing(np.random.default_rng(4), clutter=5.0)
    a, b = track_radar(dets), track_radar(dets)
    assert np.array_equal(a.xy, b.xy) and np.array_equal(a.track_id, b.track_id)


@pytest.mark.parametrize('name, value', [('gate_sigma', 0.0), ('max_miss', 0), ('doppler_tol', -1.0)])
def test_a_bad_setting_is_refused_by_name(name, value):
    with pytest.raises(ValueError, match=name):
        RadarTracker(dataclasses.replace(TrackerConfig(), **{name: value}))


def test_raw_windows_become_tracked_and_the_switch_restores_the_paper_model():
    dets, _ = _crossing(np.random.default_rng(5))
    raw = dataclasses.replace(dets, track_id=np.full(len(dets), -1))
    got, mode = radar_tracked(raw, 'raw', TrackerConfig(), TopologyConfig())
    assert mode == 'tracked' and got.has_tracks
    same, mode = radar_tracked(raw, 'raw', TrackerConfig(enabled=False), TopologyConfig())
    assert mode == 'raw' and same is raw
    assert radar_tracked(raw, 'tracked', TrackerConfig(), TopologyConfig())[1] == 'tracked'


def test_the_online_estimator_windows_radar_as_tracks():
    dets, _ = _crossing(np.random.default_rng(6))
    on = OnlineEstimator(PipelineConfig(topology_samples=100, lanes_enabled=False))
    off = OnlineEstimator(PipelineConfig(topology_samples=100, lanes_enabled=False,
                                         radar_tracking=TrackerConfig(enabled=False)))
    for t in np.unique(dets.t):
        m = dets.t == t
        assert on.add(dets.subset(m)) == off.add(dets.subset(m)) == int(m.sum())
    assert on.window().has_tracks and not off.window().has_tracks
    assert len(off.window()) == len(dets)


def test_the_input_path_only_queues_the_tracker_runs_in_the_tick():
    """``add`` (the node's input callback) queues radar rows; the tracker runs when the tick
    (or ``window``) asks, on every queued scan in stamp order; a queue beyond the window's
    cap is tracked at once (memory stays bounded without ticks)."""
    dets, _ = _crossing(np.random.default_rng(6))
    est = OnlineEstimator(PipelineConfig(topology_samples=100, lanes_enabled=False))
    for t in np.unique(dets.t)[::-1]:                 # even in reverse arrival order
        est.add(dets.subset(dets.t == t))
    assert not (Detections.concat(est._parts).track_id >= RADAR_TRACK_ID0).any()
    est.tick(float(dets.t.max()))
    assert (Detections.concat(est._parts).track_id >= RADAR_TRACK_ID0).any()
    assert est.radar_scans_late == 0 and not est._radar_queue
    small = OnlineEstimator(PipelineConfig(topology_samples=100, lanes_enabled=False,
                                           max_observations=200))
    for t in np.unique(dets.t):
        small.add(dets.subset(dets.t == t))
        assert small._queued <= 200 + int((dets.t == t).sum())


def test_with_tracked_objects_of_its_own_the_window_keeps_radar_rows_not_radar_tracks():
    dets, (east, _) = _crossing(np.random.default_rng(7))
    ts = np.unique(dets.t)
    objects = Detections.make(np.array([east(t)[0] for t in ts]), ts, heading=0.0, speed=10.0,
                              track_id=5, label=1)
    est = OnlineEstimator(PipelineConfig(topology_samples=100, lanes_enabled=False))
    est.add(dets)
    assert (est.window().track_id >= RADAR_TRACK_ID0).any()
    est.add(objects)
    w = est.window()
    assert not (w.track_id >= RADAR_TRACK_ID0).any()
    assert len(w) == len(dets) + len(objects)


def test_a_window_of_radar_tracks_needs_more_passages_for_an_unexplained_arm():
    """Descent settings per window: radar-tracker windows use ``radar_tracks_add_support``
    (default 3 passages, twice the tracked objects' 1.5: a radar track that breaks inside
    the box leaves parts that no arm explains), other windows ``descent_add_support``."""
    from intersection_estimator.topology import TopologyEstimator
    dets, _ = _crossing(np.random.default_rng(8))
    tracks = track_radar(dets)
    cfg = TopologyConfig(radar_tracks_add_support=7.0)
    est = TopologyEstimator(cfg, 0)
    est.set_observations(tracks)
    assert est._window_cfg.descent_add_support == 7.0
    own = dataclasses.replace(tracks, track_id=tracks.track_id - RADAR_TRACK_ID0)
    est.set_observations(own)
    assert est._window_cfg.descent_add_support == cfg.descent_add_support == 1.5


def test_rows_without_a_sensor_position_are_tracked_without_the_doppler():
    dets, (east, _) = _crossing(np.random.default_rng(9))
    blind = dataclasses.replace(dets, sensor_xy=np.full_like(dets.sensor_xy, np.nan))
    tracks = track_radar(blind)
    assert np.isfinite(tracks.xy).all() and np.isfinite(tracks.heading).all()
    assert max(_coverage(tracks, east, i) for i in np.unique(tracks.track_id)) > 0.9


def _parked(seconds: float, seed: int) -> Detections:
    """Radar of a car that stands at (10, 5) for ``seconds``."""
    return scans([straight((10.0, 5.0), (0.0, 0.0), 0.0, seconds)], seconds,
                 np.random.default_rng(seed))


def test_online_a_parked_car_holds_at_most_max_backlog_updates():
    """With standing reports off (``standing_s`` 0) a standing object is never reported (it
    never drove); online its track keeps only the newest ``max_backlog`` updates, so memory
    stays bounded however long it stands."""
    dets = _parked(30.0, seed=10)
    tracker = RadarTracker(dataclasses.replace(TrackerConfig(), max_backlog=40, standing_s=0.0))
    for t in np.unique(dets.t):
        m = dets.t == t
        assert len(tracker.step(float(t), dets.xy[m], dets.doppler[m], dets.sensor_xy[m])) == 0
    assert len(tracker.live) == 1 and tracker.live[0].hits > 250
    assert len(tracker.live[0].hist) <= 40


def test_a_vehicle_that_stands_through_is_reported_headless_once_it_stood_standing_s():
    """A parked car (or a queue's vehicle) that never drove: after ``standing_s`` of stamp
    time its rows are handed out online, backlog first, with no heading (radar cannot tell
    which way it faces) and speed 0; the batch reports the same track; memory stays bounded."""
    dets = _parked(30.0, seed=10)
    cfg = dataclasses.replace(TrackerConfig(), standing_s=4.0)
    tracker = RadarTracker(cfg)
    out = []
    for t in np.unique(dets.t):
        m = dets.t == t
        got = tracker.step(float(t), dets.xy[m], dets.doppler[m], dets.sensor_xy[m])
        if len(got):
            out.append(got)
        # memory: the updates of standing_s before it is reported, the newest one after
        assert len(tracker.live[0].hist) <= cfg.standing_s * RATE + 2
    rows = Detections.concat(out)
    # the backlog at 4 s (from the first update after the spawning scan), then scan by scan
    assert out[0].t.min() == 0.1 and out[0].t.max() >= cfg.standing_s
    assert len(np.unique(rows.t)) == len(rows) == len(np.unique(dets.t)) - 1
    assert np.isnan(rows.heading).all() and (rows.speed == 0).all()
    assert np.linalg.norm(rows.xy - [10.0, 5.0], axis=1).max() < 2.0
    batch = track_radar(dets, cfg)
    assert len(np.unique(batch.track_id)) == 1 and np.isnan(batch.heading).all()


def test_a_short_stand_is_not_reported():
    """A vehicle seen standing for less than ``standing_s`` gives no track."""
    assert len(track_radar(_parked(2.5, seed=11))) == 0


@pytest.mark.parametrize('doppler_var', [0.0, 1.0])
def test_the_tracks_of_a_standing_queue_stay_in_place(doppler_var):
    """Five cars 7 m apart stand in a queue through 20 s: each is one headless track at
    speed 0 that stays within a metre of its car, with and without the Doppler update."""
    cars = [straight((-10.0 - 7.0 * k, 3.0), (0.0, 0.0), 0.0, 20.0) for k in range(5)]
    dets = scans(cars, 20.0, np.random.default_rng(12))
    tracks = track_radar(dets, dataclasses.replace(TrackerConfig(), doppler_var=doppler_var))
    ids = np.unique(tracks.track_id)
    assert len(ids) == 5 and (tracks.speed == 0).all()
    for i in ids:
        xy = tracks.xy[tracks.track_id == i]
        car = np.array([-10.0 - 7.0 * round((-10.0 - xy[:, 0].mean()) / 7.0), 3.0])
        assert np.linalg.norm(xy - car, axis=1).max() < 1.0


def _t_junction_and_a_queue(rng):
    """Radar of 30 s: an east-west road driven both ways, traffic from the south turning
    right onto it, and on the north arm only a queue of five cars that stand throughout
    (right-hand traffic: on its entering lane, 12-40 m out)."""
    v = []
    for k in range(6):
        v.append(polyline([(-70, -1.75), (70, -1.75)], 10.0, 4.0 * k))
        v.append(polyline([(70, 1.75), (-70, 1.75)], 10.0, 2.0 + 4.0 * k))
        v.append(polyline([(1.75, -70), (1.75, -6), (6, -1.75), (70, -1.75)], 9.0, 1.0 + 4.5 * k))
    v += [straight((-1.75, 12.0 + 7.0 * k), (0.0, 0.0), 0.0, 30.0) for k in range(5)]
    return scans(v, 30.0, rng)


@pytest.mark.parametrize('seed', [0, 1])
def test_an_arm_only_a_standing_radar_queue_shows_is_found_through_the_tracker(seed):
    """End to end in raw mode: the queue's tracks are reported headless after
    ``standing_s`` and the topology step reads them as a queue (topology/standing.py), so
    the north arm is found; with standing reports off it is not."""
    dets = _t_junction_and_a_queue(np.random.default_rng(seed))

    def north(cfg):
        inter = estimate(dets, mode='raw', topology_samples=2000, lane_samples=0, seed=seed,
                         tracker_config=cfg).intersection
        return any(abs(a.angle - math.pi / 2) < math.radians(15) for a in inter.arms)
    assert north(TrackerConfig())
    assert not north(dataclasses.replace(TrackerConfig(), standing_s=0.0))


def test_a_window_of_radar_tracks_keeps_shorter_trajectory_parts():
    """Preprocessing per window: radar-tracker windows keep trajectory parts from
    ``radar_tracks_min_part_length`` (3 m), other windows from ``min_part_length`` (5 m). A
    vehicle seen from 16 m out, where the net cuts its road, leaves 4 m beyond
    ``part_outside`` (12 m): a part of a radar track, none of a tracked object."""
    from intersection_estimator.topology import TopologyEstimator
    xy = np.stack([np.linspace(16.0, 0.0, 33), np.zeros(33)], axis=1)     # 0.5 m a row
    track = Detections.make(xy, np.arange(33) * 0.05, heading=np.full(33, np.pi),
                            track_id=np.full(33, RADAR_TRACK_ID0))
    cfg = TopologyConfig()
    assert cfg.radar_tracks_min_part_length < 4.0 < cfg.min_part_length
    est = TopologyEstimator(cfg, 0)
    est.set_observations(track)
    assert est._pcfg.min_part_length == cfg.radar_tracks_min_part_length
    assert len(est._preprocessed(np.zeros(2), None)) == 1
    est.set_observations(dataclasses.replace(track, track_id=track.track_id - RADAR_TRACK_ID0))
    assert est._pcfg.min_part_length == cfg.min_part_length
    assert len(est._preprocessed(np.zeros(2), None)) == 0
