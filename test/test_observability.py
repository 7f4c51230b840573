"""Observability: a straight road gives no intersection (issue 15 part 4)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from road_scenes import straight_road
from topology.scenes import easy_intersection, scene

from intersection_estimator.estimate_io import dumps, estimate_to_dict
from intersection_estimator.observability import (INTERSECTION, NO_DATA, ROAD,
                                                  ObservabilityConfig, assess)
from intersection_estimator.observations import Detections
from intersection_estimator.pipeline import OnlineEstimator, PipelineConfig, estimate
from intersection_estimator.sim import simulate_scenario

MODES = ('tracked', 'heading', 'raw')


def _road(n_lanes=1):
    return easy_intersection(2, lanes=((n_lanes, n_lanes),) * 2, angles_deg=[-170, 10])


def _tee():
    return easy_intersection(3, lanes=((1, 1),) * 3, angles_deg=[-170, -80, 10])


@pytest.mark.parametrize('mode', MODES)
def test_synthetic_road_is_a_road_and_a_tee_is_an_intersection(mode):
    road = assess(scene(_road(2), mode, seed=1, per_lane=3, clutter=40))
    assert road.state == ROAD and not road.intersection
    assert road.intersection_confidence < 0.5 and road.on_axis > 0
    assert abs(((road.axis_deg - 10.0) + 90) % 180 - 90) < 5.0
    tee = assess(scene(_tee(), mode, seed=1, per_lane=3, clutter=40))
    assert tee.state == INTERSECTION and tee.intersection_confidence >= 0.5


@pytest.mark.parametrize('seed', [0, 6, 28])
@pytest.mark.parametrize('mode', MODES)
def test_simulated_through_traffic_is_a_road_the_full_scene_is_not(seed, mode):
    sc = straight_road(seed)
    assert sc is not None
    assert assess(sc.detections(mode)).state == ROAD
    assert assess(simulate_scenario(seed).detections(mode)).state == INTERSECTION


def test_one_turning_vehicle_is_not_yet_an_intersection_two_are():
    """The threshold counts passages: a single off-axis track stays below 0.5."""
    rng = np.random.default_rng(3)
    s = np.arange(-60.0, 60.0, 1.0)
    parts = [Detections.make(np.stack([s, np.full_like(s, y)], 1) + rng.normal(0, 0.3, (len(s), 2)),
                             np.arange(len(s)) * 0.1, heading=h, track_id=i, speed=10.0)
             for i, (y, h) in enumerate([(-1.75, 0.0), (1.75, np.pi)] * 3)]
    side = np.arange(2.0, 50.0, 1.0)

    def turner(i):
        xy = np.stack([np.zeros_like(side), side], 1) + rng.normal(0, 0.3, (len(side), 2))
        return Detections.make(xy, 10.0 + np.arange(len(side)) * 0.1, heading=np.pi / 2,
                               track_id=100 + i, speed=10.0)

    one = assess(Detections.concat(parts + [turner(0)]))
    two = assess(Detections.concat(parts + [turner(0), turner(1)]))
    assert one.state == ROAD and one.off_axis == 1 and 0 < one.intersection_confidence < 0.5
    assert two.state == INTERSECTION and two.off_axis == 2 and two.intersection_confidence == 0.5


def test_short_false_tracks_and_parked_vehicles_are_no_arm():
    rng = np.random.default_rng(4)
    road = scene(_road(), 'tracked', seed=2, per_lane=2)
    false = [Detections.make(rng.uniform(-60, 60, (1, 2)) + rng.normal(0, 1, (4, 2)),
                             np.arange(4) * 0.1, heading=rng.uniform(-np.pi, np.pi),
                             track_id=5000 + i) for i in range(60)]
    parked = Detections.make(np.array([0.0, 25.0]) + np.outer(np.arange(40) * 0.5, [0, 1]),
                             np.arange(40) * 0.1, heading=np.pi / 2, track_id=9000, speed=0.0)
    o = assess(Detections.concat([road] + false + [parked]))
    assert o.state == ROAD, o


def test_no_data_and_static_only():
    assert assess(None).state == NO_DATA
    assert assess(Detections.empty()).state == NO_DATA
    static = Detections.make(np.zeros((10, 2)), doppler=0.0, sensor_xy=(0.0, 0.0))
    assert assess(static).state == NO_DATA


def test_bad_parameter_is_named():
    with pytest.raises(ValueError, match='axis_tol_deg'):
        assess(Detections.empty(), ObservabilityConfig(axis_tol_deg=0.0))


def test_pipeline_reports_it_in_stats_and_estimate_json():
    sc = straight_road(0)
    res = estimate(sc.detections('tracked'), mode='tracked', topology_samples=600,
                   lane_samples=500, seed=0)
    assert res.observability.state == ROAD
    doc = json.loads(dumps(estimate_to_dict(res.intersection, res.lanelets, res.stats())))
    ob = doc['stats']['observability']
    assert ob['state'] == ROAD and ob['intersection'] is False
    assert ob['intersection_confidence'] < 0.5


def test_online_estimator_carries_the_verdict():
    sc = simulate_scenario(3)
    on = OnlineEstimator(PipelineConfig(topology_samples=300, lane_samples=300), seed=0)
    assert on.tick(0.0).observability.state == NO_DATA
    on.add(sc.detections('tracked'))
    res = on.tick(float(sc.duration))
    assert res.observability.state == INTERSECTION
    assert res.stats()['observability']['intersection'] is True


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**31 - 1), st.integers(1, 400), st.floats(0.5, 50.0))
def test_bin_medians_equal_numpy_median_per_bin(seed, n, bin_m):
    """The two-sort ridge medians are numpy.median over each bin (bins of >= min_count rows)."""
    from intersection_estimator.observability import _bin_medians
    g = np.random.default_rng(seed)
    s = np.round(g.uniform(-100, 100, n), int(g.integers(0, 3)))     # ties included
    lat = np.round(g.normal(0, 20, n), int(g.integers(0, 3)))
    b = np.floor((s - s.min()) / bin_m).astype(np.int64)
    want = [(np.median(s[b == k]), np.median(lat[b == k])) for k in np.unique(b) if (b == k).sum() >= 3]
    mids, ridge = _bin_medians(bin_m, s, lat, min_count=3)
    np.testing.assert_allclose(mids, [w[0] for w in want], atol=1e-9)
    np.testing.assert_allclose(ridge, [w[1] for w in want], atol=1e-9)


def test_unsorted_stamps_count_like_sorted_ones():
    from intersection_estimator.observability import ObservabilityConfig, _cell_evidence
    g = np.random.default_rng(3)
    xy, t = g.uniform(0, 40, (500, 2)), np.repeat(np.arange(50) * 0.1, 10)
    o = g.permutation(500)
    cfg = ObservabilityConfig()
    assert _cell_evidence(xy, t, cfg) == _cell_evidence(xy[o], t[o], cfg) > 0


@settings(max_examples=60, deadline=None)
@given(st.integers(1, 2000), st.floats(1.0, 80.0), st.integers(1, 300), st.integers(0, 2**31))
def test_cell_evidence_one_pass_equals_the_sort(n, spread, stamps, seed):
    """The dense one-pass count of stamps per square (rows in time order) gives what the
    sort of (square, stamp) pairs gives."""
    from intersection_estimator import observability as O
    rng = np.random.default_rng(seed)
    xy = rng.normal(0.0, spread, (n, 2))
    t = np.sort(rng.integers(0, stamps, n)).astype(float) * 0.1
    cfg = O.ObservabilityConfig().validate()
    dense = O._cell_evidence(xy, t, cfg)
    old, O._DENSE_CELLS = O._DENSE_CELLS, 0
    try:
        assert O._cell_evidence(xy, t, cfg) == dense
    finally:
        O._DENSE_CELLS = old


def _shuffled(dets, seed):
    return dets.subset(np.random.default_rng(seed).permutation(len(dets)))


@pytest.mark.parametrize('mode', MODES)
def test_compiled_verdict_equals_the_numpy_reference_bit_for_bit(mode):
    """The compiled passes (moving rows, ridge medians, squares, track extents) give the
    verdict of the numpy code they replaced (test/reference/observability.py), every float
    equal, on simulated scenes in time order and shuffled (the sorting fallbacks), on
    roads and on synthetic scenes with clutter."""
    from reference.observability import assess_reference
    from intersection_estimator.pipeline import in_mode
    cases = [in_mode(simulate_scenario(seed).detections(mode), mode) for seed in range(8)]
    cases += [in_mode(straight_road(seed).detections(mode), mode) for seed in (0, 6)]
    cases += [scene(_tee(), mode, seed=1, per_lane=3, clutter=40),
              scene(_road(2), mode, seed=2, per_lane=2, clutter=80)]
    cases += [_shuffled(d, i) for i, d in enumerate(cases[:3])]
    for dets in cases:
        assert assess(dets) == assess_reference(dets)
    cfg = ObservabilityConfig(min_extent_m=0.0, cell_min=1, min_speed=0.0)
    for dets in cases[:2] + cases[-1:]:
        assert assess(dets, cfg) == assess_reference(dets, cfg)


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**31 - 1), st.integers(2, 300), st.booleans())
def test_compiled_verdict_equals_the_reference_on_random_rows(seed, n, radar):
    """Random rows (ties in position and stamp, some slow or non-finite): same verdict."""
    from reference.observability import assess_reference
    g = np.random.default_rng(seed)
    xy = np.round(g.normal(0.0, 40.0, (n, 2)), int(g.integers(0, 2)))
    xy[g.random(n) < 0.02] = np.nan
    t = np.sort(np.round(g.uniform(0.0, 20.0, n), 1))
    kw = dict(doppler=g.normal(0.0, 5.0, n)) if radar else \
        dict(heading=g.uniform(-np.pi, np.pi, n), track_id=g.integers(-1, 6, n),
             speed=g.uniform(0.0, 10.0, n))
    dets = Detections.make(xy, t, **kw)
    assert assess(dets) == assess_reference(dets)
