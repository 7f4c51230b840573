"""Evaluator (DESIGN.md §5) and estimate.json / gt.json IO (DESIGN.md §4)."""

import argparse
import copy
import json

import numpy as np
import pytest

from intersection_estimator.estimate_io import (
    dumps, gt_to_dict, read_estimate, read_gt, write_estimate, write_gt)
from intersection_estimator.evaluate import (
    SUMMARY_KEYS, aggregate, evaluate, orthogonal_distances, register)
from intersection_estimator.sim import simulate_scenario


@pytest.fixture(scope='module')
def scenario():
    return simulate_scenario(3)


@pytest.fixture(scope='module')
def gt(scenario):
    return json.loads(dumps(gt_to_dict(scenario)))


def _shift(poly, dist):
    """Offset a polyline by ``dist`` along its left normal."""
    p = np.asarray(poly, float)
    t = np.gradient(p, axis=0)
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    return (p + dist * np.stack([-t[:, 1], t[:, 0]], axis=1)).tolist()


def _without_arm(doc, k):
    """Estimate that misses arm k (its lanes and connectors gone, indices re-numbered)."""
    d = copy.deepcopy(doc)
    d['arms'].pop(k)
    keep = [x for x in d['lanes'] if k not in (x['arm'], x['arm_to'])]
    ids = {x['id'] for x in keep}
    for x in keep:
        x['arm'] -= x['arm'] > k
        x['arm_to'] -= x['arm_to'] > k
        x['successors'] = [s for s in x['successors'] if s in ids]
    d['lanes'] = keep
    return d


def test_perfect_estimate_scores_perfectly(gt):
    m = evaluate(gt, gt)
    assert m['ok'] and m['reason'] is None
    assert m['arm_correct'] and m['topology_correct']
    assert m['center_error_m'] == 0.0 and m['angle_error_deg'] == 0.0
    assert m['lane_error_cm'] < 0.01
    assert m['lane_recall'] == m['lane_precision'] == m['connectivity_recall'] == 1.0
    assert m['lanes_matched'] == m['lanes_true'] == m['lanes_est'] == len(gt['lanes'])


def test_lateral_shift_gives_its_distance(gt):
    est = copy.deepcopy(gt)
    for x in est['lanes']:
        for key in ('center_line', 'left', 'right'):
            x[key] = _shift(x[key], 0.2)
    m = evaluate(est, gt)
    assert m['lane_error_cm'] == pytest.approx(20.0, abs=0.3)
    assert m['lane_recall'] == 1.0 and m['topology_correct']
    far = copy.deepcopy(gt)
    for x in far['lanes']:
        x['center_line'] = _shift(x['center_line'], 2.0)   # beyond the 1.5 m gate
    m = evaluate(far, gt)
    assert m['lanes_matched'] == 0 and m['lane_recall'] == 0.0 and m['lane_error_cm'] is None


def test_center_and_angle_errors(gt):
    est = copy.deepcopy(gt)
    est['center'] = [gt['center'][0] + 3.0, gt['center'][1] - 4.0]
    for a in est['arms']:
        a['angle_deg'] += 2.0
    m = evaluate(est, gt)
    assert m['center_error_m'] == pytest.approx(5.0)
    assert m['angle_error_deg'] == pytest.approx(2.0)
    assert m['topology_correct']


def test_missing_arm_fails_topology(gt):
    m = evaluate(_without_arm(gt, 1), gt)
    assert m['ok'] and not m['arm_correct'] and not m['topology_correct']
    assert m['n_arms_est'] == m['n_arms_true'] - 1
    assert m['angle_error_deg'] == pytest.approx(0.0, abs=1e-6)  # the others still match
    assert 0 < m['lane_recall'] < 1 and m['lane_precision'] == 1.0


def test_wrong_lane_count_fails_only_lane_level_topology(gt):
    est = copy.deepcopy(gt)
    est['arms'][0]['lanes_in'] += 1
    m = evaluate(est, gt)
    assert m['arm_correct'] and not m['topology_correct']


def test_arm_order_and_lane_ids_do_not_matter(gt):
    est = copy.deepcopy(gt)
    n = len(est['arms'])
    perm = np.random.default_rng(0).permutation(n)          # new position of old arm i
    arms = [None] * n
    for old, new in enumerate(perm):
        arms[new] = est['arms'][old]
    est['arms'] = arms
    rename = {x['id']: f'lane-{i}' for i, x in enumerate(reversed(est['lanes']))}
    for x in est['lanes']:
        x['id'] = rename[x['id']]
        x['successors'] = [rename[s] for s in x['successors']]
        x['arm'] = int(perm[x['arm']])
        x['arm_to'] = int(perm[x['arm_to']]) if x['arm_to'] >= 0 else -1
    est['lanes'].reverse()
    a, b = evaluate(est, gt), evaluate(gt, gt)
    assert a == b


def test_connectivity_counts_detached_connectors(gt):
    est = copy.deepcopy(gt)
    for x in est['lanes']:
        if x['kind'] == 'entering':
            x['successors'] = x['successors'][1:]   # drop one link per entering lane
    m = evaluate(est, gt)
    n_enter = sum(x['kind'] == 'entering' for x in gt['lanes'])
    assert m['connectors_matched'] == sum(x['kind'] == 'connector' for x in gt['lanes'])
    assert m['connectors_connected'] == m['connectors_matched'] - n_enter
    assert m['lane_recall'] == 1.0


def test_recall_counts_only_lanes_with_traffic_precision_all_estimates(gt):
    no_traffic = [x['id'] for x in gt['lanes'] if x['traffic'] == 0]
    assert no_traffic
    est = copy.deepcopy(gt)
    est['lanes'] = [x for x in est['lanes'] if x['id'] not in no_traffic]
    m = evaluate(est, gt)
    assert m['lane_recall'] == 1.0 and m['lane_precision'] == 1.0
    bogus = copy.deepcopy(est['lanes'][0]) | {'id': 'bogus'}
    bogus['center_line'] = _shift(bogus['center_line'], 30.0)
    est['lanes'].append(bogus)
    m = evaluate(est, gt)
    assert m['lane_precision'] == pytest.approx((len(est['lanes']) - 1) / len(est['lanes']))
    est['lanes'] = est['lanes'][1:]
    assert evaluate(est, gt)['lane_recall'] < 1.0


@pytest.mark.parametrize('breaker, needle', [
    (lambda d: d.pop('center'), 'center'),
    (lambda d: d.pop('lanes'), 'lanes'),
    (lambda d: d['center'].__setitem__(0, float('nan')), 'finite'),
    (lambda d: d.__setitem__('arms', 'four'), 'arms'),
    (lambda d: d['arms'][0].__setitem__('lanes_in', 'two'), 'lanes_in'),
    (lambda d: d['arms'][0].__setitem__('lanes_out', 1.5), 'lanes_out'),
    (lambda d: d['arms'][1].pop('angle_deg'), 'angle_deg'),
    (lambda d: d['lanes'][0].__setitem__('center_line', [[0.0, None]]), 'center_line'),
    (lambda d: d['lanes'][2]['center_line'][1].__setitem__(0, float('inf')), 'finite'),
    (lambda d: d['lanes'][0].__setitem__('arm', 17), 'arm'),
    (lambda d: d['lanes'][0].__setitem__('kind', 'ramp'), 'kind'),
    (lambda d: d['lanes'][1].__setitem__('id', d['lanes'][0]['id']), 'duplicate'),
    (lambda d: d['lanes'].__setitem__(0, 'lane'), 'object'),
])
def test_malformed_estimate_is_a_failed_case(gt, breaker, needle):
    est = copy.deepcopy(gt)
    breaker(est)
    m = evaluate(est, gt)
    assert m['ok'] is False and needle in m['reason']
    assert not m['arm_correct'] and not m['topology_correct']
    assert m['lanes_true_traffic'] > 0 and m['lane_recall'] == 0.0


@pytest.mark.parametrize('bad', [None, [], 'estimate', {}, {'center': [0, 0]}])
def test_not_even_an_object_is_a_failed_case(gt, bad):
    m = evaluate(bad, gt)
    assert m['ok'] is False and m['reason']


def test_orthogonal_distance_ignores_points_beyond_the_ends():
    line = np.array([[0.0, 0.0], [10.0, 0.0]])
    d = orthogonal_distances(np.array([[5.0, 0.3], [-1.0, 0.3], [11.0, -0.3], [0.0, -0.5]]), line)
    assert d[0] == pytest.approx(0.3) and d[3] == pytest.approx(0.5)
    assert np.isnan(d[1]) and np.isnan(d[2])


def test_aggregate_pools_cases(gt):
    good = evaluate(gt, gt)
    bad = evaluate({}, gt)
    miss = evaluate(_without_arm(gt, 0), gt)
    s = aggregate([good, bad, miss], [{'topology': 10.0, 'lanes': 20.0, 'total': 30.0},
                                      None, {'topology': 30.0, 'lanes': 40.0, 'total': 70.0}])
    assert set(SUMMARY_KEYS) <= set(s)
    assert s['n'] == 3 and s['n_failed'] == 1
    assert s['arm_accuracy'] == pytest.approx(1 / 3) and s['topology_accuracy'] == pytest.approx(1 / 3)
    assert s['topology_ms_median'] == pytest.approx(20.0) and s['lanes_ms_p95'] == pytest.approx(39.0)
    traffic = good['lanes_true_traffic']
    want = (traffic + miss['lanes_matched_traffic']) / (3 * traffic)
    assert s['lane_recall'] == pytest.approx(want)
    assert s['lane_precision'] == 1.0
    empty = aggregate([])
    assert empty['n'] == 0 and empty['arm_accuracy'] is None


def test_estimate_io_is_deterministic_and_round_trips(tmp_path, scenario):
    stats = {'topology_samples': 5000, 'lane_samples': 0, 'elapsed_s': 0.123456789}
    a = write_estimate(tmp_path / 'a.json', scenario.gt, scenario.gt_lanelets, stats)
    b = write_estimate(tmp_path / 'b.json', scenario.gt, list(reversed(scenario.gt_lanelets)), stats)
    assert a.read_bytes() == b.read_bytes()
    inter, lanes, st = read_estimate(a)
    assert len(inter.arms) == len(scenario.gt.arms) and st['elapsed_s'] == 0.1235
    assert np.allclose(inter.center, scenario.gt.center, atol=1e-4)
    by_id = {ll.id: ll for ll in scenario.gt_lanelets}
    for ll in lanes:
        assert np.allclose(ll.center, by_id[ll.id].center, atol=1e-4)
        assert ll.successors == by_id[ll.id].successors
    doc = json.loads(a.read_text())
    assert {'center', 'arms', 'lanes', 'stats'} <= set(doc)
    assert {'id', 'kind', 'arm', 'center_line', 'left', 'right', 'successors'} <= set(doc['lanes'][0])


def test_gt_json(tmp_path, scenario):
    p = write_gt(tmp_path / 'gt.json', scenario)
    g = read_gt(p)
    assert g.seed == 3 and g.traffic == scenario.traffic
    assert g.sim_config['traffic_side'] == 1 and g.raw['traffic_side'] == 1
    assert len(g.lanelets) == len(scenario.gt_lanelets)
    write_gt(tmp_path / 'gt2.json', simulate_scenario(3))
    assert p.read_bytes() == (tmp_path / 'gt2.json').read_bytes()


def _cli(argv):
    ap = argparse.ArgumentParser()
    register(ap.add_subparsers())
    args = ap.parse_args(argv)
    return args.func(args)


def test_evaluate_cli_single_and_cases(tmp_path, scenario, capsys):
    case = tmp_path / 'cases' / 'c0'
    case.mkdir(parents=True)
    write_gt(case / 'gt.json', scenario)
    write_estimate(case / 'estimate.json', scenario.gt, scenario.gt_lanelets, {})
    broken = tmp_path / 'cases' / 'c1'
    broken.mkdir()
    write_gt(broken / 'gt.json', scenario)
    (broken / 'estimate.json').write_text('{"center": [0, ')
    assert _cli(['evaluate', str(case / 'estimate.json'), str(case / 'gt.json'),
                 '--json', str(tmp_path / 'one.json')]) == 0
    one = json.loads((tmp_path / 'one.json').read_text())
    assert one['topology_correct'] is True and one['lane_recall'] == 1.0
    assert _cli(['evaluate', '--cases', str(tmp_path / 'cases'),
                 '--json', str(tmp_path / 'all.json')]) == 0
    out = json.loads((tmp_path / 'all.json').read_text())
    assert out['summary']['n'] == 2 and out['summary']['topology_accuracy'] == 0.5
    assert out['cases']['c1']['ok'] is False and 'cannot read' in out['cases']['c1']['reason']
    assert 'topology_accuracy' in capsys.readouterr().out
    assert _cli(['evaluate']) == 2


def test_per_kind_breakdown(gt):
    est = copy.deepcopy(gt)
    for x in est['lanes']:
        if x['kind'] == 'connector':
            x['center_line'] = _shift(x['center_line'], 0.5)
    est['lanes'] = [x for x in est['lanes'] if not (x['kind'] == 'leaving' and x['arm'] == 0)]
    m = evaluate(est, gt)
    bk = m['by_kind']
    assert bk['entering']['error_cm_sum'] < 0.1
    assert bk['connector']['error_cm_sum'] / bk['connector']['matched'] == pytest.approx(50, abs=1)
    assert bk['leaving']['matched_traffic'] < bk['leaving']['true_traffic']
    s = aggregate([m])
    assert s['lane_recall_entering'] == 1.0 and s['lane_recall_leaving'] < 1.0
    assert s['lane_error_cm_mean_connector'] == pytest.approx(50, abs=1)
