"""Ground truth from a lane graph (SUMO net, AV2 map) as the project's types.

A *lane graph* is a dict of :class:`Segment` (a lane piece: center line in driving
direction, width, predecessor and successor ids, ``connector`` flag for the pieces
inside the junction box: SUMO internal lanes, AV2 ``is_intersection`` segments).
:func:`gt_from_lane_graph` turns it into an :class:`~intersection_estimator.model.Intersection`
and :class:`~intersection_estimator.model.Lanelet` list following :mod:`~intersection_estimator.model`:

* a *connector* is a maximal chain of connector segments from a non-connector segment
  (its entering lane) to a non-connector segment (its leaving lane);
* an *entering lane* is the chain of non-connector segments ending at a connector's
  start, grown backward (straightest predecessor) up to ``arm_length`` metres or until
  another junction's connector; a *leaving lane* likewise forward. Lanes added before
  the stop line (turn pockets) share their upstream segments with the lane they split
  from: both are lanes at the stop line, as the lane count at the stop line is what the
  topology model (paper §II-B) counts;
* arms: the lanes' outward directions (stop-line point -> point ``probe_m`` out) are
  clustered by angle (gaps > ``arm_gap_deg`` separate arms); the arm angle is the
  circular mean; lane index ``k`` counts from the median outward (lateral order at the
  stop line), lane width is the median segment width, gap from the lateral offsets.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import math

import numpy as np

from ..model import Arm, Intersection, Lanelet, wrap_angle

__all__ = ['Segment', 'LaneGraphGT', 'gt_from_lane_graph', 'connector_chains', 'arc_length',
           'borders']


@dataclass
class Segment:
    id: str
    center: np.ndarray           # (n, 2) in driving direction
    width: float = 3.5
    preds: list = field(default_factory=list)
    succs: list = field(default_factory=list)
    connector: bool = False


@dataclass
class LaneGraphGT:
    """The ground truth plus how it maps back to the lane graph."""

    intersection: Intersection
    lanelets: list[Lanelet]
    segments_of: dict            # lanelet id -> list of segment ids (driving order)
    stop: np.ndarray             # stop-line distance from the center per arm [m]


def arc_length(p: np.ndarray) -> np.ndarray:
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))])


def borders(center: np.ndarray, width) -> tuple[np.ndarray, np.ndarray]:
    """Left / right borders at +-width/2 along the left normal of the center line."""
    t = np.gradient(center, axis=0)
    t /= np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-9)
    n = np.stack([-t[:, 1], t[:, 0]], axis=1)
    hw = 0.5 * np.asarray(width, float).reshape(-1, 1)
    return center + hw * n, center - hw * n


def _join(parts: list[np.ndarray]) -> np.ndarray:
    """Concatenate polylines, dropping a repeated joint point."""
    out = [parts[0]]
    for p in parts[1:]:
        out.append(p[1:] if np.linalg.norm(p[0] - out[-1][-1]) < 1e-6 else p)
    pts = np.concatenate(out)
    keep = np.concatenate([[True], np.linalg.norm(np.diff(pts, axis=0), axis=1) > 1e-6])
    return pts[keep]


def connector_chains(segs: dict, connector_ids=None) -> list[tuple[str, list, str]]:
    """``(entering segment, [connector segments], leaving segment)`` per path through
    the box (only through ``connector_ids`` if given)."""
    allowed = set(connector_ids) if connector_ids is not None else {
        k for k, s in segs.items() if s.connector}
    out = []

    def walk(entry, path):
        for nxt in segs[path[-1]].succs:
            if nxt not in segs or nxt in path:
                continue
            if nxt in allowed:
                walk(entry, path + [nxt])
            elif not segs[nxt].connector:
                out.append((entry, list(path), nxt))

    for cid in sorted(allowed):
        for p in segs[cid].preds:
            if p in segs and not segs[p].connector:
                walk(p, [cid])
    return out


def _heading(p: np.ndarray, at_end: bool) -> np.ndarray:
    d = p[-1] - p[-2] if at_end else p[1] - p[0]
    return d / max(float(np.linalg.norm(d)), 1e-9)


def _grow(segs: dict, start: str, length: float, forward: bool) -> list[str]:
    """Chain of non-connector segments from ``start`` away from the box (straightest
    neighbour first) until ``length`` metres are covered."""
    chain = [start]
    total = float(arc_length(segs[start].center)[-1])
    while total < length:
        cur = segs[chain[-1]]
        nbrs = [x for x in (cur.succs if forward else cur.preds)
                if x in segs and not segs[x].connector and x not in chain]
        if not nbrs:
            break
        h = _heading(cur.center, at_end=forward) if forward else _heading(cur.center, False)

        def turn(x):
            c = segs[x].center
            hx = _heading(c, at_end=False) if forward else _heading(c, at_end=True)
            return -float(np.dot(h, hx)), x
        chain.append(min(nbrs, key=turn))
        total += float(arc_length(segs[chain[-1]].center)[-1])
    return chain if forward else chain[::-1]


def _trim(p: np.ndarray, length: float, keep_end: bool) -> np.ndarray:
    """The ``length`` metres of a polyline next to its end (``keep_end``) or start."""
    q = p[::-1] if keep_end else p
    s = arc_length(q)
    if s[-1] <= length:
        return p
    j = int(np.searchsorted(s, length))
    f = (length - s[j - 1]) / max(s[j] - s[j - 1], 1e-9)
    q = np.concatenate([q[:j], [q[j - 1] + f * (q[j] - q[j - 1])]])
    return q[::-1] if keep_end else q


def _point_at(p: np.ndarray, dist: float) -> np.ndarray:
    s = arc_length(p)
    d = min(dist, s[-1])
    return np.array([np.interp(d, s, p[:, 0]), np.interp(d, s, p[:, 1])])


def _cluster_angles(ang: np.ndarray, gap_deg: float) -> np.ndarray:
    """Cluster label per angle: sorted circularly, split at gaps > ``gap_deg``."""
    order = np.argsort(ang)
    a = ang[order]
    cut = np.diff(np.concatenate([a, [a[0] + 2 * math.pi]])) > math.radians(gap_deg)
    labels = np.zeros(len(a), int)
    if not cut.any():
        return labels
    start, cur = (int(np.argmax(cut)) + 1) % len(a), 0   # first angle after a cut
    for i in range(len(a)):
        j = (start + i) % len(a)
        labels[order[j]] = cur
        cur += int(cut[j])
    return labels


def _lane_lines(segs, starts, arm_length, forward):
    """{segment id at the stop line: (segment chain, center line of at most arm_length)}."""
    out = {}
    for sid in starts:
        ids = _grow(segs, sid, arm_length, forward)
        line = _join([segs[i].center for i in ids])
        out[sid] = (ids, _trim(line, arm_length, keep_end=not forward))
    return out


def _arms(lines_in, lines_out, center, probe_m, gap_deg):
    """Cluster the lanes into arms -> (arm label per lane key, arm angles sorted)."""
    keys, dirs = [], []
    for sid, (_, c) in lines_in.items():
        keys.append(('in', sid))
        dirs.append(_point_at(c[::-1], probe_m) - c[-1])
    for sid, (_, c) in lines_out.items():
        keys.append(('out', sid))
        dirs.append(_point_at(c, probe_m) - c[0])
    ang = np.arctan2([d[1] for d in dirs], [d[0] for d in dirs])
    lab = _cluster_angles(ang, gap_deg)
    means = [float(np.arctan2(np.sin(ang[lab == k]).sum(), np.cos(ang[lab == k]).sum()))
             for k in range(lab.max() + 1)]
    order = np.argsort(wrap_angle(np.array(means)))          # Intersection sorts by angle
    rank = np.empty(len(order), int)
    rank[order] = np.arange(len(order))
    return {k: int(rank[lab[i]]) for i, k in enumerate(keys)}, [means[i] for i in order]


def _lane_indices(keys, lines, arm_of, angle, center, ts):
    """k per lane of each arm (0 next to the median) and each lane's lateral offset."""
    k_of, offs = {}, {}
    for a, ang in enumerate(angle):
        n = np.array([-math.sin(ang), math.cos(ang)])
        for kind, side in (('in', 1.0), ('out', -1.0)):
            mine = [key for key in keys if key[0] == kind and arm_of[key] == a]
            stop = {key: (lines[key][1][-1] if kind == 'in' else lines[key][1][0]) for key in mine}
            off = {key: float((stop[key] - center) @ n) for key in mine}
            for k, key in enumerate(sorted(mine, key=lambda q: side * ts * off[q])):
                k_of[key], offs[key] = k, off[key]
    return k_of, offs


def _arm_params(a, keys, arm_of, offs, widths, ts):
    """-> lanes_in, lanes_out, lane width, median gap of arm ``a``."""
    mine = [k for k in keys if arm_of[k] == a]
    n_in = sum(k[0] == 'in' for k in mine)
    n_out = len(mine) - n_in
    w = float(np.median([widths[k] for k in mine]))
    gap = 0.0
    if n_in and n_out:
        inner_in = min(ts * offs[k] for k in mine if k[0] == 'in')
        inner_out = max(ts * offs[k] for k in mine if k[0] == 'out')
        gap = max(0.0, inner_in - inner_out - w)
    return n_in, n_out, w, gap


def _lanelet(lid, kind, arm, k, center, width, **kw) -> Lanelet:
    from ..evaluate import resample
    c = resample(center, 1.0) if len(center) >= 2 else center
    left, right = borders(c, width)
    return Lanelet(id=lid, kind=kind, arm=arm, left=left, right=right, center=c, lane_index=k,
                   **kw)


def gt_from_lane_graph(segs: dict, connector_ids=None, *, arm_length: float = 60.0,
                       probe_m: float = 15.0, arm_gap_deg: float = 20.0,
                       traffic_side: int = 1) -> LaneGraphGT:
    """Intersection + lanelets of the junction whose box is ``connector_ids`` (module doc)."""
    chains = connector_chains(segs, connector_ids)
    if not chains:
        raise ValueError('lane graph: no connector joins an entering to a leaving lane')
    li = _lane_lines(segs, sorted({e for e, _, _ in chains}), arm_length, forward=False)
    lo = _lane_lines(segs, sorted({x for _, _, x in chains}), arm_length, forward=True)
    lines = {('in', k): v for k, v in li.items()} | {('out', k): v for k, v in lo.items()}
    center = np.mean([c[-1] for _, c in li.values()] + [c[0] for _, c in lo.values()], axis=0)
    arm_of, angles = _arms(li, lo, center, probe_m, arm_gap_deg)
    keys = list(lines)
    k_of, offs = _lane_indices(keys, lines, arm_of, angles, center, traffic_side)
    widths = {key: float(segs[key[1]].width) for key in keys}
    arms, stop = [], []
    for a, ang in enumerate(angles):
        n_in, n_out, w, gap = _arm_params(a, keys, arm_of, offs, widths, traffic_side)
        arms.append(Arm(angle=float(wrap_angle(ang)), gap=gap, lanes_in=n_in, lanes_out=n_out,
                        lane_width=w))
        pts = [lines[k][1][-1] if k[0] == 'in' else lines[k][1][0] for k in keys if arm_of[k] == a]
        stop.append(float(np.mean(np.linalg.norm(np.array(pts) - center, axis=1))))
    name = {key: f'a{arm_of[key]}_{key[0]}{k_of[key]}' for key in keys}
    lanelets = {name[key]: _lanelet(name[key], 'entering' if key[0] == 'in' else 'leaving',
                                    arm_of[key], k_of[key], lines[key][1], widths[key])
                for key in keys}
    segments_of = {name[key]: list(lines[key][0]) for key in keys}
    for e, path, x in chains:
        ki, ko = ('in', e), ('out', x)
        lin, lout = lanelets[name[ki]], lanelets[name[ko]]
        cid = f'c_a{arm_of[ki]}i{k_of[ki]}_a{arm_of[ko]}o{k_of[ko]}'
        base, j = cid, 2
        while cid in lanelets:
            cid, j = f'{base}_{j}', j + 1
        line = _join([lin.center[-1:]] + [segs[s].center for s in path] + [lout.center[:1]])
        w = float(np.mean([segs[s].width for s in path]))
        con = _lanelet(cid, 'connector', arm_of[ki], k_of[ki], line, w, arm_to=arm_of[ko],
                       successors=[lout.id])
        con.center[0], con.center[-1] = lin.center[-1], lout.center[0]
        lin.successors.append(cid)
        lanelets[cid] = con
        segments_of[cid] = list(path)
    inter = Intersection(center=center, arms=arms, traffic_side=traffic_side)
    return LaneGraphGT(inter, list(lanelets.values()), segments_of, np.array(stop))
