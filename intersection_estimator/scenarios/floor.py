"""The traffic-following floor of a case (issue 15 part 3).

A line that simply follows the traffic: per true lane, the points of the vehicles that
drove it (as the data give them: tracked detections, or the real tracks) projected onto
the lane's center line, their signed lateral offsets smoothed along the lane with a
Gaussian kernel (``sigma_m``), evaluated every ``step_m`` where at least ``min_weight``
points' worth of kernel weight supports it and a point lies within ``sigma_m``. Its mean orthogonal distance to the true
center line (:mod:`intersection_estimator.evaluate`, ``floor_cm``) is what following the
traffic costs on that case: lane courses well below it fit the map, not the data.

Labels: which lanelet each point belongs to comes from the lane-graph segment the
vehicle was on (:func:`label_points`): SUMO reports it, the AV2 converter map-matches it
(:func:`match_segments`). A vehicle's connector fixes which of the lanelets sharing an
upstream segment (turn pockets) its approach belongs to; where connectors share their first
pieces (an inD ring), the piece where they part fixes the connector.

Traffic is what drove: a vehicle that stands still through the whole recording (a parked
car, a car waiting at the kerb) shows neither a lane's course nor its direction, and the
estimator must not build an arm from it (issue 15), so it is not asked for one either --
:func:`drove` drops its labels before lanes are counted or followed.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ['project', 'traffic_line', 'traffic_lines', 'label_points', 'traffic_counts',
           'match_segments', 'drove', 'MIN_TRAVEL_M']

#: a vehicle whose positions, averaged over 1 s chunks (10 points), all lie within a box of
#: this diagonal never drove in the recording (1 m sensor noise spreads a standing
#: vehicle's chunk means over ~1-1.5 m)
MIN_TRAVEL_M = 3.0


def project(points: np.ndarray, line: np.ndarray):
    """-> arc position s, signed lateral offset d (left of the driving direction > 0) and
    ``inside`` (foot point not beyond the ends) of each point on the polyline."""
    a, b = line[:-1], line[1:]
    ab = b - a
    ll = np.maximum((ab ** 2).sum(1), 1e-12)
    rel = points[:, None, :] - a[None]
    t_raw = (rel * ab[None]).sum(2) / ll[None]
    t = np.clip(t_raw, 0.0, 1.0)
    foot = a[None] + t[..., None] * ab[None]
    d2 = ((points[:, None, :] - foot) ** 2).sum(2)
    j = d2.argmin(1)
    r = np.arange(len(points))
    seg_s = np.concatenate([[0.0], np.cumsum(np.sqrt(ll))])
    s = seg_s[j] + t[r, j] * np.sqrt(ll[j])
    cross = ab[j, 0] * rel[r, j, 1] - ab[j, 1] * rel[r, j, 0]
    d = np.sign(cross) * np.sqrt(d2[r, j])
    tr = t_raw[r, j]
    inside = ~(((j == 0) & (tr < 0)) | ((j == len(ab) - 1) & (tr > 1)))
    return s, d, inside


def traffic_line(line: np.ndarray, points: np.ndarray, *, sigma_m: float = 2.0,
                 step_m: float = 1.0, min_weight: float = 2.0):
    """The line that follows ``points`` along the lane ``line`` (module doc), or None."""
    if len(points) == 0 or len(line) < 2:
        return None
    s, d, inside = project(np.asarray(points, float), np.asarray(line, float))
    s, d = s[inside], d[inside]
    length = float(np.linalg.norm(np.diff(line, axis=0), axis=1).sum())
    grid = np.arange(0.0, length + 1e-9, step_m)
    if len(s) == 0 or len(grid) < 2:
        return None
    w = np.exp(-0.5 * ((grid[:, None] - s[None]) / sigma_m) ** 2)
    wsum = w.sum(1)
    srt = np.sort(s)
    j = np.clip(np.searchsorted(srt, grid), 1, len(srt) - 1) if len(srt) > 1 else np.zeros(len(grid), int)
    near = np.minimum(np.abs(grid - srt[j]), np.abs(grid - srt[np.maximum(j - 1, 0)]))
    ok = (wsum >= min_weight) & (near <= sigma_m)     # supported, and not beyond the data
    if ok.sum() < 2:
        return None
    off = (w[ok] @ d) / wsum[ok]
    seg = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(line, axis=0), axis=1))])
    g = grid[ok]
    cx, cy = np.interp(g, seg, line[:, 0]), np.interp(g, seg, line[:, 1])
    eps = 0.5 * step_m
    tx = np.interp(np.minimum(g + eps, length), seg, line[:, 0]) - np.interp(np.maximum(g - eps, 0), seg, line[:, 0])
    ty = np.interp(np.minimum(g + eps, length), seg, line[:, 1]) - np.interp(np.maximum(g - eps, 0), seg, line[:, 1])
    n = np.hypot(tx, ty)
    n = np.where(n > 0, n, 1.0)
    return np.stack([cx - off * ty / n, cy + off * tx / n], axis=1)


def traffic_lines(lanelets, xy: np.ndarray, labels: np.ndarray, **kw) -> dict:
    """{lanelet id: traffic line} for every lanelet with labelled points."""
    out = {}
    for ll in lanelets:
        sel = labels == ll.id
        if sel.any():
            tl = traffic_line(ll.center, xy[sel], **kw)
            if tl is not None:
                out[ll.id] = tl
    return out


def traffic_counts(lanelets, labels: np.ndarray, vehicle: np.ndarray, min_points: int = 3) -> dict:
    """{lanelet id: vehicles with >= ``min_points`` points on it} (0 for unused lanes)."""
    out = {ll.id: 0 for ll in lanelets}
    keys, n = np.unique(np.stack([labels.astype(str), vehicle.astype(str)], 1), axis=0,
                        return_counts=True) if len(labels) else (np.zeros((0, 2)), [])
    for (lid, _), c in zip(keys, n):
        if lid in out and c >= min_points:
            out[lid] += 1
    return out


def drove(labels: np.ndarray, vehicle: np.ndarray, xy: np.ndarray, t: np.ndarray,
          min_travel_m: float = MIN_TRAVEL_M, chunk: int = 10) -> np.ndarray:
    """``labels`` with '' for every row of a vehicle that did not drive in the recording:
    its positions averaged over consecutive ``chunk`` points (by ``t``; halves for a track
    shorter than two chunks) span a box of diagonal below ``min_travel_m`` (module
    docstring). A vehicle that drove up to a queue and stood there keeps its labels."""
    out = np.asarray(labels).astype(object).copy()
    vehicle = np.asarray(vehicle)
    order = np.lexsort((np.asarray(t, float), vehicle))
    cuts = np.flatnonzero(vehicle[order][1:] != vehicle[order][:-1]) + 1
    for rows in np.split(order, cuts):
        P = np.asarray(xy, float)[rows]
        k = chunk if len(P) >= 2 * chunk else max(1, len(P) // 2)
        means = np.stack([c.mean(0) for c in np.array_split(P, max(1, len(P) // k))])
        if np.linalg.norm(np.ptp(means, axis=0)) < min_travel_m:
            out[rows] = ''
    return out.astype(str)


def label_points(seg: np.ndarray, vehicle: np.ndarray, gt) -> np.ndarray:
    """Lanelet id per point ('' = none) from its segment id and vehicle (module doc);
    ``gt`` is a :class:`~.lanegraph.LaneGraphGT`."""
    by_id = {ll.id: ll for ll in gt.lanelets}
    owners: dict = {}
    for lid, segs in gt.segments_of.items():
        for s in segs:
            owners.setdefault(s, []).append(lid)
    entering_of = {c: ll.id for ll in gt.lanelets for c in ll.successors
                   if ll.kind == 'entering'}
    seg = np.asarray(seg).astype(str)
    vehicle = np.asarray(vehicle).astype(str)
    out = np.full(len(seg), '', dtype=object)
    v_codes, v_of = np.unique(vehicle, return_inverse=True)
    s_codes, s_of = np.unique(seg, return_inverse=True)
    for v in range(len(v_codes)):
        idx = np.flatnonzero(v_of == v)
        segs_v = s_codes[s_of[idx]]
        c = _vehicle_connector(segs_v, owners, by_id, gt.segments_of)
        mine = {c, entering_of.get(c, ''), by_id[c].successors[0]} if c else set()
        pick = {}
        for s in set(segs_v.tolist()):       # one decision per (vehicle, segment)
            cand = owners.get(s, [])
            if mine:
                cand = [x for x in cand if x in mine]
            pick[s] = cand[0] if len(cand) == 1 else ''
        out[idx] = [pick[s] for s in segs_v]
    return out.astype(str)


def _vehicle_connector(segs_v: np.ndarray, owners: dict, by_id: dict, segments_of: dict) -> str:
    """The connector a vehicle drove ('' if none or undecided): the one holding most of
    the distinct connector segments it was seen on, then most of its points. Connectors of
    a junction cluster share their first pieces (a turn and the straight ahead through the
    same link between two nodes of an inD ring), so the piece where they part decides; a
    vehicle seen on the shared pieces only is undecided."""
    seen, n = np.unique(segs_v, return_counts=True)
    pts = dict(zip(seen.tolist(), n.tolist()))
    cons = {lid for s in pts for lid in owners.get(s, []) if by_id[lid].kind == 'connector'}

    def covered(c):                  # (distinct pieces of c it was seen on, its points there)
        mine = [s for s in segments_of[c] if s in pts]
        return len(mine), sum(pts[s] for s in mine)
    score = {c: covered(c) for c in cons}
    best = [c for c in cons if score[c] == max(score.values())]
    return best[0] if len(best) == 1 else ''


def match_segments(xy: np.ndarray, heading: np.ndarray, segs: dict, *, gate_m: float = 2.5,
                   max_angle_deg: float = 45.0) -> np.ndarray:
    """Map matching: nearest segment (orthogonal distance <= ``gate_m``, driving
    direction within ``max_angle_deg`` of ``heading``) per point, '' if none."""
    best = np.full(len(xy), np.inf)
    out = np.full(len(xy), '', dtype=object)
    cos_max = math.cos(math.radians(max_angle_deg))
    hd = np.stack([np.cos(heading), np.sin(heading)], axis=1)
    for sid, sg in segs.items():
        c = np.asarray(sg.center, float)
        if len(c) < 2:
            continue
        lo, hi = c.min(0) - gate_m, c.max(0) + gate_m
        near = np.flatnonzero(((xy >= lo) & (xy <= hi)).all(1))
        if len(near) == 0:
            continue
        s, d, inside = project(xy[near], c)
        seg_s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(c, axis=0), axis=1))])
        j = np.clip(np.searchsorted(seg_s, s) - 1, 0, len(c) - 2)
        t = c[j + 1] - c[j]
        t /= np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-9)
        ok = inside & (np.abs(d) <= gate_m) & ((t * hd[near]).sum(1) >= cos_max)
        ok &= np.abs(d) < best[near]
        best[near[ok]] = np.abs(d[ok])
        out[near[ok]] = sid
    return out.astype(str)


def route_labels(dets, tracks, lanelets) -> np.ndarray:
    """Lanelet id per detection of a simulated scene whose tracks know their route
    (Table I simulator): the nearest lanelet of the track's route; '' for false tracks."""
    by_id = {ll.id: ll for ll in lanelets}
    route = {tr.id: [r for r in tr.route if r in by_id] for tr in tracks}
    out = np.full(len(dets), '', dtype=object)
    for tid, lanes in route.items():
        rows = np.flatnonzero(dets.track_id == tid)
        if len(rows) == 0 or not lanes:
            continue
        dist = np.full((len(lanes), len(rows)), np.inf)
        for k, lid in enumerate(lanes):
            _, d, inside = project(dets.xy[rows], by_id[lid].center)
            dist[k] = np.where(inside, np.abs(d), np.inf)
        best = dist.argmin(0)
        ok = np.isfinite(dist.min(0))
        out[rows[ok]] = np.array(lanes, dtype=object)[best[ok]]
    return out.astype(str)


def scene_traffic_lines(sc, mode: str = 'tracked') -> dict:
    """{lanelet id: {'traffic_line': line}} of a Table I scene from its tracked detections."""
    dets = sc.detections(mode)
    labels = route_labels(dets, sc.tracks, sc.gt_lanelets)
    return {lid: {'traffic_line': line}
            for lid, line in traffic_lines(sc.gt_lanelets, dets.xy, labels).items()}
