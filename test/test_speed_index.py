"""Speed index and phase profile of the benchmark (issue 18, first slice). No timing is
asserted here (timing lives in the benchmark): the tests check the workload is fixed, the
figures are divided by the index the run measured, and the profile adds up."""

from __future__ import annotations

import argparse
import json
import re
from types import SimpleNamespace

import pytest
from test_bench import _shifted_gt_estimator

from intersection_estimator import bench, speed_index as SI
from intersection_estimator.bench import BenchOptions, run_bench
from intersection_estimator.pipeline import _phases, estimate
from intersection_estimator.sim import simulate_scenario


def test_reference_workload_is_fixed_and_timed():
    a_ms, a = SI.reference_once()
    b_ms, b = SI.reference_once()
    assert a == b and a[0] > 0            # the chain accepts moves, the same ones every time
    assert a_ms > 0 and b_ms > 0
    m = SI.SpeedMeter()
    m.warm(3)
    m.add(1e3)                            # a preempted repetition counts in proportion (the mean)
    r = m.result()
    assert r['repetitions'] == 4 and r['version'] == SI.REF_VERSION
    assert r['ref_ms'] == pytest.approx(sum(m.samples) / 4) and r['min_ms'] <= r['median_ms'] < 1e3
    assert SI.SpeedMeter().result()['ref_ms'] is None


def test_reference_refuses_a_changed_workload(monkeypatch):
    SI.reference_once()
    monkeypatch.setattr(SI._REF, 'scores0', SI._REF.scores0 + 1.0)
    with pytest.raises(RuntimeError, match='not deterministic'):
        SI.reference_once()


def test_after_case_repetitions_stay_within_their_share(monkeypatch):
    monkeypatch.setattr(SI, '_SPENT', {'reference_ms': 0.0, 'cases_ms': 0.0})
    first = SI.after_case(1e6)                  # a long case: a repetition
    assert first is not None and first > 0
    assert SI.after_case(0.0) is not None       # still well within 25 % of 1e6 ms
    monkeypatch.setattr(SI, '_SPENT', {'reference_ms': 10.0, 'cases_ms': 0.0})
    assert SI.after_case(1.0) is None           # 10 ms spent on 1 ms of cases: skip


def test_relative_figures():
    assert SI.in_ref(30.0, 12.0) == 2.5 and SI.in_ref(None, 12.0) is None and SI.in_ref(3.0, None) is None
    rel = SI.relative_summary({'topology_ms_median': 30.0, 'lanes_ms_p95': None, 'n': 3}, 10.0)
    assert rel == {'topology_ref_median': 3.0, 'lanes_ref_p95': None}


def test_bench_reports_the_index_beside_every_time(monkeypatch, tmp_path, capsys):
    monkeypatch.setattr(bench, '_load_estimator', lambda: _shifted_gt_estimator([]))
    ap = argparse.ArgumentParser()
    bench.register(ap.add_subparsers())
    out = tmp_path / 'b.json'
    args = ap.parse_args(['bench', '--n', '3', '--seed', '4', '--json', str(out)])
    assert args.func(args) == 0
    text = capsys.readouterr().out
    doc = json.loads(out.read_text())
    index, s = doc['config']['speed_index'], doc['summary']
    # 5 repetitions before, one after each case (in the case's process, unless they cost more
    # than REF_SHARE of the cases' time), 5 after
    after = [c['timing_ms']['reference'] for c in doc['cases'] if 'reference' in c['timing_ms']]
    assert index['repetitions'] == 5 + len(after) + 5 and index['ref_ms'] > 0
    assert all(ms > 0 for ms in after)
    for step in ('topology', 'lanes', 'total'):
        for q in ('median', 'p95'):
            # (the JSON rounds to 4 digits)
            assert s[f'{step}_ref_{q}'] == pytest.approx(s[f'{step}_ms_{q}'] / index['ref_ms'],
                                                         rel=1e-3, abs=1e-4)
    # the table prints the unrounded figures to 2 digits: equal to the JSON's within that rounding
    shown = re.search(r'\(= ([0-9.]+) / ([0-9.]+) x ref\)', text)
    assert shown is not None
    assert float(shown[1]) == pytest.approx(s['topology_ref_median'], abs=0.0051)
    assert float(shown[2]) == pytest.approx(s['topology_ref_p95'], abs=0.0051)
    assert 'speed index: ref' in text and 'docs/benchmark.md' in text
    assert 'profile' not in doc and 'profile' not in doc['cases'][0]


def test_oracle_measures_no_index():
    res = run_bench(BenchOptions(n=1, oracle=True, seed=2))
    assert res['config']['speed_index'] is None and 'reference' not in res['cases'][0]['timing_ms']


def test_profile_of_the_estimator_adds_up():
    res = run_bench(BenchOptions(n=2, mode='tracked', samples=300, lane_samples=300, seed=1,
                                 profile=True))
    prof = res['profile']
    assert prof['cases'] == 2 and all('profile' in c for c in res['cases'])
    phases = prof['phases']
    topo_phases = {f'topology_{k}' for k in ('preprocess', 'rescore', 'initialise', 'chain', 'refit',
                                              'descent', 'other', 'report')}
    assert topo_phases | {'lanes_initialise', 'lanes_mcmc', 'lanes_other'} <= set(phases)
    assert phases['topology_chain']['mean_ms'] > 0 and phases['topology_preprocess']['mean_ms'] > 0
    assert sum(p['share'] for p in phases.values()) == pytest.approx(1.0)
    assert prof['counters']['topology_preprocess'] >= 1 and prof['counters']['topology_chains'] >= 1
    for c in res['cases']:          # the phases are the estimator's time, nothing else
        t, ph = c['timing_ms'], c['profile']['phases_ms']
        assert sum(v for k, v in ph.items() if k.startswith('topology_')) <= t['topology'] + 1e-6
        assert sum(ph.values()) <= t['total'] + 1e-6
        assert sum(ph.values()) > 0.9 * t['total']
    table = SI.format_profile(prof, 'tracked')
    assert 'topology_chain' in table and 'lanes_mcmc' in table and 'x ref' in table


def test_profile_reads_topology_timers_when_the_estimator_has_them():
    """TopologyEstimator's phase timers (``timings`` [s], as the lane estimator keeps them)
    land in the profile as ``topology_<name>`` [ms]; ``topology_other`` is the rest."""
    topo = SimpleNamespace(timings={'chain': 0.010, 'descent': 0.002})
    ph = _phases(topo, (0.0, 0.001, 0.020, 0.021, 0.030), {'mcmc': 0.005})
    assert ph['topology_chain'] == pytest.approx(10.0) and ph['topology_descent'] == pytest.approx(2.0)
    assert ph['topology_other'] == pytest.approx(8.0) and ph['lanes_mcmc'] == pytest.approx(5.0)
    assert ph['lanes_other'] == pytest.approx(4.0)
    plain = estimate(simulate_scenario(0).detections('raw'), mode='raw', topology_samples=200, seed=0)
    # the radar tracker's time is its own phase and part of the total
    assert plain.timing_ms.keys() == {'tracking', 'topology', 'lanes', 'total'}
    assert plain.phases_ms['tracking'] > 0 and plain.timing_ms['total'] >= plain.timing_ms['tracking']
    assert plain.phases_ms['topology_preprocess'] > 0 and plain.phases_ms['topology_chain'] > 0
    assert plain.counters['topology_chains'] >= 1
