"""Anytime lane-course estimator (paper §III) with the API of the topology step.

``initialise`` = preprocessing and initialisation (paper §III-A, ``lanes/init.py``,
``lanes/stops.py``): split and assign trajectories, re-fit the straight lanes, complete
one-sided trajectories, fit the stop lines, build the lanelet graph with shared border
points (``lanes/model.py``) and evidenced connectors. ``run`` = the paper's MCMC
(``lanes/mcmc.py``) plus the optional least-squares refinement (``lanes/refine.py``).
"""

from __future__ import annotations

import time

import numpy as np
from scipy.spatial import cKDTree

from ..model import ENTERING, LEAVING, Intersection, Lanelet, topology_key
from ..observations import Detections
from .config import LaneConfig
from .init import (add_connectors, arm_frames, assign_parts, chord_arms, connector_id, fit_frames,
                   lane_id, lane_specs, stop_distances, trajectories)
from .likelihood import all_terms, assign_points, station_csr
from . import mcmc as M
from .mcmc import run_chain
from .model import LaneGraph, build_graph
from .prior import all_angles, angle_csr, log_prior
from .refine import effective_share, refine_offsets, signed_offsets
from .spline import aic_prefers
from .halts import halt_positions, halt_stops
from .stops import complete_partial, fit_stops

__all__ = ['LaneCourseEstimator', 'lanelets_from_topology']


def lanelets_from_topology(topology: Intersection, length: float = 60.0,
                           config: LaneConfig | None = None) -> list[Lanelet]:
    """Straight entering/leaving lanelets of a topology (raw-detection mode, no tracks)."""
    cfg = (config or LaneConfig()).validate()
    specs, pairs, _ = lane_specs(topology, [], cfg, length=length, connectors=False)
    return build_graph(specs, pairs).lanelets() if specs else []


def _topology_key(t: Intersection):
    """The topology at the warm start's resolution (0.25 m, 0.5 deg)."""
    return topology_key(t, 0.25, 0.5, gap_m=0.25, width_m=0.25)


def _carry_shape(graph: LaneGraph, lane: int, P0: np.ndarray) -> None:
    """The connector's shape in ``P0`` (its start) carried to its current ends: each border's
    inner points move by the blend of its two ends' moves, linear in the station index."""
    o, m = graph.st_off[lane], graph.st_n[lane]
    f = np.linspace(0.0, 1.0, m)[1:-1, None]
    for side in (0, 1):
        refs = graph.ref[2 * np.arange(o, o + m) + side]
        d0, d1 = graph.P[refs[0]] - P0[refs[0]], graph.P[refs[-1]] - P0[refs[-1]]
        graph.P[refs[1:-1]] = P0[refs[1:-1]] + (1 - f) * d0 + f * d1


def _respace(graph: LaneGraph, lane: int) -> None:
    """Equidistant stations along a connector's current center line (ends stay put)."""
    o, n = graph.st_off[lane], graph.st_n[lane]
    g = np.arange(o, o + n)
    L, R = graph.P[graph.ref[2 * g]], graph.P[graph.ref[2 * g + 1]]
    c = 0.5 * (L + R)
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(c, axis=0), axis=1))])
    if s[-1] < 1e-6:
        return
    nrm = graph.st_normal[g]
    wl, wr = ((L - c) * nrm).sum(1), ((c - R) * nrm).sum(1)
    snew = np.linspace(0.0, s[-1], n)
    cn = np.stack([np.interp(snew, s, c[:, 0]), np.interp(snew, s, c[:, 1])], axis=1)
    t = np.gradient(cn, axis=0)
    t /= np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-12)
    nn = np.stack([-t[:, 1], t[:, 0]], axis=1)
    wl, wr = np.interp(snew, s, wl), np.interp(snew, s, wr)
    sp = graph.specs[lane]
    nn[0] = graph.st_normal[graph.st_off[sp.predecessor] + graph.st_n[sp.predecessor] - 1]
    nn[-1] = graph.st_normal[graph.st_off[sp.successor]]
    graph.st_normal[g] = nn
    for i in range(1, n - 1):
        pl, pr = graph.ref[2 * (o + i)], graph.ref[2 * (o + i) + 1]
        graph.P[pl] = cn[i] + wl[i] * nn[i]
        graph.P[pr] = cn[i] - wr[i] * nn[i]
        graph.axis[pl] = graph.axis[pr] = nn[i]
        graph.P[graph.home[2 * (o + i)]] = graph.P[pl]
        graph.P[graph.home[2 * (o + i) + 1]] = graph.P[pr]


def _connector_pairs(graph: LaneGraph, radius: float) -> list[tuple[int, int]]:
    """Right border slot of a connector next to a left border slot of another one."""
    conn = [i for i, s in enumerate(graph.specs) if s.kind == 'connector']
    if len(conn) < 2 or radius <= 0:
        return []
    g = np.concatenate([np.arange(graph.st_off[c] + 1, graph.st_off[c] + graph.st_n[c] - 1)
                        for c in conn])
    if not len(g):
        return []
    R, L = graph.P[graph.ref[2 * g + 1]], graph.P[graph.ref[2 * g]]
    D = cKDTree(R).sparse_distance_matrix(cKDTree(L), radius, output_type='ndarray')
    if not len(D):
        return []
    x, y, dist = D['i'], D['j'], D['v']
    ga, gb = g[x], g[y]
    ok = (graph.st_ll[ga] != graph.st_ll[gb]) & \
        ((graph.st_normal[ga] * graph.st_normal[gb]).sum(1) > 0.9)
    order = np.argsort(dist[ok], kind='stable')
    cand = zip(2 * ga[ok][order] + 1, 2 * gb[ok][order])
    used, out = set(), []
    for sa, sb in cand:
        if sa not in used and sb not in used:
            used.update((sa, sb))
            out.append((int(sa), int(sb)))
    return out


class LaneCourseEstimator:
    """Lane course by MCMC over a lanelet graph (paper §III), anytime and warm-startable.

    ``initialise(topology, dets)`` builds the lanelets from the topology and the
    trajectories (rows with ``track_id >= 0``); it keeps the chain when neither the
    topology nor the set of evidenced connectors changed. ``run`` draws samples.
    """

    def __init__(self, config: LaneConfig | None = None, seed=0):
        self.config = (config or LaneConfig()).validate()
        self.rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
        self.samples_drawn = 0
        self.graph: LaneGraph | None = None
        self._key = None
        self._k = 0
        self._start = None                # the centers the current chain's course started from
        self.timings: dict = {}
        self.last_chain = (0, 0.0, 0.0)   # (accepted, dlogP of final state, of best state)
        self._pending = None              # a prepared half of an initialisation (prepare)
        self.halves: dict = {}            # [s] the last prepare / finish (timings: their sum)

    # ------------------------------------------------------------------ setup
    def initialise(self, topology: Intersection, dets: Detections | None) -> None:
        """Lanelets from ``topology`` and the trajectories in ``dets`` (paper §III-A).

        Keeps the chain (warm start) when the topology and the set of lanelets are
        unchanged and the new initial course lies within ``warm_tolerance`` of the
        current one; then only the trajectory points are re-assigned. Otherwise the
        new observations moved the initialisation (stop lines, lane fits) and the
        lanelets are rebuilt from it. The two halves, :meth:`prepare` and :meth:`finish`,
        may also run apart (the online pipeline does when one tick has no room for both)."""
        self.prepare(topology, dets)
        self.finish()

    @property
    def pending(self) -> bool:
        """Has :meth:`prepare` run without its :meth:`finish`?"""
        return self._pending is not None

    def prepare(self, topology: Intersection, dets: Detections | None) -> None:
        """First half of :meth:`initialise`: the trajectories split and assigned, the arm
        frames and stop lines fitted, the entering / leaving lanelets shaped by their
        traffic. The current lanelets and chain stand until :meth:`finish`."""
        t0 = time.perf_counter()
        given, topology = topology, chord_arms(topology)
        trajs, frames, stops, halts = self._preprocess(topology, dets)
        specs, pairs, index = lane_specs(topology, trajs, self.config, connectors=False,
                                         stops=stops, frames=frames, halts=halts)
        self._pending = (given, topology, trajs, stops, specs, pairs, index)
        self.halves['prepare'] = time.perf_counter() - t0

    def finish(self) -> Intersection:
        """Second half of :meth:`initialise`: the connectors between the prepared lanes
        (fitted to their traffic), then the lane graph -- or the chain kept (warm start).
        Returns the topology :meth:`prepare` was given (the course is now built on it)."""
        t0 = time.perf_counter()
        given, topology, self._trajs, self.stops, specs, pairs, index = self._pending
        self._pending = None
        add_connectors(specs, index, self._trajs, self.config)
        key = (_topology_key(topology), tuple(s.id for s in specs))
        centers = np.concatenate([0.5 * (s.left + s.right) for s in specs]) if specs else None
        if self.graph is not None and key == self._key and self._close_to(specs, centers):
            self._setup_likelihood()
        else:
            self._key, self._k, self._start = key, 0, centers
            self.graph = build_graph(specs, pairs) if specs else None
            if self.graph is not None:
                self._setup_graph()
        self.halves['finish'] = time.perf_counter() - t0
        self.timings['initialise'] = self.halves['prepare'] + self.halves['finish']
        return given

    def _close_to(self, specs, centers) -> bool:
        """Does the new initial course (``specs``, their ``centers``) lie within
        ``warm_tolerance`` of the chain's current course, or with ``warm_from_start`` of the
        start it was built from (before the start's refinement and the samples moved it)?"""
        g = self.graph
        if len(specs) != len(g.specs) or any(len(s.left) != n for s, n in zip(specs, g.st_n)):
            return False
        ref = self._start if self.config.warm_from_start else g.centers()
        return float(np.max(np.linalg.norm(centers - ref, axis=1))) <= self.config.warm_tolerance

    def _preprocess(self, topology: Intersection, dets: Detections | None):
        """Trajectories split and assigned, arm frames re-fitted, stop lines fitted; the
        halted vehicles (``lanes/halts.py``; None when both halt steps are off)."""
        cfg = self.config
        trajs = trajectories(dets, cfg.skip_labels)
        stops = stop_distances(topology, cfg)
        frames = arm_frames(topology)
        halts = halt_positions(dets, cfg.skip_labels, cfg.halt_speed, cfg.halt_min_s) \
            if cfg.halt_stops or cfg.halt_follow else None
        if cfg.halt_stops:
            stops = halt_stops(frames, stops, halts, cfg.halt_pair_m, cfg.stop_min,
                               cfg.halt_max_move)
        assign_parts(trajs, topology, cfg, stops)
        for _ in range(cfg.refit_lanes):
            frames = fit_frames(topology, trajs, stops, cfg)
            assign_parts(trajs, topology, cfg, stops, frames)
        if cfg.complete_partial:
            complete_partial(topology, frames, trajs, stops, cfg.complete_min_points,
                             cfg.complete_max_cost, cfg.complete_min_ratio, cfg.stop_clip)
        if cfg.stop_fit:
            stops = fit_stops(topology, frames, trajs, stops, cfg.stop_search, cfg.stop_step,
                              float(stops.max(initial=0.0)) + 20.0, cfg.stop_clip,
                              cfg.stop_sweeps)
        return trajs, frames, stops, halts

    def _setup_graph(self) -> None:
        """Optional LS refinement of the start, prior means, neighbour pairs, caches."""
        g, cfg = self.graph, self.config
        self._start_shape()
        if cfg.refine_init:
            self._setup_likelihood()
            if len(self._Q):
                self._refine_start()
                self._start_shape()
        extra = _connector_pairs(g, cfg.merge_radius)
        if extra:
            g.pair_a = np.concatenate([g.pair_a, [a for a, _ in extra]]).astype(np.int64)
            g.pair_b = np.concatenate([g.pair_b, [b for _, b in extra]]).astype(np.int64)
            g.pair_merged = np.concatenate([g.pair_merged, np.zeros(len(extra), np.bool_)])
        self._setup_likelihood()

    def _refine_start(self) -> None:
        """The start refined by penalised least squares (``refine_init``, beyond the paper).
        With ``refine_select``, a connector keeps its refined shape only where it explains its
        points better than the start by more than ``refine_select`` per effective parameter of
        the refinement on them (:func:`.refine.lanelet_dof`), in Akaike's form with the points
        that count as independent (:func:`.refine.effective_share`); elsewhere the start's
        shape is carried to the refined ends. A start whose residuals count fewer independent
        points than ``refine_min_share`` of them (a tracker's smoothed error: the refinement
        would read each track's bias as the lane's course) stays as it is."""
        g, cfg = self.graph, self.config
        conns = [i for i, s in enumerate(g.specs) if s.kind == 'connector']
        r0, l0 = self._residuals()
        share = effective_share(r0, l0)
        if share < cfg.refine_min_share:
            return
        P0 = g.P.copy() if cfg.refine_select else None      # the start, for _carry_shape
        dof = self._refine(assign=True, dof_of=conns if cfg.refine_select else ())
        if cfg.refine_select:
            r1, l1 = self._residuals()
            n = len(g.specs)
            rss0, rss1 = np.bincount(l0, r0 * r0, n), np.bincount(l1, r1 * r1, n)
            m = np.maximum(np.bincount(l0, minlength=n), np.bincount(l1, minlength=n))
            for i in conns:
                if not aic_prefers(share * m[i], rss0[i], rss1[i], dof[i], cfg.refine_select):
                    _carry_shape(g, i, P0)
        for i in conns:
            _respace(g, i)

    def _residuals(self):
        """Signed distance of every assigned point to the current center line (clipped at
        ``refine_huber``, in the points' order) and its lanelet. The assignment is the
        current one: ``_setup_likelihood`` made it before the refinement, which makes it
        again after each of its steps."""
        k, _, _, r = signed_offsets(self.graph.centers(), self._Q, self._lo, self._hi)
        h = self.config.refine_huber
        return np.clip(r, -h, h), self.graph.st_ll[k]

    def _start_shape(self) -> None:
        """The start's width per station (the refinement's reference), the prior's mean angle
        change per lanelet (paper §III-B) and the start's second differences
        (``refine_keep_shape``), all read from the current course."""
        g = self.graph
        self._width0 = ((g.P[g.ref[0::2]] - g.P[g.ref[1::2]]) * g.st_normal).sum(1)
        C = g.centers()
        ang, self._mu = np.zeros(len(C)), np.zeros(len(g.specs))
        all_angles(C, g.prev_st, g.next_st, g.st_ll, ang, self._mu)
        self._d2_0 = np.zeros_like(C)
        h = np.flatnonzero((g.prev_st >= 0) & (g.next_st >= 0))
        self._d2_0[h] = C[g.prev_st[h]] - 2 * C[h] + C[g.next_st[h]]

    def _sequences(self):
        """(points, lanelet indices) per trajectory: its entering, connector, leaving lanelet."""
        index = {s.id: i for i, s in enumerate(self.graph.specs)}
        seqs = []
        for tr in self._trajs:
            e = index.get(lane_id(tr.lane_in[0], ENTERING, tr.lane_in[1])) if tr.lane_in else None
            o = index.get(lane_id(tr.lane_out[0], LEAVING, tr.lane_out[1])) if tr.lane_out else None
            c = index.get(connector_id(*tr.lane_in, *tr.lane_out)) if e is not None and \
                o is not None else None
            lanes = [i for i in (e, c, o) if i is not None]
            if not lanes:
                continue
            pts = tr.xy if (e is not None and o is not None) else \
                (tr.xy[:tr.split + 1] if e is not None else tr.xy[tr.split:])
            seqs.append((pts, lanes))
        return seqs

    def _assign(self):
        g = self.graph
        self._Q, self._lo, self._hi, _ = assign_points(g.centers(), g.st_off, g.st_n,
                                                       self._seqs, self.config.point_gate,
                                                       self.config.window_segments)
        return self._Q, self._lo, self._hi

    def _setup_likelihood(self) -> None:
        g, cfg = self.graph, self.config
        self._seqs = self._sequences()
        self._assign()
        self._pdep = station_csr(g.n_stations(), self._lo, self._hi)
        self._adep = angle_csr(g.prev_st, g.next_st)
        self._recompute()

    def _recompute(self) -> float:
        """Reference evaluation of all cached terms; returns the log posterior."""
        g, cfg = self.graph, self.config
        self._C = g.centers()
        self._ang = np.zeros(g.n_stations())
        self._delta = np.zeros(len(g.specs))
        all_angles(self._C, g.prev_st, g.next_st, g.st_ll, self._ang, self._delta)
        self._term = np.zeros(len(self._Q))
        lik = all_terms(self._C, self._Q, self._lo, self._hi, self._inv2s2(), self._eps(),
                        self._term)
        self._lik = lik
        return lik + log_prior(self._delta, self._mu, 0.5 / cfg.sigma_delta ** 2, cfg.tau,
                               g.n_shared())

    def _inv2s2(self):
        return 0.5 / self.config.sigma_perp ** 2

    def _eps(self):
        return self.config.outlier_weight

    def log_posterior(self) -> float:
        """Log posterior (up to a constant) of the current state, recomputed from scratch."""
        return self._recompute() if self.graph is not None else 0.0

    def _refine(self, assign: bool = False, dof_of=()) -> dict:
        cfg = self.config
        return refine_offsets(self.graph, self._Q, self._lo, self._hi, self._width0,
                              sigma=cfg.sigma_perp, smooth=cfg.refine_smooth,
                              smooth_connector=cfg.refine_smooth_connector, jerk=cfg.refine_jerk,
                              width=cfg.refine_width, iters=cfg.refine_iters,
                              huber=cfg.refine_huber, assign=self._assign if assign else None,
                              d2_ref=self._d2_0 if cfg.refine_keep_shape else None,
                              dof_of=dof_of)

    # ------------------------------------------------------------------ sampling
    def _params(self) -> np.ndarray:
        """The parameter vector of :func:`.mcmc.run_chain`, filled by named slot."""
        c = self.config
        prm = np.zeros(M.NPRM)
        prm[M.PRM_INV2S2], prm[M.PRM_EPS] = self._inv2s2(), self._eps()
        prm[M.PRM_INV2SD2], prm[M.PRM_TAU] = 0.5 / c.sigma_delta ** 2, c.tau
        prm[M.PRM_WIDTH_MIN], prm[M.PRM_WIDTH_MAX] = c.width_min, c.width_max
        prm[M.PRM_STEP_CENTER], prm[M.PRM_STEP_BORDER] = c.step_center, c.step_border
        prm[M.PRM_SPLIT_MAX] = c.split_max
        prm[M.PRM_P_CENTER], prm[M.PRM_P_BORDER] = c.p_center, c.p_border
        prm[M.PRM_P_SWITCH] = c.p_split + c.p_merge
        prm[M.PRM_TEMP_START], prm[M.PRM_TEMP_END] = c.temp_start, c.temp_end
        prm[M.PRM_ANNEAL_SAMPLES] = float(c.anneal_samples)
        return prm

    def _chain(self, n: int) -> None:
        g = self.graph
        bP, bref, bm = g.P.copy(), g.ref.copy(), g.pair_merged.copy()
        acc, cur, best = run_chain(
            n, self._k, int(self.rng.integers(2 ** 31 - 1)), self._params(), g.P, g.axis, g.ref,
            g.home, g.users, g.nusers, g.st_normal, g.st_ll, g.pair_a, g.pair_b,
            g.pair_merged, g.prev_st, g.next_st, self._adep[0], self._adep[1], self._ang,
            self._delta, self._mu, self._C, self._Q, self._lo, self._hi, self._pdep[0], self._pdep[1],
            self._term, bP, bref, bm)
        self.last_chain = (int(acc), float(cur), float(best))
        if self.config.keep_best and best > cur:
            g.set_state((bP, bref, bm))
            self._recompute()
        self._k += n

    def run(self, n_samples: int | None = None, time_budget_s: float | None = None) -> int:
        """Draw ``n_samples`` (default 20000) or as many as fit into ``time_budget_s``."""
        if self.graph is None:
            return 0
        t0 = time.perf_counter()
        drawn = 0
        if time_budget_s is None:
            n = 20000 if n_samples is None else int(n_samples)
            if n > 0:
                self._chain(n)
            drawn = max(n, 0)
        else:
            chunk = 500
            while time.perf_counter() - t0 < time_budget_s and \
                    (n_samples is None or drawn < n_samples):
                n = chunk if n_samples is None else min(chunk, n_samples - drawn)
                self._chain(n)
                drawn += n
        self.timings['mcmc'] = time.perf_counter() - t0
        if self.config.refine and len(self._Q):
            t1 = time.perf_counter()
            self._refine()
            self._recompute()
            self.timings['refine'] = time.perf_counter() - t1
        self.samples_drawn += drawn
        return drawn

    def lane_support(self) -> dict:
        """Lanelet id -> trajectories assigned to it (entering / leaving part, or both
        for a connector): the traffic each lane rests on (beyond the paper)."""
        out: dict = {}
        for tr in getattr(self, '_trajs', []):
            ids = [lane_id(tr.lane_in[0], ENTERING, tr.lane_in[1]) if tr.lane_in else None,
                   lane_id(tr.lane_out[0], LEAVING, tr.lane_out[1]) if tr.lane_out else None]
            if tr.lane_in and tr.lane_out:
                ids.append(connector_id(*tr.lane_in, *tr.lane_out))
            for i in ids:
                if i is not None:
                    out[i] = out.get(i, 0) + 1
        return out

    @property
    def lanelets(self) -> list[Lanelet]:
        """The lane course; each lanelet with ``support`` (its trajectories) and
        ``confidence = 1 - exp(-support / 3)`` (the topology arms' rule)."""
        if self.graph is None:
            return []
        sup = self.lane_support()
        out = self.graph.lanelets()
        for ll in out:
            ll.support = int(sup.get(ll.id, 0))
            ll.confidence = float(1.0 - np.exp(-ll.support / 3.0))
        return out
