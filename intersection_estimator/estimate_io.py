"""``estimate.json`` / ``gt.json`` read and write (DESIGN.md §4).

``estimate.json``: ``{"center", "arms", "lanes", "stats", "traffic_side"}`` with
``Intersection.to_json`` / ``Lanelet.to_json`` entries (arms and lanes with
``confidence`` and ``support``: the vehicle passages / trajectories behind them); a run that
estimated no intersection writes ``center`` null and no arms, ``stats.state`` NO_DATA;
``stats.observability`` says whether the data show an intersection at all
(:mod:`.observability`: ``state``, ``intersection``, ``intersection_confidence``). ``gt.json`` is the same schema
plus ``traffic`` per lane (trajectories using it), ``seed``, ``sim_config`` and a few
scenario facts (``stop_m`` per arm, ``duration_s``, ``ego``). Output is deterministic:
floats rounded to :data:`DIGITS` decimals, keys sorted, non-finite numbers written as
``null``, so two identical estimates give byte-identical files.
"""

from __future__ import annotations

from dataclasses import dataclass
import json
import math
from pathlib import Path

import numpy as np

from .model import Intersection, Lanelet

__all__ = ['DIGITS', 'estimate_to_dict', 'dumps', 'write_estimate', 'read_estimate',
           'parse_estimate', 'gt_to_dict', 'write_gt', 'read_gt', 'GroundTruth']

DIGITS = 4


def _clean(x):
    """JSON-safe copy: numpy -> python, floats rounded, non-finite -> None."""
    if isinstance(x, dict):
        return {str(k): _clean(v) for k, v in x.items()}
    if isinstance(x, (list, tuple, np.ndarray)):
        return [_clean(v) for v in x]
    if isinstance(x, (bool, np.bool_)):
        return bool(x)
    if isinstance(x, (int, np.integer)):
        return int(x)
    if isinstance(x, (float, np.floating)):
        x = float(x)
        return round(x, DIGITS) + 0.0 if math.isfinite(x) else None
    return x


def dumps(obj) -> str:
    """Deterministic JSON text (sorted keys, rounded floats, trailing newline)."""
    return json.dumps(_clean(obj), sort_keys=True, indent=1, allow_nan=False) + '\n'


def _lane_arrays(ll: Lanelet) -> dict:
    """``Lanelet.to_json`` keys with the polylines left as float arrays (fast, in-memory)."""
    return {'id': ll.id, 'kind': ll.kind, 'arm': int(ll.arm), 'arm_to': int(ll.arm_to),
            'lane_index': int(ll.lane_index), 'center_line': np.asarray(ll.center, float),
            'left': np.asarray(ll.left, float), 'right': np.asarray(ll.right, float),
            'successors': list(ll.successors), 'confidence': float(ll.confidence),
            'support': int(ll.support)}


def estimate_to_dict(intersection: Intersection | None, lanelets, stats: dict | None = None, *,
                     arrays: bool = False) -> dict:
    """The estimate.json document as a dict (not yet rounded). ``arrays=True`` keeps the
    polylines as numpy arrays (for in-memory evaluation; :func:`dumps` still serialises it).

    Without an intersection (a run that never estimated one) the document is valid and says
    so: ``center`` and ``traffic_side`` null, no arms, no lanes, ``stats.state`` NO_DATA
    (unless the stats say otherwise)."""
    if intersection is None:
        return {'center': None, 'arms': [], 'lanes': [], 'traffic_side': None,
                'stats': {'state': 'NO_DATA', **dict(stats or {})}}
    d = intersection.to_json()
    d['traffic_side'] = int(intersection.traffic_side)
    lane = _lane_arrays if arrays else Lanelet.to_json
    d['lanes'] = [lane(ll) for ll in sorted(lanelets or [], key=lambda ll: ll.id)]
    d['stats'] = dict(stats or {})
    return d


def write_estimate(path, intersection: Intersection | None, lanelets, stats: dict | None = None) -> Path:
    """Write estimate.json (see :func:`estimate_to_dict`; ``intersection`` None: NO_DATA)."""
    path = Path(path)
    path.write_text(dumps(estimate_to_dict(intersection, lanelets, stats)))
    return path


def parse_estimate(d: dict) -> tuple[Intersection, list[Lanelet], dict]:
    """estimate.json dict -> ``(Intersection, lanelets, stats)``; raises on malformed input
    and ``ValueError`` (one line) on a valid estimate without an intersection (NO_DATA)."""
    if isinstance(d, dict) and d.get('center', 0) is None:
        state = (d.get('stats') or {}).get('state', 'NO_DATA')
        raise ValueError(f'the estimate holds no intersection (state {state})')
    inter = Intersection.from_json(d)
    lanes = [Lanelet.from_json(x) for x in d.get('lanes', [])]
    return inter, lanes, dict(d.get('stats', {}))


def read_estimate(path) -> tuple[Intersection, list[Lanelet], dict]:
    return parse_estimate(json.loads(Path(path).read_text()))


@dataclass
class GroundTruth:
    """Contents of a gt.json."""

    intersection: Intersection
    lanelets: list[Lanelet]
    traffic: dict[str, int]
    seed: int | None
    sim_config: dict
    raw: dict


def gt_to_dict(scenario, *, arrays: bool = False) -> dict:
    """gt.json of a :class:`intersection_estimator.sim.Scenario` (``arrays``: see
    :func:`estimate_to_dict`)."""
    d = estimate_to_dict(scenario.gt, scenario.gt_lanelets,
                         {'tracks': len(scenario.tracks), 'duration_s': scenario.duration},
                         arrays=arrays)
    for lane in d['lanes']:
        lane['traffic'] = int(scenario.traffic.get(lane['id'], 0))
    for arm, stop in zip(d['arms'], scenario.stop):
        arm['stop_m'] = float(stop)
    ego = scenario.ego
    d.update(seed=int(scenario.seed), sim_config=scenario.config.to_dict(),
             duration_s=float(scenario.duration),
             ego={'arm': int(ego.arm), 'lane_index': int(ego.lane_index),
                  'start_xy': ego.xy[0].tolist(), 'stop_xy': ego.xy[-1].tolist()})
    return d


def write_gt(path, scenario) -> Path:
    path = Path(path)
    path.write_text(dumps(gt_to_dict(scenario)))
    return path


def read_gt(path) -> GroundTruth:
    d = json.loads(Path(path).read_text())
    inter, lanes, _ = parse_estimate(d)
    traffic = {str(x['id']): int(x.get('traffic', 0)) for x in d.get('lanes', [])}
    return GroundTruth(intersection=inter, lanelets=lanes, traffic=traffic,
                       seed=d.get('seed'), sim_config=d.get('sim_config', {}), raw=d)
