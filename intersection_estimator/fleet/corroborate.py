"""The drive's traffic against the map itself: does it corroborate what the estimate claims?
(issue 17, beyond the estimate).

A change is claimed from the difference between the estimate and the map. Where the
estimator errs -- real junctions bend, lanes are added before the stop line, arms do not
meet in one point -- that difference is the estimator's error, not the world's, and every
such error reads as a change (``docs/fleet.md``). The vehicles themselves do not err that
way: map-matched to the mapped lanes, they show where the traffic drove relative to the map,
independent of the estimator's model. A claim the traffic contradicts is dropped:

=====================  ==================================================================
``lane_moved``         the vehicles on the mapped lane drive along its center line (median
                       lateral offset below ``moved_m / 2``); nobody drove it and nobody
                       drove beside the mapped lanes of its arm direction either
``lane_removed``       a vehicle drove the mapped lane
``lane_added``         no vehicle of that arm direction drove outside the mapped lanes
``arm_removed``        a vehicle has a matched position on one of the mapped arm's lanes
                       (``TOUCH_POINTS``: a short arm gives its vehicles few)
``arm_added``          no vehicle drove outside the mapped lanes in that direction
``connector_added``    no vehicle went from the mapped entering lane to the mapped leaving
                       lane of the claimed turn (one that followed a mapped turn from that
                       entering lane past ``FOLLOW_SHARE`` of its length and then left on a
                       lane beside that turn's leaving lane took the mapped turn and changed
                       lanes after the box: that is no turn the map lacks)
``connector_unused``   a vehicle took the mapped turn
=====================  ==================================================================

The claims a real change makes survive: a moved lane's vehicles drive beside its mapped
center line, a lane or arm the map lacks carries traffic outside every mapped lane, a turn
the map lacks is driven from one mapped lane to the other.

Map matching (:func:`match_traffic`): a track's positions are averaged over ``SMOOTH_S``
(tracked objects carry a metre of noise: single points would stray onto the lane beside,
and a standing vehicle's noise would read as motion) and its heading is their displacement
over ``HEADING_S`` (slower than ``MIN_SPEED``: no heading, not matched). Each position is
matched to the nearest mapped lane or connector whose direction agrees (cos >
``HEADING_COS``) within ``match_gate_m`` laterally. A vehicle drove a lane when
``min_points`` of its positions matched it; its passage of an arm direction comes from the
lane most of its positions matched there, its turn from the entering lane it drove last to
the leaving lane it drove first after it (a connector's turn when only one side was seen; the
mapped turn it followed past ``FOLLOW_SHARE`` of its length when it then left on a lane beside
that turn's leaving lane). Positions outside the box (farther from the mapped center than the
nearest lane end) and within the map's reach that match nothing are *off the map*; a
vehicle with ``min_points`` of them drove outside the mapped lanes, at the arm sector and
in the direction (towards / away from the center) of those positions. Cyclists and
pedestrians (``SKIP_LABELS``) are not lane traffic and are left out.

The vehicles' turns on the map also give the turn counts of the lane-absence rule
(``changes._lane_absence``) when the drive is corroborated.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
import math

import numpy as np
from scipy.spatial import cKDTree

from ..evaluate import resample
from ..lanes.config import LaneConfig
from ..lanes.init import track_rows
from ..model import ENTERING, LEAVING
from ..scenarios.floor import MIN_TRAVEL_M    # a vehicle whose averaged positions span less never drove

__all__ = ['TrafficOnMap', 'match_traffic', 'refutes', 'tracks_of', 'drive_traffic', 'HEADING_S', 'HEADING_COS',
           'STEP_M']

HEADING_S = 2.0        # a point's heading: its track's displacement over this time [s]
SMOOTH_S = 1.0         # ... of its positions averaged over this time [s]
MIN_SPEED = 2.0        # slower points have no reliable heading and are not matched [m/s]
HEADING_COS = 0.7      # a lane matches a point when their directions agree this well
STEP_M = 0.5           # mapped center lines are sampled this densely for the matching [m]
#: Autoware labels of road users that keep to no lane (bicycle, pedestrian): the lane course's
SKIP_LABELS = LaneConfig().skip_labels
REACH_GATE_DEG = 30.0   # a point belongs to the mapped arm this close in angle for the map's reach
#: a vehicle that followed a mapped turn this far (share of its length) took it, whichever lane
#: of that arm it then left on. Fleet bench, cases 0-199, the vehicles whose turn the map lacks:
#: on the complete SUMO maps 42 of 70 had followed a mapped turn past 0.8 of it (lane changes
#: right after the box); of the vehicles of a turn removed from the map, 4 of 317 (SUMO) and
#: 0 of 289 (Table I, which follow the neighbouring turn from their lane to 0.26-0.74 of it)
FOLLOW_SHARE = 0.8
TOUCH_POINTS = 1         # positions on a mapped arm's lanes that show a vehicle drove the arm (refutes its removal)


@dataclass
class TrafficOnMap:
    """What one drive's vehicles did on one mapped intersection."""

    vehicles: dict = field(default_factory=dict)    # mapped lane id -> vehicles that drove it
    touched: dict = field(default_factory=dict)     # mapped lane id -> vehicles with >= TOUCH_POINTS on it
    offset_m: dict = field(default_factory=dict)    # mapped lane id -> median lateral offset (left +)
    turns: set = field(default_factory=set)         # (mapped entering lane id, leaving lane id) driven
    off_map: list = field(default_factory=list)     # (angle [rad] about the center, direction) per vehicle
    passages: dict = field(default_factory=dict)    # (mapped arm, direction) -> vehicles on its lanes
    moves: dict = field(default_factory=dict)       # (mapped arm, direction) -> {other arm: vehicles}
    lane_turns: dict = field(default_factory=dict)  # (mapped lane id, other arm) -> vehicles seen on it taking that turn


@dataclass(frozen=True)
class _Element:
    """A mapped lane or connector as the matching sees it."""

    id: str
    arm: int
    direction: int           # ENTERING / LEAVING; 0 for a connector
    center: np.ndarray
    turn: tuple = ()         # a connector's (entering lane id, leaving lane id)


def _elements(mapped) -> list:
    out = [_Element(l.id, a.index, l.direction, np.asarray(l.center, float))
           for a in mapped.arms for l in a.lanes_in + a.lanes_out]
    return out + [_Element(c.id, c.key[0], 0, np.asarray(c.center, float), (c.lane_in, c.lane_out))
                  for c in mapped.connectors]


def _samples(elements):
    """Dense samples of the elements' center lines: points, unit tangents, element index."""
    pts, tan, idx = [], [], []
    for i, el in enumerate(elements):
        p = resample(el.center, STEP_M) if len(el.center) >= 2 else el.center[:1]
        if len(p) < 2:                    # a single point or a zero-length line
            continue
        t = np.gradient(p, axis=0)
        t /= np.maximum(np.hypot(*t.T), 1e-9)[:, None]
        pts.append(p)
        tan.append(t)
        idx.append(np.full(len(p), i))
    if not pts:
        return np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0, int)
    return np.concatenate(pts), np.concatenate(tan), np.concatenate(idx)


def _fractions(I: np.ndarray) -> np.ndarray:
    """Per sample of :func:`_samples`: how far along its element it lies (0 start, 1 end;
    an element's samples are consecutive)."""
    start = np.flatnonzero(np.r_[True, I[1:] != I[:-1]])
    count = np.diff(np.r_[start, len(I)])
    first = np.repeat(start, count)
    last = np.repeat(count - 1, count)
    return np.where(last > 0, (np.arange(len(I)) - first) / np.maximum(last, 1), 1.0)


def _window(t: np.ndarray, half: float):
    return (np.clip(np.searchsorted(t, t - half, 'left'), 0, len(t) - 1),
            np.clip(np.searchsorted(t, t + half, 'right') - 1, 0, len(t) - 1))


def _smoothed(xy: np.ndarray, t: np.ndarray) -> np.ndarray:
    """The track's positions averaged over ``SMOOTH_S`` (sensor noise of a metre would put a
    vehicle's single points on the lane beside it, and a standing vehicle's noisy positions
    read as motion in a random direction)."""
    lo, hi = _window(t, 0.5 * SMOOTH_S)
    c = np.vstack([np.zeros((1, 2)), np.cumsum(xy, axis=0)])
    return (c[hi + 1] - c[lo]) / (hi - lo + 1)[:, None]


def _headings(m: np.ndarray, t: np.ndarray):
    """Unit travel direction per (smoothed) point: displacement over ``HEADING_S``; NaN where
    slower than ``MIN_SPEED``."""
    j_lo, j_hi = _window(t, 0.5 * HEADING_S)
    d = m[j_hi] - m[j_lo]
    dt = t[j_hi] - t[j_lo]
    v = np.hypot(*d.T) / np.where(dt > 0, dt, np.inf)
    u = d / np.maximum(np.hypot(*d.T), 1e-9)[:, None]
    u[(v < MIN_SPEED) | (dt < 0.5 * HEADING_S)] = np.nan
    return u


def _box_radius(mapped) -> float:
    """Distance from the mapped center of the nearest lane end (inside: the box)."""
    ends = [np.hypot(*(np.asarray(l.center[-1] if l.direction == ENTERING else l.center[0]) - mapped.center))
            for a in mapped.arms for l in a.lanes_in + a.lanes_out]
    return max(min(ends), 5.0) if ends else 5.0


def _reach(mapped, phi: np.ndarray, gate: float) -> np.ndarray:
    """How far from the center the map covers the road at angles ``phi``: the shortest far
    end of the lanes of the mapped arm within ``gate``, else the longest of all (traffic
    beyond a mapped lane's far end is not off the map, only beyond the map's extent)."""
    far = np.array([min((np.hypot(*(np.asarray(l.center[0] if l.direction == ENTERING else l.center[-1])
                                    - mapped.center)) for l in a.lanes_in + a.lanes_out), default=0.0)
                    for a in mapped.arms])
    if not len(far):
        return np.zeros(len(phi))
    ang = np.array([a.angle for a in mapped.arms])
    diff = np.abs(np.remainder(phi[:, None] - ang[None] + math.pi, 2 * math.pi) - math.pi)
    near = diff.argmin(1)
    return np.where(diff[np.arange(len(phi)), near] <= gate, far[near], far.max())


def _match_points(xy: np.ndarray, u: np.ndarray, queued: np.ndarray, tree, T, I, lane: np.ndarray,
                  gate_m: float):
    """Per point: the matched element (-1: none), the signed lateral offset to it and the matched
    sample of :func:`_samples` (-1: none). A moving
    point matches an element of its direction; a ``queued`` one (standing, of a vehicle that
    drove) the nearest lane, whatever its direction; other points are not looked up."""
    match, lat, sample = np.full(len(xy), -1), np.zeros(len(xy)), np.full(len(xy), -1)
    moving = np.isfinite(u[:, 0])
    go = np.flatnonzero(moving | queued)
    if not len(go):
        return match, lat, sample
    k = min(8, tree.n)
    j = tree.query(xy[go], k=k)[1].reshape(len(go), k)
    Tj = T[j]
    rel = xy[go, None, :] - tree.data[j]
    along = np.einsum('nkd,nkd->nk', rel, Tj)
    side = Tj[..., 0] * rel[..., 1] - Tj[..., 1] * rel[..., 0]           # left of the lane > 0
    ok = np.where(moving[go, None], np.einsum('nd,nkd->nk', np.nan_to_num(u[go]), Tj) > HEADING_COS, lane[j])
    # a sample stands for the STEP_M of line around it: a point whose foot lies further along
    # is another sample's (or beyond the element's end: a queue past a mapped lane's far end
    # is on no mapped lane, however well it lines up with it)
    ok &= np.abs(along) <= STEP_M
    ok &= np.abs(side) <= gate_m
    score = np.where(ok, np.abs(side), np.inf)
    rows = np.arange(len(go))
    best = score.argmin(1)
    hit = np.isfinite(score[rows, best])
    match[go] = np.where(hit, I[j[rows, best]], -1)
    lat[go] = side[rows, best]
    sample[go] = np.where(hit, j[rows, best], -1)
    return match, lat, sample


def _drove(smooth: np.ndarray) -> bool:
    """Did the vehicle drive in the window (its averaged positions span ``MIN_TRAVEL_M``)? A
    vehicle standing through the whole window (parked, waiting at the kerb) is no lane's
    traffic; one that drove up to a queue and stands there is (``scenarios.floor.drove``)."""
    return float(np.hypot(*np.ptp(smooth, axis=0))) >= MIN_TRAVEL_M


def match_traffic(tracks, mapped, gate_m: float, min_points: int,
                  follow_share: float = FOLLOW_SHARE) -> TrafficOnMap:
    """Map-match ``tracks`` (``[(xy (n, 2), t (n,)), ...]`` sorted by time, fixed frame) to
    the lanes and connectors of ``mapped`` (module doc; ``follow_share`` 0: a turn is its
    lanes alone)."""
    out = TrafficOnMap()
    elements = _elements(mapped)
    P, T, I = _samples(elements)
    tracks = [(xy, t) for xy, t in tracks if len(xy) >= min_points]
    if not len(P) or not tracks:
        return out
    smooth = [_smoothed(x, t) for x, t in tracks]
    xy = np.concatenate(smooth)
    u = np.concatenate([_headings(m, t) for m, (_, t) in zip(smooth, tracks)])
    queued = np.concatenate([np.full(len(m), _drove(m)) for m in smooth]) & ~np.isfinite(u[:, 0])
    lane = np.array([el.direction != 0 for el in elements])[I]
    match, lat, sample = _match_points(xy, u, queued, cKDTree(P), T, I, lane, gate_m)
    along = np.where(sample >= 0, _fractions(I)[sample], 0.0)
    radial = xy - mapped.center
    r = np.hypot(*radial.T)
    outside = (match < 0) & np.isfinite(u[:, 0]) & (r > _box_radius(mapped))
    outside &= r < _reach(mapped, np.arctan2(radial[:, 1], radial[:, 0]), math.radians(REACH_GATE_DEG))
    arm_of = {el.id: el.arm for el in elements if el.direction}
    offsets: dict = {}                    # mapped lane id -> its vehicles' matched offsets
    cuts = np.cumsum([len(x) for x, _ in tracks])[:-1]
    follow = _Follow(elements, arm_of, follow_share) if follow_share > 0 else None
    for m, off, o, rad, rr, uu, al in zip(*(np.split(v, cuts) for v in (match, lat, outside, radial, r, u, along))):
        _count(out, elements, m, off, min_points, arm_of, offsets, None if follow is None else follow.at(al))
        if o.sum() >= min_points:
            phi = math.atan2(*np.sum(rad[o] / rr[o, None], axis=0)[::-1])
            away = float(np.sum(uu[o] * rad[o] / rr[o, None])) > 0
            out.off_map.append((phi, LEAVING if away else ENTERING))
    out.offset_m = {k: float(np.median(np.concatenate(v))) for k, v in offsets.items()}
    return out


@dataclass
class _Follow:
    """The mapped turn a vehicle followed, for a turn the map lacks (``FOLLOW_SHARE``)."""

    elements: list
    arm_of: dict
    share: float
    mapped: frozenset = frozenset()      # the mapped turns
    along: np.ndarray | None = None      # per position of one vehicle: how far along its element

    def __post_init__(self):
        if not self.mapped:
            self.mapped = frozenset(el.turn for el in self.elements if not el.direction)

    def at(self, along: np.ndarray) -> '_Follow':
        """This rule for one vehicle."""
        return replace(self, along=along)

    def __call__(self, turn: tuple, at: dict) -> tuple:
        """``turn``, or the mapped turn from its entering lane to a lane of its leaving arm that
        the vehicle (positions per element ``at``) followed farthest, past ``share`` of it."""
        if turn in self.mapped:
            return turn
        best, reach = turn, self.share
        for i, k in at.items():
            el = self.elements[i]
            if el.direction or el.turn[0] != turn[0] or self.arm_of.get(el.turn[1]) != self.arm_of.get(turn[1]):
                continue
            r = float(self.along[k].max())
            if r >= reach:
                best, reach = el.turn, r
        return best


def _count(out: TrafficOnMap, elements, match: np.ndarray, off: np.ndarray, min_points: int,
           arm_of: dict, offsets: dict, follow=None) -> None:
    """One vehicle's matched elements: every lane ``min_points`` of its positions matched (a
    turn pocket's vehicle drives the through lane first) with their offsets; its passage of
    each arm direction from the lane most of its positions matched there; its turn from the
    entering lane it drove last to the leaving lane it drove first after it (the connector
    most of its positions matched when it was seen on one side only)."""
    at = {int(i): np.flatnonzero(match == i) for i in np.unique(match[match >= 0])}   # its positions per element
    n = {i: len(k) for i, k in at.items()}
    top: dict = {}
    for i, c in n.items():
        key = (elements[i].arm, elements[i].direction)
        if c >= min_points and c > n.get(top.get(key, -1), 0):
            top[key] = i
    for (arm, d), i in top.items():
        if d:
            out.passages[(arm, d)] = out.passages.get((arm, d), 0) + 1
    for i, c in n.items():
        if elements[i].direction and c >= min(TOUCH_POINTS, min_points):
            out.touched[elements[i].id] = out.touched.get(elements[i].id, 0) + 1
        if elements[i].direction and c >= min_points:
            lid = elements[i].id
            out.vehicles[lid] = out.vehicles.get(lid, 0) + 1
            offsets.setdefault(lid, []).append(off[at[i]])
    cons = [i for (_, d), i in top.items() if not d]
    # the turn is taken from the lane the vehicle drove last before the box (a turn pocket's
    # vehicle drove the through lane longer) to the leaving lane it drove first after it
    ins = [i for i, c in n.items() if c >= min_points and elements[i].direction == ENTERING]
    outs = [i for i, c in n.items() if c >= min_points and elements[i].direction == LEAVING]
    last_in = max(ins, key=lambda i: at[i][-1]) if ins else None
    after = [i for i in outs if last_in is None or at[i][0] > at[last_in][-1]]
    first_out = min(after, key=lambda i: at[i][0]) if after else None
    turn = None
    if last_in is not None and first_out is not None:
        turn = (elements[last_in].id, elements[first_out].id)
    if turn is not None and follow is not None:
        turn = follow(turn, at)
    if turn is None and cons:
        # seen on one side only: the mapped turn it followed (connectors from one lane overlap
        # at their start, so the lanes decide where both were seen: a turn the map lacks
        # must not read as the mapped turn beside it)
        turn = elements[max(cons, key=lambda i: n[i])].turn
    if turn is not None and turn[0] in arm_of and turn[1] in arm_of:
        out.turns.add(turn)
        a, b = arm_of[turn[0]], arm_of[turn[1]]
        for key, other in (((a, ENTERING), b), ((b, LEAVING), a)):
            per = out.moves.setdefault(key, {})
            per[other] = per.get(other, 0) + 1
        # the lane choice it showed, on each side where it was seen on a lane of the turn's
        # arm (a vehicle seen in the box only chose no lane there: it missed none)
        for i, arm, other in ((last_in, a, b), (first_out, b, a)):
            if i is not None and elements[i].arm == arm:
                key = (elements[i].id, other)
                out.lane_turns[key] = out.lane_turns.get(key, 0) + 1


def _off_map(traffic: TrafficOnMap, angle: float, direction, gate: float) -> int:
    return sum(1 for phi, d in traffic.off_map
               if abs(math.remainder(phi - angle, 2 * math.pi)) <= gate and (direction is None or d == direction))


def refutes(f, traffic: TrafficOnMap, mapped, moved_m: float, arm_gate_deg: float) -> bool:
    """Does the drive's traffic on the map contradict finding ``f`` (module table)?"""
    gate = math.radians(arm_gate_deg)
    if f.kind in ('lane_moved', 'lane_added'):
        lid = f.map_lanes[0] if f.kind == 'lane_moved' else None
        if lid is not None and traffic.vehicles.get(lid, 0) >= 1:
            return abs(traffic.offset_m[lid]) < 0.5 * moved_m
        # nobody drove the mapped lane (or it is a lane the map lacks): only traffic beside
        # the mapped lanes of that arm direction can show it
        d = ENTERING if f.direction == 'in' else LEAVING
        return _off_map(traffic, mapped.arms[f.map_arm].angle, d, gate) == 0
    if f.kind == 'lane_removed':
        return any(traffic.vehicles.get(l, 0) >= 1 for l in f.map_lanes)
    if f.kind == 'arm_removed':
        # a short arm (a neighbouring junction 17 m on, the end of a clip) gives its vehicles
        # fewer than ``min_points`` positions on its lanes: any vehicle seen on them counts
        return any(traffic.touched.get(l, 0) >= 1 for l in f.map_lanes)
    if f.kind == 'arm_added':
        return _off_map(traffic, math.radians(f.evidence['angle_deg']), None, gate) == 0
    if f.kind == 'connector_added':
        return tuple(f.map_lanes) not in traffic.turns
    if f.kind == 'connector_unused':
        c = next((c for c in mapped.connectors if c.id == f.map_lanes[0]), None)
        return c is not None and (c.lane_in, c.lane_out) in traffic.turns
    return False


def tracks_of(dets, skip_labels=SKIP_LABELS) -> list:
    """``[(xy, t), ...]`` per track id (time-sorted) of a ``Detections`` window, without the
    road users that do not drive lanes (``skip_labels``: cyclists ride beside the kerb lane,
    pedestrians walk along it -- they would "drive" a mapped lane beyond it); ``[]`` when the
    window has no identities (raw radar): then nothing can be corroborated."""
    return [(xy, t) for _, xy, t in track_rows(dets, skip_labels)]


def drive_traffic(window, mapped, cfg) -> TrafficOnMap | None:
    """The vehicles of a drive's observation ``window`` (``Detections``) map-matched to
    ``mapped`` with ``cfg`` (a ``ChangeConfig``); None when ``cfg.corroborate`` is off or the
    window has no tracks (then the estimate alone speaks)."""
    if not cfg.corroborate:
        return None
    tracks = tracks_of(window)
    return (match_traffic(tracks, mapped, cfg.match_gate_m, int(cfg.match_min_points), cfg.turn_follow)
            if tracks else None)
