"""bench --family table1 | sumo | av2 (issue 15) and the Table I option of lanes
without traffic."""

import argparse

import pytest

from intersection_estimator import bench
from intersection_estimator.bench import BenchOptions, is_perfect, run_bench
from intersection_estimator.sim import SimConfig, simulate_scenario


def _cli(argv):
    ap = argparse.ArgumentParser()
    bench.register(ap.add_subparsers())
    args = ap.parse_args(argv)
    return args.func(args)


def test_sumo_family_oracle_is_perfect_and_has_a_floor():
    res = run_bench(BenchOptions(n=1, family='sumo', oracle=True, seed=7))
    s = res['summary']
    assert is_perfect(s) and s['topology_observed_accuracy'] == 1.0
    assert s['floor_cm_mean'] is not None and s['floor_cm_mean'] > 0
    assert res['config']['family'] == 'sumo' and res['config']['family_config']['arms'] == [3, 6]


def test_av2_family_runs_the_three_scenarios(capsys):
    assert _cli(['bench', '--family', 'av2', '--n', '10', '--oracle']) == 0
    out = capsys.readouterr().out
    assert 'family=av2' in out and 'n=3' in out and 'traffic-following floor' in out


def test_family_flags_are_checked(capsys):
    assert _cli(['bench', '--family', 'sumo', '--empty-lanes', '0.2', '--oracle']) == 2
    assert _cli(['bench', '--empty-lanes', '1.5', '--oracle']) == 2
    assert 'empty-lanes' in capsys.readouterr().err
    with pytest.raises(ValueError, match='family'):
        run_bench(BenchOptions(n=1, family='nope', oracle=True))


def test_table1_lanes_without_traffic_option():
    empty = [0, 0]
    for seed in range(6):
        base = simulate_scenario(seed)
        assert all(v > 0 for k, v in base.traffic.items() if not k.startswith('c_'))
        sc = simulate_scenario(seed, SimConfig(empty_lane_prob=0.3))
        assert [a.lanes_in for a in sc.gt.arms] == [a.lanes_in for a in base.gt.arms]
        zero = [k for k, v in sc.traffic.items() if v == 0 and not k.startswith('c_')]
        empty[0] += len(zero)
        empty[1] += len([k for k in sc.traffic if not k.startswith('c_')])
        assert sc.tracks          # at least one route survives
    assert 0.15 < empty[0] / empty[1] < 0.6
    res = run_bench(BenchOptions(n=3, oracle=True, empty_lanes=0.3))
    assert is_perfect(res['summary'])
    assert res['config']['sim_config']['empty_lane_prob'] == 0.3
