"""Pipeline: one-shot estimate and the anytime OnlineEstimator (window, determinism, states)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from intersection_estimator.observations import Detections
from intersection_estimator.pipeline import OnlineEstimator, PipelineConfig, estimate
from intersection_estimator.sim import simulate_scenario
from intersection_estimator.topology import TopologyConfig


@pytest.fixture(scope='module')
def scenario():
    return simulate_scenario(11)


def _json(result):
    return (result.intersection.to_json(), [l.to_json() for l in result.lanelets])


def test_estimate_is_deterministic_per_seed(scenario):
    dets = scenario.detections('tracked')
    a = estimate(dets, mode='tracked', topology_samples=1500, lane_samples=3000, seed=3)
    b = estimate(dets, mode='tracked', topology_samples=1500, lane_samples=3000, seed=3)
    assert _json(a) == _json(b)
    assert a.topology_samples == 1500 * TopologyConfig().chains_tracked and a.lane_samples > 0
    assert set(a.timing_ms) == {'tracking', 'topology', 'lanes', 'total'}


def test_raw_mode_ignores_track_ids_and_skips_the_lane_mcmc(scenario):
    r = estimate(scenario.detections('tracked'), mode='raw', topology_samples=1500, seed=0)
    assert r.lane_samples == 0
    assert {l.kind for l in r.lanelets} <= {'entering', 'leaving'}


def test_bad_mode_is_refused(scenario):
    with pytest.raises(ValueError, match='mode'):
        estimate(scenario.detections('tracked'), mode='lidar')


@pytest.mark.parametrize('field, value', [('budget_s', 0.0), ('window_s', -1.0), ('lane_share', 1.0)])
def test_config_validation_names_the_field(field, value):
    with pytest.raises(ValueError, match=field):
        replace(PipelineConfig(), **{field: value}).validate()


def test_online_without_data_is_no_data():
    est = OnlineEstimator()
    r = est.tick(0.0)
    assert r.intersection is None and r.state == 'NO_DATA' and r.lanelets == []


def test_online_window_forgets_old_and_caps_count():
    cfg = replace(PipelineConfig(), window_s=10.0, max_observations=100, topology_samples=10, lane_samples=0)
    est = OnlineEstimator(cfg)
    for t in range(30):
        est.add(Detections.make(np.random.default_rng(t).normal(size=(20, 2)), float(t)))
    est.tick(29.0)
    win = est.window()
    assert len(win) <= 100 and win.t.min() >= 19.0
    assert est.add(Detections.make([[np.nan, 0.0], [1.0, 1.0]], 30.0)) == 1


def test_online_ticks_are_deterministic_and_reach_the_topology(scenario):
    cfg = replace(PipelineConfig(), topology_samples=2000, lane_samples=2000)

    def run():
        est = OnlineEstimator(cfg, seed=5)
        for stamp, d in scenario.frames('tracked'):
            est.add(d)
            if round(stamp * 10) % 20 == 0:
                est.tick(stamp)
        return est.tick(stamp)

    a, b = run(), run()
    assert _json(a) == _json(b)
    assert len(a.intersection.arms) == len(scenario.gt.arms)
    assert a.lanelets and {l.kind for l in a.lanelets} == {'entering', 'leaving', 'connector'}


class _Topo:
    """A topology estimator stand-in that records its wall budgets and reports ``best``."""

    def __init__(self, best):
        self.best, self.budgets = best, []

    def run(self, n_samples=None, time_budget_s=None):
        self.budgets.append(time_budget_s)
        return 0


def test_topology_stops_early_when_the_lane_initialisation_is_due(scenario):
    """Wall mode: with a known lane-initialisation cost the topology first runs only until
    that initialisation would still end in time; it goes on to its own end only when the
    lane course is not initialised this tick (the initialisation cannot be cut short)."""
    import time
    dets = scenario.detections('tracked')
    est = OnlineEstimator(PipelineConfig(), seed=0)
    est._topo = topo = _Topo(scenario.gt)
    t0 = time.perf_counter()
    topo_end, lanes_start = t0 + 60.0, t0 + 20.0       # generous: no test timing depends on it
    assert est._lane_step(scenario.gt, dets, now=5.0) == 'initialise'   # no lanes yet
    est._topology_phase(dets, False, 5.0, topo_end, lanes_start, 0.15)
    assert len(topo.budgets) == 1 and topo.budgets[0] <= 20.0 + 1e-6
    # the lane course stands for this topology and is not due before lane_period
    est._lane_topo, est._lane_t = scenario.gt, 4.5
    assert est._lane_step(scenario.gt, dets, now=5.0) == 'keep'
    topo.budgets.clear()
    est._topology_phase(dets, False, 5.0, topo_end, lanes_start, 0.15)
    assert len(topo.budgets) == 2 and topo.budgets[1] > 30.0
    # a due lane run without initialisation does not stop the topology either
    assert est._lane_step(scenario.gt, dets, now=9.0) == 'run'
    assert est._lane_step(None, dets, now=9.0) == 'none'


def test_a_lane_reinitialisation_without_room_is_spread_over_three_ticks(scenario):
    """Wall mode: when even the least topology share leaves no room for re-initialising
    the lane course (the node's tick that also publishes the waiting lanelets), the tick is
    the topology's and the last lanelets stand; the next tick prepares the first half
    (the last lanelets still stand), the one after finishes it. The plan counts the MAP
    state's report beside both halves."""
    import time
    dets = scenario.detections('tracked')
    est = OnlineEstimator(PipelineConfig(), seed=0)
    est._topo = topo = _Topo(scenario.gt)
    est._report_s.append(0.012)
    est._prepare_s.append(0.050)
    est._finish_s.append(0.030)
    t0 = time.perf_counter()
    assert est._lanes_start(t0 + 1.0, 0.15) == pytest.approx(t0 + 1.0 - 0.092 - 0.0075)
    topo_end, no_room = t0 + 60.0, t0 + 0.05    # whole: 92 ms + least share > 50 ms left
    est._topology_phase(dets, False, 5.0, topo_end, no_room, 0.15)
    assert not est._no_room                      # the first initialisation never waits
    est._lanes.initialise(scenario.gt, dets)
    est._lane_topo, est._lane_stale, est._lane_t = scenario.gt, True, 0.0   # new data since
    before = [l.id for l in est._lanes.lanelets]

    def tick(deadline):
        topo.budgets.clear()
        est._topology_phase(dets, False, 5.0, topo_end, deadline, 0.15)
        step = est._lane_step(scenario.gt, dets, 5.0)
        lanes = est._tick_lanes(scenario.gt, dets, 5.0, None, 0.15)
        return step, [l.id for l in lanes]

    step, ids = tick(time.perf_counter() + 0.05)
    assert step == 'defer' and ids == before and not est._lanes_updated
    assert len(topo.budgets) == 1 and topo.budgets[0] > 30.0       # the topology keeps the tick
    step, ids = tick(time.perf_counter() + 0.05)
    assert step == 'prepare' and est._lanes.pending and ids == before and not est._lanes_updated
    assert topo.budgets[0] < 0.05                # stops for the report and the first half only
    step, ids = tick(time.perf_counter() + 0.05)
    assert step == 'finish' and not est._lanes.pending and est._lanes_updated
    assert est._lane_topo is scenario.gt and not est._lane_stale
    # with room a re-initialisation is done whole, in one tick
    est._lane_stale, est._lane_t = True, 0.0
    step, _ = tick(time.perf_counter() + 20.0)
    assert step == 'initialise' and not est._lanes.pending


def test_the_lane_course_stands_while_the_topology_stays_within_its_tolerance(scenario):
    """A MAP state that moves less than 1 m / 3 deg keeps the lane course (no re-initialisation
    when it merely crosses a grid line); more, another lane count or another arm set does not."""
    from dataclasses import replace as rep
    from intersection_estimator.pipeline import same_lanes
    gt = scenario.gt
    moved = rep(gt, center=np.asarray(gt.center, float) + [0.6, -0.5],
                arms=[rep(a, angle=a.angle + np.radians(2.5)) for a in gt.arms])
    assert same_lanes(moved, gt) and same_lanes(gt, gt)
    assert not same_lanes(rep(gt, center=np.asarray(gt.center, float) + [1.2, 0.0]), gt)
    assert not same_lanes(rep(gt, arms=[rep(a, angle=a.angle + np.radians(4.0)) for a in gt.arms]), gt)
    fewer = [rep(gt.arms[0], lanes_in=gt.arms[0].lanes_in + 1)] + list(gt.arms[1:])
    assert not same_lanes(rep(gt, arms=fewer), gt)
    assert not same_lanes(rep(gt, arms=list(gt.arms[1:])), gt) and not same_lanes(gt, None)
    # an arm near +-180 deg whose angle wraps stays the same arm
    wrap = rep(gt, arms=[rep(gt.arms[0], angle=np.pi - 0.01)] + list(gt.arms[1:]))
    wrapped = rep(gt, arms=[rep(gt.arms[0], angle=-np.pi + 0.01)] + list(gt.arms[1:]))
    assert same_lanes(wrapped, wrap)
    est = OnlineEstimator(PipelineConfig(), seed=0)
    dets = scenario.detections('tracked')
    est._lane_topo, est._lane_stale, est._lane_t = gt, True, 4.5
    assert est._lane_step(moved, dets, now=5.0) == 'keep'        # within the lane period
    assert est._lane_step(rep(gt, center=np.asarray(gt.center, float) + [3.0, 0.0]), dets, now=5.0) == 'initialise'
