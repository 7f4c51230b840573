"""Anytime topology estimator (paper §II): orchestration of the steps in this package.

>>> est = TopologyEstimator(TopologyConfig(), seed=0)
>>> est.set_observations(dets)
>>> est.run(n_samples=5000)        # or est.run(time_budget_s=0.05)
>>> est.best                       # model.Intersection | None

One :meth:`TopologyEstimator.run` advances every chain (``chains``, or ``chains_tracked``
when the data hold trajectories; each with its own RNG stream, all on one observation
set, the best reported) in chunks: the initialisation (:mod:`.init`), then annealed
Metropolis-Hastings (:mod:`.mcmc`), the first ``polish_samples`` with continuous moves
only, an arm refit (:mod:`.refit`) after the polish and every ``refit_every`` samples, and
the descent (:mod:`.descent`) when the schedule ends. The chains are kept across
:meth:`TopologyEstimator.set_observations` calls (warm start, slightly re-heated); the
observations are re-preprocessed (:mod:`.preprocess`) whenever the best center estimate
has moved more than ``recenter_threshold`` since the last preprocessing. The reported
estimate leaves out arms without support (:mod:`.support`).
"""

from __future__ import annotations

from dataclasses import replace
import math
import time

import numpy as np

from ..model import Intersection
from ..observations import Detections
from ..tracking.tracker import is_radar_track
from .config import Tables, TopologyConfig
from .descent import descend
from .init import initial_state
from .likelihood import ObservationSet
from .mcmc import Posterior, acceptance_rates, new_work, temperatures
from .moves import MOVE_NAMES
from .preprocess import preprocess, radar_rows
from .refit import refit_chain
from .side_by_side import tracks_of
from .state import (BEND, CX, CY, GAP, HDR, MAXA, OFF, P_GAP_MAX, P_OFF_MAX, STRIDE, Chain,
                    arm_angles, pack_state, unpack_state)
from .support import reported

__all__ = ['TopologyEstimator']


def _as_rng(seed) -> np.random.Generator:
    if isinstance(seed, np.random.Generator):
        return seed
    return np.random.default_rng(seed)


class TopologyEstimator:
    """Anytime MAP estimate of the intersection topology (paper §II)."""

    def __init__(self, cfg: TopologyConfig | None = None, seed=0, audit: bool = False):
        self.cfg = (cfg or TopologyConfig()).validate()
        #: count the likelihood's lower bounds in :attr:`work` too (:mod:`.cost_model`;
        #: slower, the samples are the same)
        self.audit = bool(audit)
        self._rng = _as_rng(seed)
        #: the tables for windows with tracked objects (``gap_max_tracked``) and without
        #: them (no arm-axis offset when ``arm_offset_tracks_only``, :mod:`.arm_offset`)
        tracked, plain = self.cfg.for_tracks(), self.cfg.for_voxels()
        self._tables_all = Tables(tracked)
        self._tables_plain = self._tables_all if plain == tracked else Tables(plain)
        self.reset()

    # ------------------------------------------------------------------ public API
    def reset(self) -> None:
        """Forget observations and chains."""
        self._dets = Detections.empty()
        self._tracked = False                  # self._dets.has_tracks, read per chunk
        self._radar_tracks = False             # every track from the radar tracker
        self._radar = None                     # radar_rows(self._dets), made on first use
        self._tracks = None                    # side_by_side.tracks_of(self._dets), ditto
        #: likelihood work counters of the chains and of the descents
        #: (:data:`.mcmc.WORK_FIELDS`), since the reset; read by :mod:`.cost_model`
        self.work = {'chain': new_work(), 'descent': new_work()}
        self._post = self._posterior(ObservationSet.empty())
        self._pp_center = None                 # center of the last preprocessing
        self._chains: list[Chain] = []
        self._since_data = 0                   # samples since set_observations
        self._polish_left = 0                  # continuous-only samples left
        self._last_improve = 0                 # step of the last gain > converge_tol ...
        self._ref_best = -math.inf             # ... to this log posterior
        self._rep_key = self._rep = None       # cache of the reported estimate
        self.samples_drawn = 0
        self.preprocess_count = 0
        #: wall time [s] per phase since the reset, disjoint: ``preprocess`` (observation
        #: building, §II-A), ``rescore`` (chains re-scored on new observations), ``initialise``
        #: (data-driven start, §II-A, without its preprocessing), ``chain`` (the samples,
        #: Algorithm 1), ``refit`` (:mod:`.refit`), ``descent`` (:mod:`.descent`).
        #: Read by ``bench --profile``; timing only, no effect on the estimate.
        self.timings: dict[str, float] = dict.fromkeys(
            ('preprocess', 'rescore', 'initialise', 'chain', 'refit', 'descent'), 0.0)

    def set_observations(self, dets: Detections) -> None:
        """Replace the observation window; keep the chains (warm start, re-heated)."""
        self._dets = dets.finite()
        self._tracked = self._dets.has_tracks
        ids = self._dets.track_id[self._dets.track_id >= 0]
        self._radar_tracks = bool(len(ids)) and bool(is_radar_track(ids).all())
        self._radar = None
        self._tracks = None
        self._since_data = 0
        if not self._chains:
            self._initialise()
            return
        if self._tables is not self._tables_all:
            self._drop_offsets()
        self._preprocess(self._best_chain().best_S[CX:CY + 1].copy())
        for c in self._chains:
            c.step = min(c.step, int(self.cfg.reheat_fraction * self.cfg.anneal_samples))

    def run(self, n_samples: int | None = None, time_budget_s: float | None = None) -> int:
        """Advance every chain by ``n_samples`` (or until the wall-time budget is used);
        returns the count drawn over all chains, including those of the descent at the end
        of the schedule."""
        if n_samples is None and time_budget_s is None:
            raise ValueError('run() needs n_samples or time_budget_s')
        if not self._chains and len(self._dets):
            self._initialise()
        if not self._chains or len(self._post.obs) == 0:
            return 0
        t0 = time.perf_counter()
        deadline = math.inf if time_budget_s is None else t0 + time_budget_s
        done = drawn = 0       # steps of each chain; samples drawn by all (and descents)
        chunk = self.cfg.chunk   # with a budget: ~250 samples of all chains between checks
        if time_budget_s is not None:
            chunk = max(1, min(chunk, 250) // len(self._chains))
        while True:
            m = chunk if n_samples is None else min(chunk, n_samples - done)
            if self._polish_left > 0:
                m = min(m, self._polish_left)
            if m <= 0:
                break
            drawn += self._advance(m, deadline)
            done += m
            if time_budget_s is not None and time.perf_counter() - t0 >= time_budget_s:
                break
        return drawn

    @property
    def best(self) -> Intersection | None:
        """Best (MAP) intersection so far, arms with lane width and confidence
        ``1 - exp(-passages / 3)`` (vehicle passages the arm explains best); arms that
        explain fewer than ``min_arm_support`` passages are left out (:mod:`.support`)."""
        if not self._chains:
            return None
        S, conf, _ = self._reported()
        return unpack_state(S, self.cfg.traffic_side, conf)

    @property
    def best_log_posterior(self) -> float:
        """log P(I|Z) + const of :attr:`best`."""
        return -math.inf if not self._chains else self._reported()[2]

    @property
    def state(self) -> str:
        """'NO_DATA', 'CONVERGING' or 'CONVERGED' (their message constants:
        ``msg_adapters.topology.STATES``)."""
        if not self._chains or len(self._post.obs) == 0:
            return 'NO_DATA'
        c = self._best_chain()
        if (c.step >= self.cfg.anneal_samples
                and c.step - self._last_improve >= self.cfg.converge_window):
            return 'CONVERGED'
        return 'CONVERGING'

    @property
    def observations(self) -> ObservationSet:
        """The preprocessed observations currently scored."""
        return self._post.obs

    @property
    def acceptance(self) -> dict:
        """Per move kind over all chains: (proposed, accepted)."""
        if not self._chains:
            return {}
        return acceptance_rates(sum(c.stats for c in self._chains))

    @property
    def n_chains(self) -> int:
        return len(self._chains)

    @property
    def chain_summaries(self) -> list[dict]:
        """Per chain: its best (MAP) state ``best`` (all arms), ``log_posterior`` and
        ``acceptance`` (per move kind: proposed, accepted)."""
        return [{'best': unpack_state(c.best_S, self.cfg.traffic_side),
                 'log_posterior': c.best_lpost, 'acceptance': acceptance_rates(c.stats)}
                for c in self._chains]

    def log_posterior(self, inter: Intersection) -> float:
        """log P(I|Z) + const of any intersection under the current observations."""
        return self._post(pack_state(inter))

    # ------------------------------------------------------------------ internals
    def _best_chain(self) -> Chain:
        """The chain with the best state so far (the first on ties)."""
        return max(self._chains, key=lambda c: c.best_lpost)

    def _timed(self, phase: str, t0: float) -> float:
        """Add the time since ``t0`` to ``timings[phase]``; returns now."""
        now = time.perf_counter()
        self.timings[phase] += now - t0
        return now

    def _initialise(self) -> None:
        t0 = time.perf_counter()
        inner = self.timings['preprocess'] + self.timings['rescore'] + self.timings['refit']
        self._initialise_chains()
        spent = time.perf_counter() - t0
        inner = self.timings['preprocess'] + self.timings['rescore'] + self.timings['refit'] - inner
        self.timings['initialise'] += spent - inner

    def _initialise_chains(self) -> None:
        cfg = self.cfg
        init = initial_state(self._dets, cfg, self._pcfg, self._preprocessed)
        if init is None:
            return
        S, obs, obs_center = init
        n = cfg.chains_tracked if self._tracked else cfg.chains
        self._chains = [Chain.start(S, 0, len(MOVE_NAMES)) for _ in range(n)]
        self._polish_left = cfg.polish_samples
        near = np.hypot(*(S[CX:CY + 1] - obs_center)) <= cfg.recenter_threshold
        self._preprocess(S[CX:CY + 1].copy(), obs if near else None, obs_center)
        if cfg.polish_samples == 0:
            t = time.perf_counter()
            for c in self._chains:
                refit_chain(self._post, c, cfg.refit_sweeps)
            self._timed('refit', t)

    def _preprocess(self, center, obs=None, obs_center=None) -> None:
        """(Re-)preprocess around ``center`` (or adopt ``obs`` made around ``obs_center``)
        and re-score every chain and its best state on the new observations."""
        if obs is None:
            obs = self._preprocessed(center, arm_angles(self._best_chain().best_S))
            obs_center = center
        t = time.perf_counter()
        self._post = self._posterior(obs)
        self._pp_center = np.asarray(obs_center, float).copy()
        self.preprocess_count += 1
        for c in self._chains:
            c.best_lpost = self._post(c.best_S)
            self._post.rescore(c)
        best = self._best_chain()
        self._ref_best = best.best_lpost
        self._last_improve = best.step
        self._timed('rescore', t)

    def _posterior(self, obs: ObservationSet) -> Posterior:
        """The posterior on ``obs``, counting its chains' work in ``work['chain']``."""
        return Posterior(self._tables, obs, self.work['chain'], self.audit)

    def _drop_offsets(self) -> None:
        """Arms through the center again and gaps within ``gap_max`` (the window lost its
        tracked objects: the model is that of :meth:`.TopologyConfig.for_voxels`)."""
        gmax = self._tables_plain.P[P_GAP_MAX]
        straight = not self._tables_plain.P[P_OFF_MAX] > 0.0
        for c in self._chains:
            for S in (c.S, c.best_S):
                if straight:
                    S[HDR + OFF:HDR + MAXA * STRIDE:STRIDE] = 0.0
                    S[HDR + BEND:HDR + MAXA * STRIDE:STRIDE] = 0.0
                g = S[HDR + GAP:HDR + MAXA * STRIDE:STRIDE]
                np.minimum(g, gmax, out=g)

    @property
    def _pcfg(self):
        """The preprocessing parameters of this window (:attr:`_window_cfg`)."""
        return self._window_cfg.preprocess_config()

    @property
    def _tables(self) -> Tables:
        """The kernel tables for the current window: with the arm-axis offset only when
        the window has tracked objects or the offset is not limited to them."""
        return self._tables_all if self._tracked else self._tables_plain

    def _preprocessed(self, center, angles) -> ObservationSet:
        t = time.perf_counter()
        if self._radar is None:
            self._radar = radar_rows(self._dets, self._pcfg)
        obs = preprocess(self._dets, center, self._pcfg, angles, self._radar)
        self._timed('preprocess', t)
        return obs

    def _window_tracks(self):
        """The window's trajectories for :mod:`.weak_arms` and :mod:`.side_by_side` (None:
        no tracked objects or both steps off), grouped once per window."""
        cfg = self.cfg
        if not (self._tracked and (cfg.side_by_side_overlap > 0 or cfg.weak_arm_nats > 0)):
            return None
        if self._tracks is None:
            self._tracks = tracks_of(self._dets, cfg.weak_labels, cfg.min_track_speed,
                                     (cfg.standing_min_s, cfg.side_by_side_queues)
                                     if cfg.side_by_side_queues else None)
        return self._tracks

    def _advance(self, m: int, deadline: float) -> int:
        """``m`` samples of every chain (+ refits, + the descent when the schedule ends),
        the chains in lockstep; returns samples drawn."""
        cfg, post = self.cfg, self._post
        temps = temperatures(self._chains[0].step, m, cfg.t_start, cfg.t_end, cfg.anneal_samples)
        P = self._tables.P_polish if self._polish_left > 0 else self._tables.P
        was_polishing = self._polish_left > 0
        self._polish_left = max(0, self._polish_left - m)
        drawn = 0
        for c in self._chains:
            t = time.perf_counter()
            post.advance(c, m, temps, int(self._rng.integers(0, 2 ** 31 - 1)), P)
            t = self._timed('chain', t)
            if was_polishing and self._polish_left == 0:
                refit_chain(post, c, cfg.refit_sweeps)
            elif cfg.refit_every and c.step // cfg.refit_every != (c.step - m) // cfg.refit_every:
                refit_chain(post, c, cfg.refit_sweeps)
            t = self._timed('refit', t)
            if c.step - m < cfg.anneal_samples <= c.step:
                drawn += self._descend(c, deadline)
                self._timed('descent', t)
            drawn += m
        self.samples_drawn += drawn
        self._since_data += m
        self._track_convergence()
        return drawn

    def _descend(self, c: Chain, deadline: float) -> int:
        """:func:`.descent.descend` from chain ``c``'s MAP state; ``c`` takes the result if
        it scores higher. Returns samples drawn."""
        post = self._post
        post.work = self.work['descent']
        try:
            res = descend(c.best_S, self._window_cfg, post, self._rng, deadline)
        finally:
            post.work = self.work['chain']
        if res.lpost > c.best_lpost:
            c.best_S[:] = res.S
            c.best_lpost = res.lpost
            c.S[:] = res.S
            c.ll, _ = self._post.loglik(c.S, c.C)
            c.lp = res.lpost - c.ll
        return res.samples

    @property
    def _window_cfg(self) -> TopologyConfig:
        """The settings of this window's preprocessing, descent and reported estimate. A
        window whose tracks all come from the radar tracker keeps trajectory parts from
        ``radar_tracks_min_part_length`` (a radar track starts some metres after its vehicle
        appears: on a road the net cuts 17 m out its parts beyond ``part_outside`` are 3-5 m
        long), adds arms for unexplained parts from ``radar_tracks_add_support`` passages (a
        radar track that breaks inside the box leaves parts no arm explains) and leaves no
        arm out by :func:`.support.drop_empty_arms` (its broken tracks drive real arms next
        to the box too seldom to tell them from junk ones). Each setting is read by one step
        only (``min_part_length`` by the preprocessing, ``descent_add_support`` by the
        descent, ``empty_arm_drop`` by the report)."""
        if not self._radar_tracks:
            return self.cfg
        return replace(self.cfg, min_part_length=self.cfg.radar_tracks_min_part_length,
                       descent_add_support=self.cfg.radar_tracks_add_support,
                       empty_arm_drop=False)

    def _track_convergence(self) -> None:
        """Note a gain of more than ``converge_tol``; re-preprocess when the best center
        moved more than ``recenter_threshold`` soon after new data."""
        cfg, c = self.cfg, self._best_chain()
        if c.best_lpost > self._ref_best + cfg.converge_tol:
            self._ref_best = c.best_lpost
            self._last_improve = c.step
        center = c.best_S[CX:CY + 1]
        if (self._since_data <= cfg.recenter_window
                and np.hypot(*(center - self._pp_center)) > cfg.recenter_threshold):
            self._preprocess(center.copy())

    def _reported(self):
        """(state, confidence per arm, log posterior) of the reported estimate (cached)."""
        c = self._best_chain()
        key = (c.best_S.tobytes(), self.preprocess_count)
        if self._rep_key != key:
            self._rep = reported(self._post, c.best_S, c.best_lpost, self._window_cfg,
                                 self._window_tracks())
            self._rep_key = key
        return self._rep
