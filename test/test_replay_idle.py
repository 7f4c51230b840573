"""Issue 16: idle ticks cost nothing -- a converged estimate on unchanged data stops sampling
until new data arrive (the node's idle CPU, the replay across gaps in bag time)."""

from __future__ import annotations

import time

from intersection_estimator.pipeline import (IDLE_SAMPLING_TICKS, OnlineEstimator, PipelineConfig,
                                             needs_sampling)
from intersection_estimator.sim import simulate_scenario


def test_needs_sampling_rule():
    assert needs_sampling(True, 'CONVERGED', 100)            # new data: always
    assert needs_sampling(True, 'NO_DATA', 0)
    assert not needs_sampling(False, 'CONVERGED', 0)         # converged, nothing new: never
    assert needs_sampling(False, 'CONVERGING', 0)            # not converged: a few ticks more ...
    assert needs_sampling(False, 'CONVERGING', IDLE_SAMPLING_TICKS - 1)
    assert not needs_sampling(False, 'CONVERGING', IDLE_SAMPLING_TICKS)   # ... but bounded


def converged_estimator():
    dets = simulate_scenario(3).detections('raw')
    est = OnlineEstimator(PipelineConfig(topology_samples=2000, lanes_enabled=False), seed=1)
    est.add(dets)
    now = float(dets.t.max())
    for _ in range(IDLE_SAMPLING_TICKS + 2):
        r = est.tick(now)
        if r.state == 'CONVERGED':
            break
    return est, dets, now


def test_a_converged_estimate_on_unchanged_data_stops_sampling_until_new_data():
    est, dets, now = converged_estimator()
    assert est.idle
    before = est.result
    t0 = time.perf_counter()
    for _ in range(200):
        r = est.tick(now)
    per_tick = (time.perf_counter() - t0) / 200
    assert r.topology_samples == before.topology_samples      # not one sample drawn
    assert r.intersection is before.intersection and r.state == before.state
    assert not r.lanes_updated and r.timing_ms['total'] == 0.0
    assert per_tick < 0.005, per_tick                        # a sampling tick of 2000 costs ~100x this
    est.add(dets.subset(dets.t >= now - 1.0))                 # new data: sampling resumes
    assert not est.idle
    assert est.tick(now + 0.5).topology_samples > before.topology_samples


def test_unchanged_but_not_converged_samples_a_bounded_number_of_ticks():
    dets = simulate_scenario(3).detections('raw')
    # converge_window so long that the chain cannot converge: only the tick bound stops it
    from dataclasses import replace
    cfg = PipelineConfig(topology_samples=200, lanes_enabled=False)
    cfg = replace(cfg, topology=replace(cfg.topology, converge_window=10**9))
    est = OnlineEstimator(cfg, seed=1)
    est.add(dets)
    now = float(dets.t.max())
    drawn = [est.tick(now).topology_samples for _ in range(IDLE_SAMPLING_TICKS + 20)]
    assert est.result.state == 'CONVERGING'
    grew = sum(b > a for a, b in zip(drawn, drawn[1:]))
    assert grew == IDLE_SAMPLING_TICKS, grew
