"""Score an estimate against ground truth (DESIGN.md §5, paper §IV).

Per case (:func:`evaluate`):

* ``arm_correct`` -- same number of arms; ``arms_observed_correct`` -- the arm half of
  ``topology_observed_correct`` below: no estimated arm beyond the true arms and every true
  arm that traffic used matched (an arm no vehicle drove may be missing);
* ``topology_correct`` -- arm count right AND, after matching arms one-to-one by angular
  distance (Hungarian, ``linear_sum_assignment``), every matched arm's
  ``(lanes_in, lanes_out)`` right;
* ``center_error_m``; ``angle_error_deg`` -- mean |angle difference| of matched arms;
* lane course: estimated lanes are matched to true lanes of the same kind and matched
  arm (connectors: same (from, to) arm pair through the arm matching) by Hungarian
  assignment on the mean orthogonal distance of the estimated center line (resampled
  every :data:`RESAMPLE_M`) to the true center line; pairs above :data:`GATE_M` stay
  unmatched. Points beyond the ends of the true center line are left out (no
  orthogonal foot point). ``lane_error_cm`` = mean over matched lanes; recall over true
  lanes carrying traffic, precision over estimated lanes;
* what the data show (issue 15): a true lane is *used* when its ``traffic`` (vehicles
  that drove it, from the ground truth) is > 0, an arm when any of its lanes is.
  ``topology_observed_correct`` asks only for what traffic used and never excuses
  anything beyond the truth: no estimated arm beyond the true arms, every used true arm
  matched, and per matched arm ``used <= estimated <= true`` lanes in and out (a curb
  lane no vehicle drove may be missing, an extra lane may not). The strict
  ``topology_correct`` stays beside it;
* observability: ``road_case`` -- lane users were on at most two arms of the truth (the
  data show a road, not an intersection; vehicles that stood on a lane through the
  recording count: the ``present`` of a gt lane, default its ``traffic``);
  ``intersection_reported`` -- the estimate has three or more arms. Over road cases,
  :func:`aggregate` gives ``road_no_intersection_rate``;
* traffic-following floor: where the ground truth carries a ``traffic_line`` per lane
  (the line that follows the traffic on that lane, see
  :mod:`intersection_estimator.scenarios.floor`), ``floor_cm`` is its mean orthogonal
  distance to the true center line over the lanes that have one (``floor_cm_matched``:
  over the true lanes our estimate matched, the like-for-like figure beside
  ``lane_error_cm``);
* ``connectivity_recall`` -- share of matched true connectors whose estimated
  counterpart follows the estimate matched to the true entering lane and is followed by
  the estimate matched to the true leaving lane.

A malformed estimate (missing keys, NaN, wrong types, dangling arm indices) gives a
failed case (``ok`` False, ``reason``), never an exception. :func:`aggregate` pools the
cases into the summary of issue 4 (accuracies as fractions in [0, 1]).
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
import sys

import numpy as np
from scipy.optimize import linear_sum_assignment

__all__ = ['evaluate', 'evaluate_files', 'aggregate', 'failed_case', 'SUMMARY_KEYS', 'GATE_M', 'RESAMPLE_M', 'register',
           'format_metrics']

GATE_M = 1.5
RESAMPLE_M = 0.5
KINDS = ('entering', 'leaving', 'connector')
SUMMARY_KEYS = ('n', 'arm_accuracy', 'topology_accuracy', 'topology_observed_accuracy',
                'center_error_m_mean', 'floor_cm_mean', 'floor_cm_matched_mean',
                'center_error_m_median', 'angle_error_deg_mean', 'lane_error_cm_mean',
                'lane_recall', 'lane_precision', 'connectivity_recall', 'topology_ms_median',
                'topology_ms_p95', 'lanes_ms_median', 'lanes_ms_p95')


class Malformed(ValueError):
    """The document does not follow the estimate.json schema."""


# ---------------------------------------------------------------- parsing / validation
def _num(x, what) -> float:
    if isinstance(x, bool) or not isinstance(x, (int, float, np.integer, np.floating)):
        raise Malformed(f'{what}: expected a number, got {type(x).__name__}')
    if not math.isfinite(float(x)):
        raise Malformed(f'{what}: not finite')
    return float(x)


def _int(x, what) -> int:
    v = _num(x, what)
    if v != int(v):
        raise Malformed(f'{what}: expected an integer, got {v}')
    return int(v)


def _points(x, what, min_len=1) -> np.ndarray:
    try:
        a = np.asarray(x, dtype=float)
    except (TypeError, ValueError) as e:
        raise Malformed(f'{what}: not a list of [x, y] ({e})') from None
    if a.ndim != 2 or a.shape[1] != 2 or len(a) < min_len:
        raise Malformed(f'{what}: expected >= {min_len} points [x, y], got shape {a.shape}')
    if not np.isfinite(a).all():
        raise Malformed(f'{what}: not finite')
    return a


def _get(d, key, what):
    if not isinstance(d, dict):
        raise Malformed(f'{what}: expected an object, got {type(d).__name__}')
    if key not in d:
        raise Malformed(f'{what}: missing key {key!r}')
    return d[key]


def _as_dict(x) -> dict:
    """Accept an estimate.json dict, an ``(Intersection, lanelets[, stats])`` tuple or a
    simulator ``Scenario`` (its gt.json)."""
    if isinstance(x, dict):
        return x
    if hasattr(x, 'gt_lanelets'):
        from .estimate_io import gt_to_dict
        return gt_to_dict(x, arrays=True)
    if isinstance(x, (tuple, list)) and len(x) in (2, 3):
        from .estimate_io import estimate_to_dict
        return estimate_to_dict(*x, arrays=True)
    raise Malformed(f'expected an estimate.json object, got {type(x).__name__}')


def _arm(a, what) -> list:
    return [math.radians(_num(_get(a, 'angle_deg', what), f'{what}.angle_deg')),
            _int(_get(a, 'lanes_in', what), f'{what}.lanes_in'),
            _int(_get(a, 'lanes_out', what), f'{what}.lanes_out')]


def _parse(d, name):
    """-> center (2,), arms (n, 3) [angle rad, lanes_in, lanes_out], lanes list of dicts."""
    d = _as_dict(d)
    center = _points([_get(d, 'center', name)], f'{name}.center')[0]
    arms_in = _get(d, 'arms', name)
    if not isinstance(arms_in, list):
        raise Malformed(f'{name}.arms: expected a list')
    arms = np.array([_arm(a, f'{name}.arms[{i}]') for i, a in enumerate(arms_in)],
                    dtype=float).reshape(-1, 3)
    lanes_in = _get(d, 'lanes', name)
    if not isinstance(lanes_in, list):
        raise Malformed(f'{name}.lanes: expected a list')
    lanes, ids = [], set()
    for i, x in enumerate(lanes_in):
        what = f'{name}.lanes[{i}]'
        lid, kind = str(_get(x, 'id', what)), _get(x, 'kind', what)
        if kind not in KINDS:
            raise Malformed(f'{what}.kind: {kind!r} not in {KINDS}')
        if lid in ids:
            raise Malformed(f'{what}.id: duplicate {lid!r}')
        ids.add(lid)
        arm = _int(_get(x, 'arm', what), f'{what}.arm')
        arm_to = _int(x.get('arm_to', -1), f'{what}.arm_to')
        for a, key in ((arm, 'arm'), (arm_to, 'arm_to')):
            if not (-1 <= a < len(arms)):
                raise Malformed(f'{what}.{key}: {a} does not index the {len(arms)} arms')
        succ = x.get('successors', [])
        if not isinstance(succ, list):
            raise Malformed(f'{what}.successors: expected a list')
        line = _points(_get(x, 'center_line', what), f'{what}.center_line', 2)
        tl = x.get('traffic_line')
        tl = None if tl is None or len(tl) < 2 else _points(tl, f'{what}.traffic_line', 2)
        traffic = int(_num(x.get('traffic', 1), f'{what}.traffic'))
        lanes.append({'id': lid, 'kind': kind, 'arm': arm, 'arm_to': arm_to,
                      'center': line, 'pts': resample(line),
                      'successors': [str(s) for s in succ],
                      'traffic': traffic,
                      'present': max(int(_num(x.get('present', traffic), f'{what}.present')), traffic),
                      'traffic_line': tl})
    return center, arms, lanes


# ---------------------------------------------------------------- geometry
def resample(polyline: np.ndarray, step: float = RESAMPLE_M) -> np.ndarray:
    """Points every ``step`` metres along a polyline (ends included)."""
    seg = np.linalg.norm(np.diff(polyline, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    if s[-1] <= 0:
        return polyline[:1]
    q = np.linspace(0.0, s[-1], max(2, int(math.ceil(s[-1] / step)) + 1))
    return np.stack([np.interp(q, s, polyline[:, 0]), np.interp(q, s, polyline[:, 1])], axis=1)


def simplify(polyline: np.ndarray, tol: float = 1e-4) -> np.ndarray:
    """A polyline whose vertices all lie within ``tol`` of its chord -> its two ends
    (straight lanes become one segment; keeps the distance computation cheap)."""
    if len(polyline) <= 2:
        return polyline
    a, b = polyline[0], polyline[-1]
    ab = b - a
    n = np.linalg.norm(ab)
    if n < 1e-9:
        return polyline
    off = np.abs((polyline[:, 0] - a[0]) * ab[1] - (polyline[:, 1] - a[1]) * ab[0]) / n
    along = (polyline - a) @ ab / n
    straight = off.max() <= tol and np.all(np.diff(along) > 0)
    return np.stack([a, b]) if straight else polyline


def orthogonal_distances(points: np.ndarray, polyline: np.ndarray, eps: float = 1e-6):
    """Distance of each point to the polyline; NaN where the nearest foot point lies
    beyond the first or last vertex (no orthogonal projection)."""
    ax, ay = polyline[:-1, 0], polyline[:-1, 1]
    bx, by = np.diff(polyline[:, 0]), np.diff(polyline[:, 1])
    ll = np.maximum(bx * bx + by * by, 1e-12)
    px = points[:, :1] - ax[None]
    py = points[:, 1:] - ay[None]
    t_raw = (px * bx + py * by) / ll
    t = np.clip(t_raw, 0.0, 1.0)
    d2 = (px - t * bx) ** 2 + (py - t * by) ** 2
    j = d2.argmin(axis=1)
    rows = np.arange(len(points))
    out = np.sqrt(d2[rows, j])
    tr = t_raw[rows, j]
    beyond = ((j == 0) & (tr < -eps)) | ((j == len(ax) - 1) & (tr > 1 + eps))
    out[beyond] = np.nan
    return out


def lane_distance(est_center: np.ndarray, gt_center: np.ndarray) -> float:
    """Mean orthogonal distance of the resampled estimated center line to the true one
    (inf with fewer than two points that have an orthogonal foot point)."""
    return float(_cost_matrix([resample(est_center)], [gt_center])[0, 0])


def _cost_matrix(est_pts: list, gt_centers: list) -> np.ndarray:
    """``lane_distance`` for all pairs: (len(gt_centers), len(est_pts)), one pass per true lane."""
    pts = np.concatenate(est_pts)
    starts = np.cumsum([0] + [len(p) for p in est_pts[:-1]])
    cost = np.empty((len(gt_centers), len(est_pts)))
    for i, g in enumerate(gt_centers):
        d = orthogonal_distances(pts, g)
        ok = np.isfinite(d)
        cnt = np.add.reduceat(ok.astype(float), starts)
        tot = np.add.reduceat(np.where(ok, d, 0.0), starts)
        cost[i] = np.where(cnt >= 2, tot / np.maximum(cnt, 1), np.inf)
    return cost


# ---------------------------------------------------------------- matching
def _match_arms(est_arms, gt_arms):
    if len(est_arms) == 0 or len(gt_arms) == 0:
        return np.zeros(0, int), np.zeros(0, int), np.zeros(0)
    diff = np.abs((est_arms[:, None, 0] - gt_arms[None, :, 0] + math.pi) % (2 * math.pi) - math.pi)
    r, c = linear_sum_assignment(diff)
    return r, c, diff[r, c]


def _lane_key(lane, arm_map):
    if lane['kind'] == 'connector':
        if lane['arm'] not in arm_map or lane['arm_to'] not in arm_map:
            return None
        return ('connector', arm_map[lane['arm']], arm_map[lane['arm_to']])
    return (lane['kind'], arm_map[lane['arm']]) if lane['arm'] in arm_map else None


def _match_lanes(est_lanes, gt_lanes, arm_map, gate):
    """-> {gt index: (est index, distance)} for matches within ``gate``."""
    groups: dict = {}
    for i, g in enumerate(gt_lanes):
        key = (('connector', g['arm'], g['arm_to']) if g['kind'] == 'connector'
               else (g['kind'], g['arm']))
        groups.setdefault(key, ([], []))[0].append(i)
    for i, e in enumerate(est_lanes):
        key = _lane_key(e, arm_map)
        if key in groups:
            groups[key][1].append(i)
    out = {}
    for gi, ei in groups.values():
        if not gi or not ei:
            continue
        cost = _cost_matrix([est_lanes[e]['pts'] for e in ei],
                            [simplify(gt_lanes[g]['center']) for g in gi])
        r, c = linear_sum_assignment(np.where(np.isfinite(cost), cost, 1e9))
        for a, b in zip(r, c):
            if cost[a, b] <= gate:
                out[gi[a]] = (ei[b], float(cost[a, b]))
    return out


def _connectivity(est_lanes, gt_lanes, match):
    """(matched true connectors, of which correctly attached) -- see module docstring."""
    gt_idx = {g['id']: i for i, g in enumerate(gt_lanes)}
    pred = {s: i for i, g in enumerate(gt_lanes) for s in g['successors']}
    n = ok = 0
    for gi, (ei, _) in match.items():
        g = gt_lanes[gi]
        if g['kind'] != 'connector':
            continue
        n += 1
        e = est_lanes[ei]
        p, s = pred.get(g['id']), gt_idx.get(g['successors'][0]) if g['successors'] else None
        if p in match and s in match:
            ep, es = est_lanes[match[p][0]], est_lanes[match[s][0]]
            ok += int(e['id'] in ep['successors'] and es['id'] in e['successors'])
    return n, ok


# ---------------------------------------------------------------- per case
def _failed(reason, n_arms_true=None, gt_lanes=None) -> dict:
    traffic = sum(g['traffic'] > 0 for g in gt_lanes) if gt_lanes is not None else None
    return {'ok': False, 'reason': reason, 'n_arms_true': n_arms_true, 'n_arms_est': None,
            'arm_correct': False, 'topology_correct': False, 'topology_observed_correct': False,
            'arms_observed_correct': False,
            'arms_true_used': None, 'road_case': None, 'intersection_reported': False,
            'floor_cm': None, 'floor_cm_sum': 0.0, 'floor_lanes': 0,
            'floor_cm_matched': None, 'floor_cm_matched_sum': 0.0, 'floor_lanes_matched': 0,
            'used_lanes_per_arm': None, 'center_error_m': None,
            'angle_error_deg': None, 'arms_matched': 0, 'angle_error_deg_sum': 0.0,
            'lanes_true': len(gt_lanes) if gt_lanes is not None else None,
            'lanes_true_traffic': traffic, 'lanes_est': 0, 'lanes_matched': 0,
            'lanes_matched_traffic': 0, 'lane_error_cm': None, 'lane_error_cm_sum': 0.0,
            'lane_recall': 0.0 if traffic else None, 'lane_precision': None,
            'connectors_matched': 0, 'connectors_connected': 0, 'connectivity_recall': None,
            'by_kind': None}


def failed_case(reason: str) -> dict:
    """Metrics of a case that could not be scored (all counts zero, ``ok`` False)."""
    return _failed(reason)


def evaluate(estimate, gt, *, gate: float = GATE_M, score_lanes: bool = True) -> dict:
    """Metrics of one case; ``estimate``/``gt`` as estimate.json / gt.json dicts (or
    ``(Intersection, lanelets)`` tuples, or a ``Scenario`` for ``gt``).

    ``score_lanes=False`` (a run without the lane course step): the lane-course metrics
    are left out, but the truth's lanes still say which lanes and arms traffic used, so
    ``topology_observed_correct`` asks for the same lanes as in a full run."""
    try:
        gc, ga, gl = _parse(gt, 'gt')
    except Malformed as e:
        return _failed(f'malformed ground truth: {e}')
    try:
        ec, ea, el = _parse(estimate, 'estimate')
    except Malformed as e:
        return _failed(f'malformed estimate: {e}', len(ga), gl)
    r, c, dang = _match_arms(ea, ga)
    arm_correct = len(ea) == len(ga)
    topo = arm_correct and bool(np.all(ea[r, 1:] == ga[c, 1:]))
    arm_map = {int(a): int(b) for a, b in zip(r, c)}
    match = _match_lanes(el, gl, arm_map, gate)
    dists = np.array([d for _, d in match.values()])
    n_traffic = sum(g['traffic'] > 0 for g in gl)
    m_traffic = sum(gl[g]['traffic'] > 0 for g in match)
    n_con, ok_con = _connectivity(el, gl, match)
    floor = _floor(gl, match)
    by_kind = _by_kind(el, gl, match, floor)
    used_in, used_out = _used_lanes(gl, len(ga))
    if not score_lanes:
        return {**_without_lanes(ea, ga, r, c, used_in, used_out, ec, gc, dang, arm_correct, topo,
                                 _road_case(gl, len(ga)))}
    return {'ok': True, 'reason': None, 'n_arms_true': len(ga), 'n_arms_est': len(ea),
            'arm_correct': arm_correct, 'topology_correct': topo,
            'topology_observed_correct': _topology_observed(ea, ga, r, c, used_in, used_out),
            'arms_observed_correct': _arms_observed(ea, ga, c, used_in, used_out),
            'arms_true_used': int(np.count_nonzero(used_in + used_out)),
            'road_case': _road_case(gl, len(ga)),
            'intersection_reported': len(ea) >= 3,
            'used_lanes_per_arm': [[int(a), int(b)] for a, b in zip(used_in, used_out)],
            **_floor_summary(floor, match),
            'center_error_m': float(np.linalg.norm(ec - gc)),
            'angle_error_deg': float(np.degrees(dang).mean()) if len(dang) else None,
            'arms_matched': len(dang), 'angle_error_deg_sum': float(np.degrees(dang).sum()),
            'lanes_true': len(gl), 'lanes_true_traffic': n_traffic, 'lanes_est': len(el),
            'lanes_matched': len(match), 'lanes_matched_traffic': m_traffic,
            'lane_error_cm': float(100 * dists.mean()) if len(dists) else None,
            'lane_error_cm_sum': float(100 * dists.sum()),
            'lane_recall': m_traffic / n_traffic if n_traffic else None,
            'lane_precision': len(match) / len(el) if el else None,
            'connectors_matched': n_con, 'connectors_connected': ok_con,
            'connectivity_recall': ok_con / n_con if n_con else None, 'by_kind': by_kind}


def _without_lanes(ea, ga, r, c, used_in, used_out, ec, gc, dang, arm_correct, topo, road) -> dict:
    """The topology-level metrics of :func:`evaluate` with every lane-course field empty."""
    m = _failed(None)
    m.update({'ok': True, 'n_arms_true': len(ga), 'n_arms_est': len(ea),
              'arm_correct': arm_correct, 'topology_correct': topo,
              'topology_observed_correct': _topology_observed(ea, ga, r, c, used_in, used_out),
              'arms_observed_correct': _arms_observed(ea, ga, c, used_in, used_out),
              'arms_true_used': int(np.count_nonzero(used_in + used_out)),
              'road_case': road,
              'intersection_reported': len(ea) >= 3,
              'used_lanes_per_arm': [[int(a), int(b)] for a, b in zip(used_in, used_out)],
              'center_error_m': float(np.linalg.norm(ec - gc)),
              'angle_error_deg': float(np.degrees(dang).mean()) if len(dang) else None,
              'arms_matched': len(dang), 'angle_error_deg_sum': float(np.degrees(dang).sum()),
              'lanes_true': None, 'lane_recall': None})
    return m


def _by_kind(est_lanes, gt_lanes, match, floor) -> dict:
    """Lane counts, error and floor sums per kind (where does the lane step lose accuracy?)."""
    out = {}
    for kind in KINDS:
        m = {g: d for g, (_, d) in match.items() if gt_lanes[g]['kind'] == kind}
        f = [d for g, d in floor.items() if gt_lanes[g]['kind'] == kind]
        out[kind] = {'est': sum(e['kind'] == kind for e in est_lanes),
                     'true_traffic': sum(g['kind'] == kind and g['traffic'] > 0 for g in gt_lanes),
                     'matched': len(m),
                     'matched_traffic': sum(gt_lanes[g]['traffic'] > 0 for g in m),
                     'error_cm_sum': float(100 * sum(m.values())),
                     'floor_lanes': len(f), 'floor_cm_sum': float(100 * sum(f))}
    return out


def _used_lanes(gt_lanes, n_arms, count: str = 'traffic'):
    """Per true arm: how many entering / leaving lanes carried traffic (issue 15; ``count``
    'present': had a lane user on them, standing ones included)."""
    used_in, used_out = np.zeros(n_arms, int), np.zeros(n_arms, int)
    for g in gt_lanes:
        if g[count] > 0 and g['kind'] != 'connector' and 0 <= g['arm'] < n_arms:
            (used_in if g['kind'] == 'entering' else used_out)[g['arm']] += 1
    return used_in, used_out


def _road_case(gt_lanes, n_arms) -> bool:
    """The data show a road, not an intersection: lane users were on at most two true arms,
    counting every vehicle seen on a lane, those that stood through the recording too
    (``present``; a queue at a red light shows its approach -- the estimator reads such
    queues, ``topology/standing.py`` -- while ``traffic`` counts only vehicles that drove)."""
    seen_in, seen_out = _used_lanes(gt_lanes, n_arms, 'present')
    return bool(np.count_nonzero(seen_in + seen_out) <= 2)


def _arms_observed(est_arms, gt_arms, c, used_in, used_out) -> bool:
    """Arm count on what the traffic shows: no estimated arm beyond the true arms, every
    true arm that traffic used matched (``c``: the matched true arms)."""
    matched = set(int(j) for j in c)
    return len(est_arms) <= len(gt_arms) and all(
        j in matched for j in range(len(gt_arms)) if used_in[j] + used_out[j] > 0)


def _topology_observed(est_arms, gt_arms, r, c, used_in, used_out) -> bool:
    """Lane-level topology on what the traffic shows (module docstring): lanes and arms
    no vehicle used are not asked for; nothing beyond the truth is excused."""
    if not _arms_observed(est_arms, gt_arms, c, used_in, used_out):
        return False
    to_est = {int(j): int(i) for i, j in zip(r, c)}
    for j in range(len(gt_arms)):
        if j not in to_est:
            continue
        e = est_arms[to_est[j]]
        if not (used_in[j] <= e[1] <= gt_arms[j, 1] and used_out[j] <= e[2] <= gt_arms[j, 2]):
            return False
    return True


def _floor(gt_lanes, match) -> dict:
    """{true lane index: distance [m] of its traffic-following line to its center line}."""
    out = {}
    for i, g in enumerate(gt_lanes):
        if g['traffic_line'] is not None and g['traffic'] > 0:
            d = lane_distance(g['traffic_line'], g['center'])
            if math.isfinite(d):
                out[i] = d
    return out


def _floor_summary(floor, match) -> dict:
    fm = [d for g, d in floor.items() if g in match]
    return {'floor_cm': float(100 * np.mean(list(floor.values()))) if floor else None,
            'floor_cm_sum': float(100 * sum(floor.values())), 'floor_lanes': len(floor),
            'floor_cm_matched': float(100 * np.mean(fm)) if fm else None,
            'floor_cm_matched_sum': float(100 * sum(fm)), 'floor_lanes_matched': len(fm)}


# ---------------------------------------------------------------- summary
def _ratio(num, den):
    return num / den if den else None


def _pct(values, q):
    v = [x for x in values if x is not None]
    return float(np.percentile(v, q)) if v else None


def aggregate(metrics: list[dict], timings: list[dict] | None = None) -> dict:
    """Pool per-case metrics (and optional per-case ``timing_ms``) into the summary.

    Accuracies are shares of all cases (failed cases count as wrong); errors are
    averaged over successful cases, lane error and angle error over matched lanes /
    arms; recall and precision are pooled over lanes of all cases.
    """
    n = len(metrics)
    ok = [m for m in metrics if m['ok']]

    def total(key):
        return sum(m.get(key) or 0 for m in metrics)

    center = [m['center_error_m'] for m in ok]
    roads = [m for m in metrics if m.get('road_case')]
    timings = timings or []
    summary = {
        'n': n, 'n_failed': n - len(ok),
        'arm_accuracy': _ratio(sum(m['arm_correct'] for m in metrics), n),
        'arm_observed_accuracy': _ratio(
            sum(m.get('arms_observed_correct', False) for m in metrics), n),
        'topology_accuracy': _ratio(sum(m['topology_correct'] for m in metrics), n),
        'topology_observed_accuracy': _ratio(
            sum(m.get('topology_observed_correct', False) for m in metrics), n),
        'road_cases': len(roads),
        'road_no_intersection_rate': _ratio(sum(not m['intersection_reported'] for m in roads),
                                            len(roads)),
        'center_error_m_mean': float(np.mean(center)) if center else None,
        'center_error_m_median': float(np.median(center)) if center else None,
        'angle_error_deg_mean': _ratio(total('angle_error_deg_sum'), total('arms_matched')),
        'lane_error_cm_mean': _ratio(total('lane_error_cm_sum'), total('lanes_matched')),
        'floor_cm_mean': _ratio(total('floor_cm_sum'), total('floor_lanes')),
        'floor_cm_matched_mean': _ratio(total('floor_cm_matched_sum'), total('floor_lanes_matched')),
        'lane_recall': _ratio(total('lanes_matched_traffic'), total('lanes_true_traffic')),
        'lane_precision': _ratio(total('lanes_matched'), total('lanes_est')),
        'connectivity_recall': _ratio(total('connectors_connected'), total('connectors_matched')),
    }
    for kind in KINDS:
        k = [m['by_kind'][kind] for m in metrics if m.get('by_kind')]
        summary[f'lane_error_cm_mean_{kind}'] = _ratio(sum(x['error_cm_sum'] for x in k),
                                                       sum(x['matched'] for x in k))
        summary[f'lane_recall_{kind}'] = _ratio(sum(x['matched_traffic'] for x in k),
                                                sum(x['true_traffic'] for x in k))
        summary[f'floor_cm_mean_{kind}'] = _ratio(sum(x.get('floor_cm_sum', 0.0) for x in k),
                                                  sum(x.get('floor_lanes', 0) for x in k))
    for step in ('topology', 'lanes', 'total'):
        vals = [t.get(step) for t in timings if t]
        summary[f'{step}_ms_median'] = _pct(vals, 50)
        summary[f'{step}_ms_p95'] = _pct(vals, 95)
    return summary


# ---------------------------------------------------------------- CLI
def format_metrics(m: dict) -> str:
    """Plain-text ``key: value`` block."""
    def fmt(v):
        return f'{v:.4g}' if isinstance(v, float) else str(v)
    return '\n'.join(f'{k:24s} {fmt(v)}' for k, v in m.items())


def _load(path):
    try:
        return json.loads(Path(path).read_text())
    except (OSError, ValueError) as e:
        return {'__error__': f'cannot read {path}: {e}'}


def evaluate_files(est_path, gt_path) -> dict:
    """Metrics of an estimate.json file against a gt.json file (unreadable files: a failed case)."""
    est, gt = _load(est_path), _load(gt_path)
    if '__error__' in gt:
        return _failed(gt['__error__'])
    if '__error__' in est:
        return evaluate({}, gt) | {'reason': est['__error__']}
    return evaluate(est, gt)


def _cmd(args) -> int:
    if args.cases:
        root = Path(args.cases)
        dirs = sorted(p for p in root.iterdir() if (p / 'gt.json').exists())
        if not dirs:
            print(f'no case folders with gt.json under {root}')
            return 2
        per_case = {p.name: evaluate_files(p / 'estimate.json', p / 'gt.json') for p in dirs}
        summary = aggregate(list(per_case.values()))
        out = {'summary': summary, 'cases': per_case}
        print(format_metrics(summary))
    elif args.estimate and args.gt:
        missing = [f for f in (args.estimate, args.gt) if not Path(f).is_file()]
        if missing:
            print(f'evaluate: {missing[0]}: no such file', file=sys.stderr)
            return 1
        out = evaluate_files(args.estimate, args.gt)
        print(format_metrics(out))
    else:
        print('evaluate: give ESTIMATE GT or --cases DIR')
        return 2
    if args.json:
        from .estimate_io import dumps
        Path(args.json).write_text(dumps(out))
    return 0


def register(subparsers) -> argparse.ArgumentParser:
    """Add the ``evaluate`` subcommand (DESIGN.md §5 metrics)."""
    p = subparsers.add_parser('evaluate', help='score estimate.json against gt.json',
                              description=__doc__.split('\n\n')[0])
    p.add_argument('estimate', nargs='?', help='estimate.json')
    p.add_argument('gt', nargs='?', help='gt.json')
    p.add_argument('--cases', metavar='DIR',
                   help='folder of case subfolders, each with estimate.json + gt.json')
    p.add_argument('--json', metavar='OUT', help='also write the metrics as JSON')
    p.set_defaults(func=_cmd)
    return p
