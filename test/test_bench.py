"""Benchmark runner (issue 4): oracle sanity row, JSON interface, estimator plumbing."""

import argparse
import json
from types import SimpleNamespace

import numpy as np
import pytest

from intersection_estimator import bench
from intersection_estimator.bench import BenchOptions, format_table, is_perfect, run_bench
from intersection_estimator.cli import main
from intersection_estimator.evaluate import SUMMARY_KEYS
from intersection_estimator.model import Lanelet
from intersection_estimator.sim import SimConfig, simulate_scenario

CONFIG_KEYS = {'n', 'mode', 'samples', 'lane_samples', 'seed', 'jobs', 'oracle', 'estimator',
               'sim_config', 'package_version', 'machine', 'timing_note'}
CASE_KEYS = {'seed', 'true', 'estimate', 'metrics', 'timing_ms'}


def _cli(argv):
    ap = argparse.ArgumentParser()
    bench.register(ap.add_subparsers())
    args = ap.parse_args(argv)
    return args.func(args)


def test_oracle_is_perfect_and_json_has_documented_keys(tmp_path, capsys):
    out = tmp_path / 'bench.json'
    assert _cli(['bench', '--n', '3', '--oracle', '--seed', '5', '--json', str(out)]) == 0
    text = capsys.readouterr().out
    assert 'lane-level topology accuracy' in text and '92.28 %' in text
    assert text.count('100.00 %') >= 5
    doc = json.loads(out.read_text())
    assert set(doc) == {'config', 'summary', 'cases'}
    assert CONFIG_KEYS <= set(doc['config'])
    assert doc['config']['machine']['cpu_count'] >= 1
    assert doc['config']['sim_config'] == SimConfig().to_dict()
    assert set(SUMMARY_KEYS) <= set(doc['summary'])
    s = doc['summary']
    assert s['n'] == 3 and is_perfect(s)
    assert s['arm_accuracy'] == s['topology_accuracy'] == s['lane_recall'] == 1.0
    assert s['connectivity_recall'] == 1.0 and s['center_error_m_mean'] == 0.0
    assert [c['seed'] for c in doc['cases']] == [5, 6, 7]
    for c in doc['cases']:
        assert set(c) == CASE_KEYS
        assert {'center', 'arms'} <= set(c['true']) and c['estimate']['arms'] == c['true']['arms']
        assert c['metrics']['ok'] and c['metrics']['topology_correct']


def _shifted_gt_estimator(calls, shift=0.2, fail_seed=None):
    """Fake pipeline.estimate: the scenario's GT with every lane moved 0.2 m sideways."""
    def estimate(dets, *, mode, topology_samples, lane_samples, seed):
        calls.append((len(dets), mode, topology_samples, lane_samples, seed))
        if seed == fail_seed:
            raise RuntimeError('chain diverged')
        sc = simulate_scenario(seed)
        lanes = []
        for ll in sc.gt_lanelets:
            t = np.gradient(ll.center, axis=0)
            n = np.stack([-t[:, 1], t[:, 0]], 1) / np.linalg.norm(t, axis=1, keepdims=True)
            lanes.append(Lanelet(id='x' + ll.id, kind=ll.kind, arm=ll.arm, arm_to=ll.arm_to,
                                 left=ll.left, right=ll.right, center=ll.center + shift * n,
                                 successors=['x' + s for s in ll.successors]))
        return SimpleNamespace(intersection=sc.gt, lanelets=lanes,
                               timing_ms={'topology': 5.0 + seed, 'lanes': 7.0, 'total': 12.0 + seed})
    return estimate


def test_estimator_is_called_and_scored(monkeypatch):
    calls = []
    monkeypatch.setattr(bench, '_load_estimator', lambda: _shifted_gt_estimator(calls))
    bench._WARM.clear()
    res = run_bench(BenchOptions(n=3, mode='raw', samples=1234, lane_samples=456, seed=10))
    # one small untimed warm-up run per process, then one call per case
    assert calls[0][1:] == ('raw', 200, 200, 10)
    calls = calls[1:]
    assert [c[1:] for c in calls] == [('raw', 1234, 456, s) for s in (10, 11, 12)]
    assert all(c[0] == len(simulate_scenario(s).detections('raw')) for c, s in zip(calls, (10, 11, 12)))
    s = res['summary']
    assert s['topology_accuracy'] == 1.0 and s['lane_recall'] == 1.0
    assert s['lane_error_cm_mean'] == pytest.approx(20.0, abs=0.3)
    assert s['topology_ms_median'] == 16.0 and s['lanes_ms_median'] == 7.0
    assert s['total_ms_median'] == 23.0
    assert res['cases'][0]['timing_ms']['simulate'] > 0
    table = format_table(res)
    assert '55.4' in table and '84.90 %' in table   # raw-mode paper figures


def test_estimator_errors_become_failed_cases(monkeypatch):
    calls = []
    est = _shifted_gt_estimator(calls, fail_seed=1)
    res = run_bench(BenchOptions(n=3, seed=0, warmup=False), estimator=est)
    assert len(calls) == 3
    bad = res['cases'][1]['metrics']
    assert not bad['ok'] and 'chain diverged' in bad['reason'] and res['cases'][1]['estimate'] is None
    assert res['summary']['n_failed'] == 1
    assert res['summary']['topology_accuracy'] == pytest.approx(2 / 3)
    assert not is_perfect(res['summary'])


def test_lane_samples_zero_scores_topology_only():
    res = run_bench(BenchOptions(n=2, lane_samples=0, oracle=True))
    s = res['summary']
    assert s['topology_accuracy'] == 1.0
    assert s['lane_recall'] is None and s['lane_error_cm_mean'] is None


def test_no_estimator_module_means_exit_2(monkeypatch):
    def missing():
        raise ImportError('no pipeline yet')
    monkeypatch.setattr(bench, '_load_estimator', missing)
    assert _cli(['bench', '--n', '1']) == 2


def test_jobs_2_spawn_workers_give_the_same_cases():
    one = run_bench(BenchOptions(n=2, oracle=True, jobs=1))
    two = run_bench(BenchOptions(n=2, oracle=True, jobs=2))
    strip = [{k: v for k, v in c.items() if k != 'timing_ms'} for c in one['cases']]
    assert strip == [{k: v for k, v in c.items() if k != 'timing_ms'} for c in two['cases']]
    assert 'shared' in two['config']['timing_note']


def test_cost_model_lands_in_the_profile_and_its_table():
    """--cost-model: per case and pooled, the work per sample done vs needed (no timing
    asserted)."""
    from intersection_estimator.topology.cost_model import format_cost
    res = run_bench(BenchOptions(n=1, mode='raw', samples=600, lane_samples=0, seed=2,
                                 profile=True, cost_model=True))
    case = res['cases'][0]['profile']['cost_model']
    assert case['samples']['chain'] == 600 and case['observations'] > 0
    pooled = res['profile']['cost_model']
    assert pooled['cases'] == 1
    c = pooled['chain']
    assert 0 < c['must_entries_per_sample'] <= c['entries_per_sample']
    assert 0 < c['must_logs_per_sample'] <= c['logs_per_sample']
    assert 'x limit' in format_cost(pooled)


def test_no_radar_tracking_hands_the_estimator_the_paper_model(monkeypatch):
    """``--no-radar-tracking``: the estimator gets a disabled tracker config; by default it
    gets none (its own default: the tracker); the table's header says which."""
    seen = []

    def est(dets, *, mode, topology_samples, lane_samples, seed, **kw):
        seen.append(kw.get('tracker_config'))
        return _shifted_gt_estimator([])(dets, mode=mode, topology_samples=topology_samples,
                                         lane_samples=lane_samples, seed=seed)
    off = run_bench(BenchOptions(n=1, mode='raw', seed=3, warmup=False, radar_tracking=False), estimator=est)
    assert seen[-1] is not None and not seen[-1].enabled
    assert 'radar_tracking=off' in format_table(off)
    on = run_bench(BenchOptions(n=1, mode='raw', seed=3, warmup=False), estimator=est)
    assert seen[-1] is None and 'radar_tracking=on' in format_table(on)
    assert main(['bench', '--n', '1', '--oracle', '--mode', 'raw', '--no-radar-tracking']) == 0


def test_noise_options_reach_the_simulated_cases_and_bad_values_are_refused(tmp_path, capsys):
    """``--track-noise-corr`` / ``--position-noise``: the cases are simulated with them (the
    JSON's sim_config says so, the detections differ); values outside their range and the
    AV2 family (recorded, nothing simulated) exit 2 naming the option."""
    out = tmp_path / 'bench.json'
    assert _cli(['bench', '--n', '1', '--oracle', '--seed', '5', '--track-noise-corr', '0.9',
                 '--position-noise', '0.3', '--json', str(out)]) == 0
    cfg = json.loads(out.read_text())['config']['sim_config']
    assert cfg['track_noise_corr'] == 0.9 and cfg['position_noise'] == 0.3
    opts = BenchOptions(n=1, seed=5, track_noise_corr=0.9, position_noise=0.3)
    sc, _ = bench.make_case(opts, 0)
    plain, _ = bench.make_case(BenchOptions(n=1, seed=5), 0)
    assert sc.config.track_noise_corr == 0.9
    assert not np.array_equal(sc.detections('tracked').xy[:50], plain.detections('tracked').xy[:50])
    assert BenchOptions(turn_shape='corner').sim_config().turn_shape == 'corner'
    capsys.readouterr()
    for argv, name in ((['--track-noise-corr', '1.0'], '--track-noise-corr'),
                       (['--position-noise', '0'], '--position-noise'),
                       (['--family', 'av2', '--track-noise-corr', '0.5'], '--track-noise-corr'),
                       (['--family', 'sumo', '--turn-shape', 'corner'], '--turn-shape')):
        assert _cli(['bench', '--n', '1', '--oracle', *argv]) == 2
        assert name in capsys.readouterr().err
