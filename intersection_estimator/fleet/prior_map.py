"""A prior Lanelet2 map and the intersections of its lane graph (issue 17, "Prior map").

The map is loaded with ``lanelet2`` (projector ``local`` = the LocalCartesian projector
our export writes with, or ``utm``; origin as latitude/longitude). Its intersections are
read from the lane graph, not from tags a map may lack:

* a **connector** is a lanelet tagged ``turn_direction`` (Autoware) or whose borders are
  both ``virtual`` (DESIGN.md §6);
* connectors are grouped into intersections when they share an entering or leaving
  lanelet (routing graph predecessors/successors) or lie within ``CLUSTER_M`` of each other;
* the **entering** lanes of an intersection are the predecessors of its connectors, the
  **leaving** lanes their successors; an **arm** is a group of entering/leaving lanes whose
  outward headings at the intersection agree within ``ARM_TOL_DEG`` (paper §II-B: arms
  ``a = (angle, gap, lanes)``); lane index 0 is next to the median, as in
  :mod:`intersection_estimator.model`;
* the **center** is the least-squares point of the arms' axes (the median line between
  the innermost entering and leaving lane), the paper's intersection center ``c``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import math

import numpy as np

from ..components import components
from ..model import ENTERING, LEAVING, wrap_angle

__all__ = ['LaneRecord', 'MappedLane', 'MappedArm', 'MappedConnector', 'MappedIntersection',
           'load_prior_map', 'records_from_lanelet_map', 'records_from_lanelets',
           'derive_intersections', 'PriorMapError']

CLUSTER_M = 25.0      # connectors closer than this belong to one intersection [m]
ARM_TOL_DEG = 25.0    # lanes whose outward headings differ less are one arm
END_M = 10.0          # heading of a lane at the intersection over its last/first metres


class PriorMapError(ValueError):
    """The prior map cannot be loaded or has no intersection (one-line reason)."""


@dataclass
class LaneRecord:
    """One lanelet as the lane graph sees it: center line in driving direction."""

    id: str
    center: np.ndarray
    successors: list[str] = field(default_factory=list)
    connector: bool = False
    name: str = ''            # our export's ``ie:id`` when present
    neighbours: list[str] = field(default_factory=list)   # same-direction lanes beside it


@dataclass
class MappedLane:
    id: str
    name: str
    arm: int
    direction: int            # ENTERING / LEAVING
    index: int                # 0 = next to the median
    center: np.ndarray


@dataclass
class MappedArm:
    index: int
    angle: float              # heading from the center outward [rad]
    lanes_in: list[MappedLane]
    lanes_out: list[MappedLane]

    def lanes(self, direction: int) -> list[MappedLane]:
        return self.lanes_in if direction == ENTERING else self.lanes_out


@dataclass
class MappedConnector:
    id: str
    name: str
    lane_in: str
    lane_out: str
    key: tuple                # (arm_from, k_in, arm_to, k_out) in map indices
    center: np.ndarray


@dataclass
class MappedIntersection:
    id: str
    center: np.ndarray
    arms: list[MappedArm]
    connectors: list[MappedConnector]
    traffic_side: int = 1


def lane_centers(X: MappedIntersection):
    """``(lanelet id, center line)`` of every mapped lane and connector of ``X``."""
    for a in X.arms:
        for l in a.lanes_in + a.lanes_out:
            yield l.id, l.center
    for c in X.connectors:
        yield c.id, c.center


def _projector(kind: str, origin):
    from lanelet2.io import Origin
    from lanelet2.projection import LocalCartesianProjector, UtmProjector
    o = Origin(float(origin[0]), float(origin[1]))
    if kind == 'local':
        return LocalCartesianProjector(o)
    if kind == 'utm':
        return UtmProjector(o)
    raise PriorMapError(f"projector: unknown '{kind}' (local | utm)")


def load_prior_map(path, *, origin=(49.0, 8.4), projector: str = 'local') -> list[MappedIntersection]:
    """Load a Lanelet2 OSM map and derive its intersections; raises :class:`PriorMapError`."""
    import lanelet2
    try:
        lmap, errors = lanelet2.io.loadRobust(str(path), _projector(projector, origin))
    except (RuntimeError, OSError) as exc:
        raise PriorMapError(f'prior map {path}: {" ".join(str(exc).split())}') from None
    if len(lmap.laneletLayer) == 0:
        raise PriorMapError(f'prior map {path}: no lanelets' + (f' ({errors[0]})' if errors else ''))
    return derive_intersections(records_from_lanelet_map(lmap))


def _is_connector(ll) -> bool:
    attrs = ll.attributes
    if 'turn_direction' in attrs:
        return True
    kinds = [b.attributes['type'] if 'type' in b.attributes else '' for b in (ll.leftBound, ll.rightBound)]
    return all(k == 'virtual' for k in kinds)


def records_from_lanelet_map(lmap) -> list[LaneRecord]:
    """Lane graph of a ``lanelet2`` map (successors from its vehicle routing graph)."""
    from lanelet2 import routing, traffic_rules
    rules = traffic_rules.create(traffic_rules.Locations.Germany, traffic_rules.Participants.Vehicle)
    graph = routing.RoutingGraph(lmap, rules)
    out = []
    for ll in sorted(lmap.laneletLayer, key=lambda l: l.id):
        c = np.array([[p.x, p.y] for p in ll.centerline], float)
        name = ll.attributes['ie:id'] if 'ie:id' in ll.attributes else ''
        beside = [graph.adjacentLeft(ll), graph.adjacentRight(ll), graph.left(ll), graph.right(ll)]
        out.append(LaneRecord(id=str(ll.id), center=c, connector=_is_connector(ll), name=name,
                              successors=sorted(str(f.id) for f in graph.following(ll)),
                              neighbours=sorted({str(b.id) for b in beside if b is not None})))
    return out


def records_from_lanelets(lanelets) -> list[LaneRecord]:
    """Lane graph of :class:`model.Lanelet` objects (no OSM round trip; neighbours = a shared
    border, as the routing graph sees them)."""
    def key(b):
        return tuple(np.round(np.asarray(b, float), 3).ravel())
    right = {key(l.right): l.id for l in lanelets if l.kind != 'connector'}
    left = {key(l.left): l.id for l in lanelets if l.kind != 'connector'}
    return [LaneRecord(id=l.id, name=l.id, center=np.asarray(l.center, float), connector=l.kind == 'connector',
                       successors=list(l.successors),
                       neighbours=sorted({x for x in (right.get(key(l.left)), left.get(key(l.right)))
                                          if x is not None and x != l.id}))
            for l in lanelets]


def _with_neighbours(recs: dict, lanes: set) -> list[str]:
    """``lanes`` and every non-connector lane beside them (transitively): a lane of an arm
    belongs to the intersection even when the map gives it no connector."""
    todo, out = list(lanes), set(lanes)
    while todo:
        for n in recs[todo.pop()].neighbours:
            if n in recs and n not in out and not recs[n].connector:
                out.add(n)
                todo.append(n)
    return sorted(out)


def _clusters(recs: dict, connectors: list[str], preds: dict) -> list[list[str]]:
    """Connectors grouped by shared lanes or proximity (connected components)."""
    by_lane: dict = {}
    for c in connectors:
        for lane in preds.get(c, []) + [s for s in recs[c].successors if not recs[s].connector]:
            by_lane.setdefault(lane, []).append(c)
    pairs = [(group[0], c) for group in by_lane.values() for c in group[1:]]
    mids = {c: recs[c].center[len(recs[c].center) // 2] for c in connectors}
    pairs += [(a, b) for i, a in enumerate(connectors) for b in connectors[i + 1:]
              if np.hypot(*(mids[a] - mids[b])) < CLUSTER_M]
    return components(connectors, pairs)


def _end(center: np.ndarray, direction: int):
    """(point at the intersection, outward unit heading) of a lane's center line."""
    c = center if direction == LEAVING else center[::-1]
    s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(c, axis=0).T))])
    j = int(min(len(c) - 1, max(1, np.searchsorted(s, END_M))))
    d = c[j] - c[0]
    return c[0], d / max(np.hypot(*d), 1e-9)


def _group_arms(ends: list) -> list[list[int]]:
    """Indices of ``ends`` grouped by outward angle (circular, gap > ARM_TOL_DEG splits)."""
    ang = np.array([math.atan2(u[1], u[0]) for _, u, _, _ in ends])
    order = np.argsort(ang)
    a = ang[order]
    gaps = np.diff(np.concatenate([a, [a[0] + 2 * math.pi]]))
    tol = math.radians(ARM_TOL_DEG)
    if (gaps > tol).sum() == 0:
        return [list(order)]
    start = int(np.argmax(gaps > tol)) + 1          # first element after a split
    groups, cur = [], []
    for i in range(len(a)):
        k = (start + i) % len(a)
        cur.append(int(order[k]))
        if gaps[k] > tol:
            groups.append(cur)
            cur = []
    return groups


def _traffic_side(ends: list, arms: list[list[int]]) -> int:
    """+1 when entering lanes lie left of leaving ones looking outward (right-hand traffic)."""
    votes = 0.0
    for g in arms:
        u = np.mean([ends[i][1] for i in g], axis=0)
        n = np.array([-u[1], u[0]])
        off = {d: [float(ends[i][0] @ n) for i in g if ends[i][2] == d] for d in (ENTERING, LEAVING)}
        if off[ENTERING] and off[LEAVING]:
            votes += np.mean(off[ENTERING]) - np.mean(off[LEAVING])
    return 1 if votes >= 0 else -1


def _center(axes: list, fallback: np.ndarray) -> np.ndarray:
    """Least-squares point of the arm axes (lines through p with heading u)."""
    A, b = np.zeros((2, 2)), np.zeros(2)
    for p, u in axes:
        M = np.eye(2) - np.outer(u, u)
        A += M
        b += M @ p
    if len(axes) < 2 or np.linalg.cond(A) > 1e6:
        return fallback
    return np.linalg.solve(A, b)


def _build_arms(ends: list, groups: list, recs: dict, ts: int):
    arms, axes = [], []
    for g in groups:
        u = np.mean([ends[i][1] for i in g], axis=0)
        u /= max(np.hypot(*u), 1e-9)
        n = np.array([-u[1], u[0]])
        side = {ENTERING: [], LEAVING: []}
        for i in g:
            p, _, d, lid = ends[i]
            side[d].append((float(ts * (p @ n)) * (1 if d == ENTERING else -1), lid, p))
        for d in side:
            side[d].sort(key=lambda t: t[0])
        inner = [side[d][0][2] for d in (ENTERING, LEAVING) if side[d]]
        axes.append((np.mean(inner, axis=0), u))
        arms.append([math.atan2(u[1], u[0]), side])
    order = np.argsort([a[0] for a in arms])
    out = []
    for k, j in enumerate(order):
        ang, side = arms[j]
        lanes = {d: [MappedLane(id=lid, name=recs[lid].name, arm=k, direction=d, index=i, center=recs[lid].center)
                     for i, (_, lid, _) in enumerate(side[d])] for d in side}
        out.append(MappedArm(index=k, angle=float(wrap_angle(ang)), lanes_in=lanes[ENTERING],
                             lanes_out=lanes[LEAVING]))
    return out, [axes[j] for j in order]


def _intersection(recs: dict, group: list[str], preds: dict) -> MappedIntersection | None:
    lanes_in = _with_neighbours(recs, {p for c in group for p in preds.get(c, []) if not recs[p].connector})
    lanes_out = _with_neighbours(recs, {s for c in group for s in recs[c].successors if not recs[s].connector})
    ends = [(*_end(recs[l].center, ENTERING), ENTERING, l) for l in lanes_in]
    ends += [(*_end(recs[l].center, LEAVING), LEAVING, l) for l in lanes_out]
    if not ends:
        return None
    groups = _group_arms(ends)
    ts = _traffic_side(ends, groups)
    arms, axes = _build_arms(ends, groups, recs, ts)
    where = {l.id: (a.index, l.index) for a in arms for l in a.lanes_in + a.lanes_out}
    cons = []
    for c in group:
        for p in preds.get(c, []):
            for s in recs[c].successors:
                if p in where and s in where:
                    cons.append(MappedConnector(id=c, name=recs[c].name, lane_in=p, lane_out=s,
                                                key=(*where[p], *where[s]), center=recs[c].center))
    fallback = np.mean([recs[c].center[len(recs[c].center) // 2] for c in group], axis=0)
    ident = 'X' + min(group, key=lambda s: (len(s), s))
    return MappedIntersection(id=ident, center=_center(axes, fallback), arms=arms,
                              connectors=sorted(cons, key=lambda c: c.key), traffic_side=ts)


def derive_intersections(records: list[LaneRecord]) -> list[MappedIntersection]:
    """The intersections of a lane graph (module docstring), sorted by id."""
    recs = {r.id: r for r in records}
    preds: dict = {}
    for r in records:
        for s in r.successors:
            if s in recs:
                preds.setdefault(s, []).append(r.id)
    connectors = sorted((r.id for r in records if r.connector), key=lambda s: (len(s), s))
    out = [_intersection(recs, g, preds) for g in _clusters(recs, connectors, preds)]
    return sorted((x for x in out if x is not None), key=lambda x: x.id)
