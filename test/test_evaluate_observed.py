"""Evaluation that knows what the data show (issue 15 part 3): used lanes / arms,
``topology_observed`` beside the strict metric, the traffic-following floor."""

import copy
import json

import numpy as np
import pytest

from intersection_estimator.estimate_io import dumps, gt_to_dict
from intersection_estimator.evaluate import aggregate, evaluate
from intersection_estimator.sim import simulate_scenario


@pytest.fixture(scope='module')
def gt():
    for seed in range(50):   # first scene with an arm of >= 2 entering lanes
        d = json.loads(dumps(gt_to_dict(simulate_scenario(seed))))
        if any(a['lanes_in'] >= 2 for a in d['arms']):
            return d
    raise AssertionError('no scene with two entering lanes in seeds 0..49')


def _curb_arm(doc):
    return next(i for i, a in enumerate(doc['arms']) if a['lanes_in'] >= 2)


def _undriven_curb(doc):
    """GT whose curb entering lane (and its connectors) of one arm no vehicle used."""
    d = copy.deepcopy(doc)
    a = _curb_arm(d)
    k = d['arms'][a]['lanes_in'] - 1
    curb = f'a{a}_in{k}'
    for x in d['lanes']:
        if x['id'] == curb or (x['kind'] == 'connector' and x['id'].startswith(f'c_a{a}i{k}_')):
            x['traffic'] = 0
    return d, a, curb


def test_undriven_curb_lane_absent_is_correct_by_topology_observed(gt):
    truth, a, curb = _undriven_curb(gt)
    est = copy.deepcopy(gt)
    est['arms'][a]['lanes_in'] -= 1
    est['lanes'] = [x for x in est['lanes'] if x['id'] != curb]
    m = evaluate(est, truth)
    assert m['ok'] and m['arm_correct']
    assert not m['topology_correct']             # strict: one lane short of the map
    assert m['topology_observed_correct']        # but no vehicle used that lane
    assert m['used_lanes_per_arm'][a][0] == truth['arms'][a]['lanes_in'] - 1
    # the same estimate is wrong when the curb lane did carry traffic
    assert not evaluate(est, gt)['topology_observed_correct']
    # and the full estimate is right by both
    full = evaluate(gt, truth)
    assert full['topology_correct'] and full['topology_observed_correct']


def test_lane_beyond_the_truth_is_never_excused(gt):
    truth, a, _ = _undriven_curb(gt)
    est = copy.deepcopy(gt)
    est['arms'][a]['lanes_in'] += 1
    m = evaluate(est, truth)
    assert not m['topology_correct'] and not m['topology_observed_correct']
    extra_arm = copy.deepcopy(gt)
    extra_arm['arms'].append({**extra_arm['arms'][0],
                              'angle_deg': extra_arm['arms'][0]['angle_deg'] + 20.0})
    assert not evaluate(extra_arm, truth)['topology_observed_correct']
    assert not evaluate(extra_arm, truth)['arms_observed_correct']


def test_unused_arm_may_be_missing_a_used_one_not(gt):
    truth = copy.deepcopy(gt)
    for x in truth['lanes']:
        if 0 in (x['arm'], x['arm_to']):
            x['traffic'] = 0
    est = copy.deepcopy(gt)
    est['arms'].pop(0)
    est['lanes'] = []     # topology only (lane indices would dangle)
    m = evaluate(est, truth)
    assert not m['arm_correct'] and m['topology_observed_correct']
    assert m['arms_observed_correct']              # the arm half of topology_observed
    assert m['arms_true_used'] == len(gt['arms']) - 1
    strict = evaluate(est, gt)
    assert not strict['topology_observed_correct'] and not strict['arms_observed_correct']
    pooled = aggregate([m, strict])
    assert pooled['arm_accuracy'] == 0.0 and pooled['arm_observed_accuracy'] == 0.5


def test_floor_is_the_distance_of_the_traffic_line(gt):
    truth = copy.deepcopy(gt)
    for x in truth['lanes']:
        if x['kind'] == 'entering':
            c = np.asarray(x['center_line'], float)
            t = np.gradient(c, axis=0)
            t /= np.linalg.norm(t, axis=1, keepdims=True)
            x['traffic_line'] = (c + 0.3 * np.stack([-t[:, 1], t[:, 0]], axis=1)).tolist()
    m = evaluate(gt, truth)
    n_in = sum(x['kind'] == 'entering' and x['traffic'] > 0 for x in truth['lanes'])
    assert m['floor_lanes'] == n_in and m['floor_cm'] == pytest.approx(30.0, abs=0.5)
    assert m['floor_cm_matched'] == pytest.approx(30.0, abs=0.5)
    s = aggregate([m, m])
    assert s['floor_cm_mean'] == pytest.approx(30.0, abs=0.5)
    assert s['floor_cm_mean_entering'] == pytest.approx(30.0, abs=0.5)
    assert s['floor_cm_mean_leaving'] is None
    assert s['topology_observed_accuracy'] == 1.0
    assert evaluate(gt, gt)['floor_cm'] is None   # no traffic lines: no floor


def test_road_case_and_intersection_reported(gt):
    truth = copy.deepcopy(gt)
    keep = {0, 1}
    for x in truth['lanes']:
        if x['arm'] not in keep or (x['kind'] == 'connector' and x['arm_to'] not in keep):
            x['traffic'] = 0
    full = evaluate(gt, truth)
    assert full['road_case'] and full['intersection_reported']
    road = copy.deepcopy(gt)
    road['arms'] = road['arms'][:2]
    road['lanes'] = []
    m = evaluate(road, truth)
    assert m['road_case'] and not m['intersection_reported']
    s = aggregate([full, m, evaluate(gt, gt)])
    assert s['road_cases'] == 2 and s['road_no_intersection_rate'] == 0.5
    assert not evaluate(gt, gt)['road_case']
    # a queue that stood on a third arm's lane through the recording (``present``, not
    # ``traffic``): the data show that arm, no road; topology_observed still does not ask
    # for the lane (no vehicle drove it)
    queued = copy.deepcopy(truth)
    lane = next(x for x in queued['lanes'] if x['kind'] == 'entering' and x['arm'] not in keep)
    lane['present'] = 3
    q = evaluate(gt, queued)
    assert not q['road_case'] and q['arms_true_used'] == full['arms_true_used']


def test_topology_only_scoring_still_asks_for_the_used_lanes(gt):
    """``score_lanes=False`` (a bench run with ``--lane-samples 0``) leaves the lane-course
    metrics out but keeps the truth's traffic: a used curb lane that the estimate lacks is
    still wrong, as in a full run (the earlier bench emptied the truth's lanes, so every
    lane looked unused and ``topology_observed`` excused any missing lane)."""
    truth, a, _ = _undriven_curb(gt)
    short = copy.deepcopy(gt)
    short['arms'][a]['lanes_in'] -= 1
    short['lanes'] = []
    assert not evaluate(short, gt, score_lanes=False)['topology_observed_correct']
    m = evaluate(short, truth, score_lanes=False)
    assert m['topology_observed_correct'] and not m['topology_correct']
    assert m['lane_recall'] is None and m['lane_error_cm'] is None
    assert m['used_lanes_per_arm'] == evaluate(gt, truth)['used_lanes_per_arm']
