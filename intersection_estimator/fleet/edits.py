"""Prior maps with one change applied to a simulated case's ground truth (tests, benchmark).

Each edit changes the *map*; the world (the simulated traffic) stays the ground truth, so
the change a detector should report is the opposite one (:data:`EXPECTED`): a map that lost
an arm must give ``arm_added``, a map with an extra lane ``lane_removed``, and so on.
Edits pick their target with a seeded ``numpy.random.Generator`` among the elements the
edit applies to; ``None`` when the case has none (e.g. ``lane_added`` needs no extra
condition, ``lane_removed`` an arm direction with >= 2 lanes).
"""

from __future__ import annotations

import copy

import numpy as np

__all__ = ['EDITS', 'EXPECTED', 'apply_edit', 'WORLD_EDITS', 'world_without_arm', 'arm_lane_points']

EDITS = ('arm_removed', 'lane_added', 'lane_removed', 'lane_moved', 'connector_removed')
#: map edit -> change kind the drives should show
EXPECTED = {'arm_removed': 'arm_added', 'lane_added': 'lane_removed', 'lane_removed': 'lane_added',
            'lane_moved': 'lane_moved', 'connector_removed': 'connector_added'}
#: edits of the *world* (the map stays the ground truth) -> the change kind they should show:
#: ``arm_closed`` = the vehicles of one arm gone (a road closed), the map still has it
WORLD_EDITS = {'arm_closed': 'arm_removed'}


def _lanes(lanelets, kind):
    return [l for l in lanelets if l.kind == kind]


def _outermost(lanelets, rng):
    """(arm, kind, outermost lane) of a random arm direction."""
    groups: dict = {}
    for l in lanelets:
        if l.kind != 'connector':
            groups.setdefault((l.arm, l.kind), []).append(l)
    keys = sorted(groups)
    a, kind = keys[int(rng.integers(len(keys)))]
    return a, kind, max(groups[(a, kind)], key=lambda l: l.lane_index), len(groups[(a, kind)])


def _normal(l) -> np.ndarray:
    """Unit normal pointing from the lane's center line to its left border."""
    n = l.left[0] - l.center[0]
    return n / np.hypot(*n)


def _shift(l, vec, weights=None):
    w = np.ones(len(l.center)) if weights is None else weights
    for name in ('left', 'right', 'center'):
        setattr(l, name, getattr(l, name) + w[:, None] * vec)


def _arm_removed(lls, rng, gt, traffic):
    """One arm gone from the map with its lanes and turns -- and the lanes of other arms
    whose every turn led into it or came from it (a turn pocket into a new road is as new
    as the road): a map without the arm has no lane into nowhere. ``what['lanes']`` lists
    their (arm, kind): showing them is part of the change, not another one."""
    a = int(rng.integers(len(gt.arms)))
    con = {l.id: l for l in lls if l.kind == 'connector'}
    fed = {}
    for c in con.values():
        for s in c.successors:
            fed.setdefault(s, []).append(c)
    orphans = [l for l in lls if l.arm != a and (
        (l.kind == 'entering' and l.successors and all(con[s].arm_to == a for s in l.successors if s in con))
        or (l.kind == 'leaving' and fed.get(l.id) and all(c.arm == a for c in fed[l.id])))]
    gone = {l.id for l in orphans}
    kept = [l for l in lls if l.arm != a and l.arm_to != a and l.id not in gone]
    return kept, {'arm': a, 'lanes': sorted({(int(l.arm), l.kind) for l in orphans})}


def _lane_added(lls, rng, gt, traffic):
    a, kind, outer, _ = _outermost(lls, rng)
    new = copy.deepcopy(outer)
    w = float(np.hypot(*(outer.left[0] - outer.right[0])))
    # away from the median = to the right of the driving direction in right-hand traffic
    n = -_normal(outer) * gt.traffic_side
    _shift(new, n * w)
    new.id, new.lane_index, new.successors = f'{outer.id}_extra', outer.lane_index + 1, []
    return lls + [new] + _copied_turns(lls, outer, new, n * w), {'arm': a, 'kind': kind}


def _copied_turns(lls, outer, new, vec) -> list:
    """The turns of ``outer`` copied for the added lane ``new`` (``vec`` beside it): a mapped
    lane leads somewhere, and a lane added next to a kerb lane serves its turns. Each copy is
    the connector shifted by ``vec`` at the new lane's end, fading to 0 at its other end (as
    in :func:`_lane_moved`), so it shares its end points with both lanes."""
    out = []
    for c in _lanes(lls, 'connector'):
        if outer.kind == 'entering' and c.id in outer.successors:
            w, into = np.linspace(1.0, 0.0, len(c.center)), None
        elif outer.kind == 'leaving' and outer.id in c.successors:
            w, into = np.linspace(0.0, 1.0, len(c.center)), next(l for l in lls if c.id in l.successors)
        else:
            continue
        cc = copy.deepcopy(c)
        _shift(cc, vec, w)
        cc.id = f'{c.id}_extra'
        if into is None:
            new.successors.append(cc.id)
        else:
            cc.successors = [new.id]
            into.successors = into.successors + [cc.id]
        out.append(cc)
    return out


def _lane_removed(lls, rng, gt, traffic):
    cands = [(l.arm, l.kind) for l in lls if l.kind != 'connector' and l.lane_index >= 1]
    if not cands:
        return None, None
    a, kind = sorted(set(cands))[int(rng.integers(len(set(cands))))]
    k = max(l.lane_index for l in lls if l.arm == a and l.kind == kind)
    gone = next(l for l in lls if l.arm == a and l.kind == kind and l.lane_index == k)
    out = [l for l in lls if l is not gone and gone.id not in l.successors and l.id not in gone.successors]
    for l in out:
        l.successors = [s for s in l.successors if s != gone.id]
    return out, {'arm': a, 'kind': kind, 'lane': gone.id}


def _lane_moved(lls, rng, gt, traffic):
    lanes = [l for l in lls if l.kind != 'connector']
    l = lanes[int(rng.integers(len(lanes)))]
    vec = _normal(l) * (1.0 if rng.random() < 0.5 else -1.0)
    _shift(l, vec)
    # the connectors it shares end points with follow at that end (weight 1 -> 0 along them)
    for c in _lanes(lls, 'connector'):
        m = len(c.center)
        if l.kind == 'entering' and c.id in l.successors:
            _shift(c, vec, np.linspace(1.0, 0.0, m))
        elif l.kind == 'leaving' and l.id in c.successors:
            _shift(c, vec, np.linspace(0.0, 1.0, m))
    return lls, {'lane': l.id}


def _connector_removed(lls, rng, gt, traffic):
    """A driven connector whose entering and leaving lanes keep another connector."""
    cons = _lanes(lls, 'connector')
    n_from = {}
    n_to = {}
    for c in cons:
        src = next(l.id for l in lls if c.id in l.successors)
        n_from[src] = n_from.get(src, 0) + 1
        n_to[c.successors[0]] = n_to.get(c.successors[0], 0) + 1
    ok = [c for c in cons if traffic.get(c.id, 0) > 0 and n_to[c.successors[0]] > 1
          and n_from[next(l.id for l in lls if c.id in l.successors)] > 1]
    if not ok:
        return None, None
    gone = ok[int(rng.integers(len(ok)))]
    out = [l for l in lls if l is not gone]
    for l in out:
        l.successors = [s for s in l.successors if s != gone.id]
    return out, {'connector': gone.id}


_EDIT = {'arm_removed': _arm_removed, 'lane_added': _lane_added, 'lane_removed': _lane_removed,
         'lane_moved': _lane_moved, 'connector_removed': _connector_removed}


def apply_edit(scenario, edit: str, rng: np.random.Generator):
    """``(lanelets of the edited map, what was edited)`` or ``(None, None)`` if not applicable."""
    if edit not in _EDIT:
        raise ValueError(f"edit: unknown '{edit}' ({' | '.join(EDITS)})")
    lls = copy.deepcopy(scenario.gt_lanelets)
    return _EDIT[edit](lls, rng, scenario.gt, scenario.traffic)


def drive_variant(scenario, drive: int, share: float = 1.0):
    """Another drive through the same intersection: a ``share`` of its vehicles (drawn with
    a generator seeded by ``(scenario seed, drive)``) seen by a sensor with its own noise.

    Geometry, ego and the traffic's routes stay the scenario's (the world); which vehicles
    pass while this drive records, and the noise on them, change. ``share=1`` and
    ``drive=0`` is the scenario itself.
    """
    from dataclasses import replace
    if not 0.0 < share <= 1.0:
        raise ValueError(f'share must be in (0, 1] (got {share})')
    if drive == 0 and share == 1.0:
        return scenario
    rng = np.random.default_rng([int(scenario.seed), int(drive)])
    n = len(scenario.tracks)
    keep = np.sort(rng.choice(n, size=max(1, int(round(share * n))), replace=False))
    return replace(scenario, tracks=[scenario.tracks[i] for i in keep],
                   seed=int(scenario.seed) * 1000 + int(drive), _cache={})


#: a vehicle drove an arm when its true path comes this close to one of the arm's lane center lines [m]
ARM_TOUCH_M = 1.0


def _drove_arm(track, tree) -> bool:
    return bool(len(track.xy)) and bool((tree.query(track.xy)[0] < ARM_TOUCH_M).any())


def arm_lane_points(lanelets, arm: int, step: float = 0.25) -> np.ndarray:
    """Points every ``step`` metres along the center lines of the entering and leaving
    lanelets of ``arm`` (``(0, 2)`` when it has none)."""
    from ..evaluate import resample
    pts = [resample(np.asarray(l.center, float), step) for l in lanelets
           if l.arm == arm and l.kind in ('entering', 'leaving')]
    return np.concatenate(pts) if pts else np.zeros((0, 2))


def world_without_arm(scenario, rng: np.random.Generator):
    """The world of ``scenario`` with one arm closed: ``(scenario without every vehicle that
    drove the arm, {'arm': index of the ground truth's arm, 'vehicles': how many were
    dropped})``, or ``(None, None)`` when no arm qualifies.

    The arm is drawn among the arms the ego does not drive (its sensors ride on it) and some
    vehicle did (an arm nobody drove is closed already, and nothing can show it). A vehicle
    drove the arm when its true path comes within ``ARM_TOUCH_M`` of one of the arm's
    entering or leaving lanes -- by geometry, so that the SUMO family (whose vehicles carry no
    lanelet route) and Table I are edited alike. The map of such a case is the unchanged
    ground truth, and the change to find is ``arm_removed`` (:data:`WORLD_EDITS`). Sensor noise
    is drawn anew (seed ``scenario.seed * 1000 + 999``: another drive of the same place)."""
    from dataclasses import replace
    from scipy.spatial import cKDTree
    if getattr(scenario, 'real', None):          # recorded data: its vehicles cannot be taken out
        return None, None
    gone = {}
    for a in range(len(scenario.gt.arms)):
        pts = arm_lane_points(scenario.gt_lanelets, a)
        if not len(pts):
            continue
        tree = cKDTree(pts)
        if (tree.query(scenario.ego.xy)[0] < ARM_TOUCH_M).any():
            continue
        ids = {i for i, tr in enumerate(scenario.tracks) if _drove_arm(tr, tree)}
        if ids:
            gone[a] = ids
    if not gone:
        return None, None
    a = sorted(gone)[int(rng.integers(len(gone)))]
    keep = [tr for i, tr in enumerate(scenario.tracks) if i not in gone[a]]
    world = replace(scenario, tracks=keep, seed=int(scenario.seed) * 1000 + 999, _cache={})
    return world, {'arm': int(a), 'vehicles': len(gone[a])}
