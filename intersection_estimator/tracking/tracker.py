"""A radar tracker: radar rows scan by scan -> tracks with position, heading and speed.

Per scan (one stamp), rows that survive the radar clutter filter go to the track whose
gate (:func:`.gating.gate_distance`: position and Doppler) they are nearest, inside one
gate; a track is updated with the mean of its rows (:func:`.kalman.update`, variance
``row_var`` / rows) and, with ``doppler_var`` > 0, their mean Doppler
(:func:`.kalman.update_radial`, variance ``doppler_var`` / rows). Rows
farther than ``spawn_gates`` from every track are clustered (single linkage within
``cluster_m``) and each cluster starts a track whose velocity is its Doppler along the line
of sight. Two tracks on one vehicle: the younger ends (:func:`.gating.duplicates`). A
track ends after ``max_miss`` scans without rows and is reported once it has ``min_rows``
updates (one row each), ``min_path_m`` between its first and last position and has moved
(``min_speed``); while it stands or creeps (below ``heading_speed``) its rows keep the
heading it last drove. A track that has lived ``standing_s`` without driving (a queue at
a red light, which creeps; a parked car) is reported too, headless and at speed 0 until it
drives: radar cannot tell which way a vehicle faces that never moved, and the topology
step reads such tracks as queues only (:mod:`..topology.standing`).

Online (:meth:`RadarTracker.feed`) a track's rows are filtered states, handed out when
the track is reported and then scan by scan; in a batch (:func:`track_radar`) every
reported track is smoothed (:func:`.kalman.rts`) once all scans are in. Deterministic: no
random draw.

Online, scans arrive in receive order, not stamp order: several radars on one vehicle
reach the node with different latencies (a corner radar's scan stamped before the front
radar's last one arrives after it). A filter can only go forward in time, so scans are held
``reorder_s`` of stamp time (:meth:`RadarTracker.feed`) and tracked in stamp order, scans
of one stamp as one; a scan not newer than the last one tracked is late: counted
(:attr:`RadarTracker.scans_late`) and left out.
"""

from __future__ import annotations

import bisect
import math

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from ..observations import Detections
from .config import TrackerConfig
from .gating import duplicates, gate_distance
from .kalman import predict, rts, transition, update, update_radial

__all__ = ['RADAR_TRACK_ID0', 'RadarTracker', 'track_radar', 'radar_rows_of', 'is_radar_track']

#: track ids of radar tracks start here (apart from a tracked-objects topic's ids)
RADAR_TRACK_ID0 = 1 << 40
#: online: at most this many stamps held for reordering (memory cap; the oldest go first)
MAX_HELD = 256


def radar_rows_of(dets: Detections) -> np.ndarray:
    """Mask of radar rows: no identity, a finite Doppler."""
    return (dets.track_id < 0) & np.isfinite(dets.doppler)


def is_radar_track(track_id: np.ndarray) -> np.ndarray:
    """Mask of rows this tracker made (ids from :data:`RADAR_TRACK_ID0`)."""
    return track_id >= RADAR_TRACK_ID0


def _line_of_sight(xy, sensor_xy, doppler):
    """Unit vectors sensor -> row, and the Doppler; a row without a sensor position (or
    Doppler) gets a zero line of sight and a NaN Doppler: no Doppler gate, no velocity
    from it."""
    los = xy - sensor_xy
    los /= np.maximum(np.linalg.norm(los, axis=1, keepdims=True), 1e-6)
    ok = np.isfinite(los).all(axis=1) & np.isfinite(doppler)
    return np.where(ok[:, None], los, 0.0), np.where(ok, doppler, np.nan)


class _Track:
    """One track: filter state, counters, and its updates (t, predicted and filtered
    state and covariance) since the last rows handed out."""

    __slots__ = ('x', 'P', 'hits', 'miss', 'id', 'hist', 'start', 'moved', 'heading', 'reported',
                 't0')

    def __init__(self, z, v, tid: int, t: float, cfg: TrackerConfig):
        self.x = np.array([z[0], z[1], v[0], v[1]])
        # position: the mean of a cluster of rows (~0.6 m); velocity: Doppler along the
        # line of sight only, the rest unknown within velocity_sigma0
        self.P = np.diag([0.36, 0.36, cfg.velocity_sigma0**2, cfg.velocity_sigma0**2])
        self.hits, self.miss, self.id = 1, 0, tid
        self.hist = [(t, self.x.copy(), self.P.copy(), self.x.copy(), self.P.copy())]
        self.start = self.x[:2].copy()
        self.moved = False
        self.heading = math.nan
        self.reported = False
        self.t0 = t                           # hist loses its first updates online

    def drives(self, cfg: TrackerConfig) -> bool:
        """Has the track driven: moved (``min_speed``) and ``min_path_m`` from its start?"""
        return (self.hits >= cfg.min_rows and self.moved
                and float(np.hypot(*(self.x[:2] - self.start))) >= cfg.min_path_m)

    def lived(self, cfg: TrackerConfig) -> bool:
        """Has the track lived ``standing_s`` (0: never) with ``min_rows`` updates?"""
        return (cfg.standing_s > 0 and self.hits >= cfg.min_rows
                and self.hist[-1][0] - self.t0 >= cfg.standing_s)

    def passes(self, cfg: TrackerConfig) -> bool:
        """Is the track reported (its rows handed out): has it driven, or lived
        ``standing_s`` without driving (a queue, which creeps; a parked car)?"""
        return self.drives(cfg) or self.lived(cfg)


class RadarTracker:
    """Radar rows in, tracked rows out (module docstring). ``keep_history`` keeps every
    update for :meth:`finish` (batch); online a track holds at most ``max_backlog`` updates
    before it is reported and none after."""

    def __init__(self, cfg: TrackerConfig | None = None, keep_history: bool = False):
        self.cfg = (cfg or TrackerConfig()).validate()
        self.keep_history = keep_history
        self.live: list[_Track] = []
        self.ended: list[_Track] = []
        self.t: float | None = None
        self._next_id = 0
        self.scans_late = 0
        self._held: dict[float, list[tuple]] = {}     # online: stamp -> its scans' rows, not yet tracked

    def step(self, t: float, xy: np.ndarray, doppler: np.ndarray, sensor_xy: np.ndarray) -> Detections:
        """One scan of filtered radar rows at stamp ``t``; returns the tracked rows handed
        out now (online). A scan not newer than the last is late (scans of one stamp are
        one scan): counted and ignored."""
        if self.t is not None and t <= self.t:
            self.scans_late += 1
            return Detections.empty()
        dt = 0.0 if self.t is None else t - self.t
        self.t = t
        cfg = self.cfg
        F, Q = transition(dt, cfg.accel_noise)
        for tr in self.live:
            tr.x, tr.P = predict(tr.x, tr.P, F, Q)
        los, doppler = _line_of_sight(xy, sensor_xy, doppler)
        owner, near = self._associate(xy, doppler, los)
        for i in np.unique(owner[owner >= 0]):
            sel = owner == i
            rows = (los[sel], doppler[sel]) if self.cfg.doppler_var > 0 else None
            self._update(self.live[i], xy[sel].mean(0), int(sel.sum()), t, rows)
        self._end_duplicates()
        for tr in self.live:
            tr.miss += 1
        self.ended += [tr for tr in self.live if tr.miss > cfg.max_miss]
        self.live = [tr for tr in self.live if tr.miss <= cfg.max_miss]
        self._spawn(np.flatnonzero((owner < 0) & ~near), xy, doppler, los, t)
        if not self.keep_history:
            self.ended = []
            return self._hand_out()
        return Detections.empty()

    def feed(self, dets: Detections, keep: np.ndarray | None = None) -> Detections:
        """The radar rows of ``dets`` (those ``keep`` keeps, a mask; default all) as scans,
        one per stamp; returns the rows handed out (online).

        Batch (``keep_history``): every scan at once, in stamp order. Online: the scans join
        the held ones and those ``reorder_s`` older than the newest stamp held are tracked,
        in stamp order (module docstring); :meth:`flush` tracks the rest."""
        m = radar_rows_of(dets) if keep is None else (keep & radar_rows_of(dets))
        d = dets.subset(m)
        d = d.subset(np.argsort(d.t, kind='stable'))
        ts, starts = np.unique(d.t, return_index=True)
        for t, a, b in zip(ts, starts, np.r_[starts[1:], len(d.t)]):
            # a scan behind the tracks sorts first and is counted late by step()
            self._held.setdefault(float(t), []).append((d.xy[a:b], d.doppler[a:b], d.sensor_xy[a:b]))
        held = sorted(self._held)
        if self.keep_history or not held:
            return self.flush()
        n = max(bisect.bisect_right(held, held[-1] - self.cfg.reorder_s), len(held) - MAX_HELD)
        return Detections.concat([self._step_held(t) for t in held[:n]])

    def flush(self) -> Detections:
        """Online: track every held scan now (end of the input); returns the rows handed out."""
        return Detections.concat([self._step_held(t) for t in sorted(self._held)])

    def _step_held(self, t: float) -> Detections:
        parts = self._held.pop(t)
        if len(parts) == 1:
            return self.step(t, *parts[0])
        return self.step(t, *(np.concatenate(c) for c in zip(*parts)))

    def finish(self) -> Detections:
        """Batch: every reported track of the scans so far, smoothed."""
        rows = []
        for tr in self.ended + self.live:
            if tr.passes(self.cfg):
                rows.append(self._rows(tr, smooth=True))
        return Detections.concat(rows)

    # -- internals ----------------------------------------------------------------------
    def _states(self) -> tuple[np.ndarray, np.ndarray]:
        """States (n, 4) and covariances (n, 4, 4) of the live tracks."""
        return np.array([tr.x for tr in self.live]), np.array([tr.P for tr in self.live])

    def _associate(self, xy, doppler, los):
        """Owner track of every row (-1: none) and rows near a track (they start none)."""
        n = len(xy)
        if not self.live or n == 0:
            return np.full(n, -1), np.zeros(n, bool)
        X, P = self._states()
        d = gate_distance(X, P, xy, self.cfg, doppler, los)
        best = np.argmin(d, axis=0)
        dmin = d[best, np.arange(n)]
        return np.where(dmin <= 1.0, best, -1), dmin <= self.cfg.spawn_gates

    def _update(self, tr: _Track, z, k: int, t: float, rows=None) -> None:
        """Position update with the rows' mean ``z`` of ``k`` rows; ``rows``: their lines
        of sight and Doppler for the Doppler update (None: off)."""
        xp, Pp = tr.x.copy(), tr.P.copy()
        tr.x, tr.P = update(tr.x, tr.P, z, self.cfg.row_var / k)
        if rows is not None:
            self._update_doppler(tr, *rows)
        tr.hits += 1
        tr.miss = -1
        tr.hist.append((t, xp, Pp, tr.x.copy(), tr.P.copy()))
        if not self.keep_history and not tr.reported and len(tr.hist) > self.cfg.max_backlog:
            del tr.hist[0]
        if float(np.hypot(tr.x[2], tr.x[3])) >= self.cfg.min_speed:
            tr.moved = True

    def _update_doppler(self, tr: _Track, los, doppler) -> None:
        """The rows' mean Doppler as a measurement of the velocity along their mean line of
        sight (:func:`.kalman.update_radial`): it pins a standing vehicle's velocity to zero,
        where positions alone let a track drift along a queue of vehicles."""
        ok = np.isfinite(doppler)
        if not ok.any():
            return
        u = los[ok].mean(0)
        if float(np.hypot(u[0], u[1])) < 1e-6:
            return
        tr.x, tr.P = update_radial(tr.x, tr.P, u, float(doppler[ok].mean()),
                                   self.cfg.doppler_var / int(ok.sum()))

    def _end_duplicates(self) -> None:
        if len(self.live) < 2:
            return
        X, P = self._states()
        gone = set(duplicates(X, P, np.array([tr.hits for tr in self.live]), self.cfg).tolist())
        if gone:
            self.ended += [tr for k, tr in enumerate(self.live) if k in gone]
            self.live = [tr for k, tr in enumerate(self.live) if k not in gone]

    def _spawn(self, free, xy, doppler, los, t: float) -> None:
        if not len(free):
            return
        n = len(free)
        pairs = cKDTree(xy[free]).query_pairs(self.cfg.cluster_m, output_type='ndarray')
        g = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
        k, lab = connected_components(g, directed=False)
        for j in range(k):
            rows = free[lab == j]
            v = np.nan_to_num(doppler[rows]).mean() * los[rows].mean(0)
            self.live.append(_Track(xy[rows].mean(0), v, self._next_id, t, self.cfg))
            self._next_id += 1

    def _hand_out(self) -> Detections:
        """Online: rows of tracks reported by now (their backlog first)."""
        out = []
        for tr in self.live:
            if tr.miss != 0:
                continue                      # no update this scan: nothing new
            if tr.reported or tr.passes(self.cfg):
                tr.reported = True
                out.append(self._rows(tr, smooth=False))
                tr.hist = tr.hist[-1:]
        return Detections.concat(out)

    def _rows(self, tr: _Track, smooth: bool) -> Detections:
        """The track's updates since it last handed out rows, as tracked rows (the first
        update handed out before is skipped online: its row went out then)."""
        skip = not smooth and tr.reported and len(tr.hist) > 1
        t = np.array([h[0] for h in tr.hist])
        xs = (rts(t, np.array([h[1] for h in tr.hist]), np.array([h[2] for h in tr.hist]),
                  np.array([h[3] for h in tr.hist]), np.array([h[4] for h in tr.hist]),
                  self.cfg.accel_noise) if smooth else np.array([h[3] for h in tr.hist]))
        if skip:
            t, xs = t[1:], xs[1:]
        if tr.drives(self.cfg) or math.isfinite(tr.heading):
            heading, speed = self._held_headings(tr, xs)
        else:                                 # stood since it started: no heading yet
            heading, speed = np.full(len(xs), math.nan), np.zeros(len(xs))
        return Detections.make(xs[:, :2], t, heading=heading, speed=speed,
                               track_id=RADAR_TRACK_ID0 + tr.id, label=0)

    def _held_headings(self, tr: _Track, xs: np.ndarray):
        """Heading of every row: its velocity's while it drives at ``heading_speed`` or
        faster, else the last one driven so (before the first: the first one); speed 0 below
        ``min_speed``. A velocity's direction is only as good as its speed is large: a
        braking vehicle's swung by up to 20 degrees at 1-3 m/s, more with the Doppler update,
        which pins the radial speed sooner than positions pin the rest (test_tracker)."""
        sp = np.hypot(xs[:, 2], xs[:, 3])
        h = np.arctan2(xs[:, 3], xs[:, 2])
        sure = sp >= max(self.cfg.heading_speed, self.cfg.min_speed)
        if not sure.any() and not math.isfinite(tr.heading):
            sure = sp >= self.cfg.min_speed           # it never drove faster: the best it has
        idx = np.maximum.accumulate(np.where(sure, np.arange(len(xs)), -1))
        if sure.any():
            fill = tr.heading if math.isfinite(tr.heading) else h[np.flatnonzero(sure)[0]]
            held = np.where(idx >= 0, h[np.maximum(idx, 0)], fill)
            tr.heading = float(held[-1])
        else:
            held = np.full(len(xs), tr.heading)
        return held, np.where(sp >= self.cfg.min_speed, sp, 0.0)


def track_radar(dets: Detections, cfg: TrackerConfig | None = None, clutter=None) -> Detections:
    """Batch: the radar rows of ``dets`` (those ``clutter`` keeps, a mask; default all)
    scan by scan through a :class:`RadarTracker`, reported tracks smoothed."""
    tracker = RadarTracker(cfg, keep_history=True)
    tracker.feed(dets, clutter)
    return tracker.finish()
