"""Anytime topology estimator (paper §II): preprocessing -> annealed MCMC -> MAP intersection.

>>> est = TopologyEstimator(TopologyConfig(), seed=0)
>>> est.set_observations(dets)
>>> est.run(n_samples=5000)        # or est.run(time_budget_s=0.05)
>>> est.best                       # model.Intersection | None

The chains (``chains``, or ``chains_tracked`` when the data hold trajectories; each with
its own RNG stream, all on one observation set, the best reported) are kept across
:meth:`TopologyEstimator.set_observations` calls (warm start, slightly re-heated); the
observations are re-preprocessed whenever the best center estimate has moved more than
``recenter_threshold`` since the last preprocessing.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields
import math
import time

import numpy as np

from . import _kernels as K
from .anneal import Chain, acceptance_rates, advance, temperatures
from .likelihood import ObservationSet
from .model import Arm, Intersection
from .moves import pack_state, unpack_state
from .observations import Detections
from .preprocess import (PreprocessConfig, initial_arm_angles, initial_center, initial_lanes,
                         preprocess, radar_rows, seed_lines)
from .prior import ARM_COUNT_PRIOR, LANE_COUNT_PRIOR, arm_log_const, count_log_table

__all__ = ['TopologyConfig', 'TopologyEstimator', 'warmup']

STATES = ('NO_DATA', 'CONVERGING', 'CONVERGED')


@dataclass(frozen=True)
class TopologyConfig:
    """All parameters of the topology step; defaults follow the paper where it gives one."""

    # --- move probabilities (Algorithm 1); normalised to sum 1 --------------------------
    p_rotate: float = 0.40
    p_shift: float = 0.20
    p_gap: float = 0.10
    p_arm: float = 0.15
    p_lane: float = 0.15
    p_width: float = 0.10                # beyond the paper: lane width move
    # --- move ranges (Algorithm 1) ------------------------------------------------------
    rotate_max_deg: float = 6.0
    shift_max: float = 6.0               # [m]
    gap_step: float = 1.8                # [m]
    width_step: float = 0.25             # [m]
    fine_step_prob: float = 0.5          # continuous moves use fine_step_scale x range
    fine_step_scale: float = 0.1         # ... with this probability (beyond the paper)
    split_span_deg: float = 60.0         # add arm next to an arm: offset U[min_sep, +span]
    # --- model bounds ---------------------------------------------------------------
    min_sep_deg: float = 30.0            # min angle between arms (benchmark generator: 45)
    min_arms: int = 2
    max_arms: int = 6
    min_lanes: int = 1                   # per driving direction (no one-way roads)
    max_lanes: int = 6
    gap_max: float = 4.0                 # [m]
    lane_width: float = 3.5              # [m] default / fixed lane width
    lane_width_min: float = 2.75
    lane_width_max: float = 4.0
    traffic_side: int = 1                # +1 right-hand traffic, -1 left-hand
    # --- prior (prior.py documents how these were chosen) -------------------------------
    arm_count_prior: tuple = ARM_COUNT_PRIOR
    lane_count_prior: tuple = LANE_COUNT_PRIOR
    # --- likelihood -----------------------------------------------------------------
    sigma_track: float = 0.5             # [m] sigma_perp of a trajectory part's mean point
    sigma_point: float = 1.2             # [m] sigma_perp of a detection (raw / heading voxel)
    sigma_angle_deg: float = 5.0         # heading of a trajectory part / detection
    pca_radius: float = 8.0              # [m] initial center: local PCA of radar voxels
    min_arm_support: float = 2.5         # reported arms explain >= this many vehicle passages
    clutter_floor: float = 0.01          # uniform outlier level relative to the peak density
    cut_sigma2: float = 30.0             # densities below exp(-cut) are 0 (speed)
    lane_sum: bool = False               # sum over lanes (paper eq.) instead of the closest
    lane_norm: float = 0.5               # density / (lanes of that arm and direction)**this
    # --- preprocessing (paper §II-A) ------------------------------------------------
    voxel_size: float = 3.0              # [m] square voxels (heading rows; radar before arms)
    voxel_length: float = 10.0           # [m] radar voxels aligned with the nearest arm
    voxel_width: float = 1.0             # [m]
    straight_run: bool = True            # drop radar voxels off straight lane runs
    voxel_merge: int = 3                 # ... then merge this many along-arm voxels (radar;
                                         # raw 1000 cases: 2 -> 84.8 % 81 ms, 3 -> 84.9 % 71 ms)
    heading_voxel_merge: int = 2         # ... lidar / camera rows (300 cases: 3 -> 81.7 %)
    heading_sectors: int = 8
    passage_gap: float = 1.0             # [s] voxel weight counts vehicle passages, not hits
    weight_power: float = 1.0
    weight_scale: float = 0.3
    min_doppler: float = 0.5             # [m/s]
    min_rcs: float = 0.0                 # [dBsm]
    min_rcs_static: float = 5.0          # [dBsm] slow (crossing) radar rows kept above this
    keep_unknown_direction: bool = True  # radar rows of unknown direction kept (d = 0)
    min_radial_cos: float = 0.25
    min_part_points: int = 3
    min_part_length: float = 5.0         # [m]
    min_track_speed: float = 3.0         # [m/s] max speed below: static (false) track
    trim_turn_deg: float = 15.0          # straight run of a trajectory part (0: paper)
    min_center_dist: float = 20.0        # [m] observations closer to the center are dropped:
                                         # inside the box vehicles turn, and the model's lanes
                                         # (straight rays, §II-B) do not describe them. Lane-
                                         # level, 300 cases: raw 78 -> 89 % (seeds 3000+:
                                         # 71 -> 83 %), tracked 93 -> 97 %; 12/16/25/30 m: raw
                                         # 77/80/87/76 %
    arm_reach: float = 18.0              # [m] radar/heading rows farther from every arm's
                                         # axis keep square voxels (arm not found yet)
    recenter_threshold: float = 2.0      # [m] re-preprocess when the center moved more
    recenter_window: int = 2500          # ... checked during the first samples after new data
    # --- annealing ------------------------------------------------------------------
    t_start: float = 1.0
    t_end: float = 0.2                   # MAP search: cold end (0.5 left raw lane counts
                                         # 1-5 nats below the truth's posterior)
    anneal_samples: int = 5000
    chains: int = 1                      # independent chains (own RNG streams, one shared
                                         # observation set; every run() advances each; the
                                         # best is reported)
    chains_tracked: int = 2              # ... when the data hold trajectories: their sharp
                                         # posterior is multimodal and a chain can stick in a
                                         # wrong mode (tracked, 1000 cases: 1 chain 96.7 %,
                                         # 2: 98.5 %, 3: 99.0 %); raw detections prefer one
                                         # long schedule (2 x 2500 samples: 84.8 % vs 86.4 %)
    init_peak_frac: float = 0.12         # init: direction-histogram peaks above this share
    refit_every: int = 1000              # also refit every this many samples (0: never):
                                         # lane count / gap / width jump jointly to the best
                                         # grid point, which single moves rarely reach
    refit_sweeps: int = 1                # init: per-arm lane/gap/width coordinate ascent
    polish_samples: int = 1000           # first samples of a new chain: continuous moves only
    reheat_fraction: float = 0.3         # on new data: back to this share of the schedule
    descent_rounds: int = 2              # end of the schedule: greedy descent over lane-count
                                         # changes and arm removals, each followed by
    descent_samples: int = 250           # ... this many continuous moves at descent_temp
    descent_temp: float = 1e-3           # (0 rounds: off; beyond the paper, see _descend)
    descent_screen: float = 4.5          # lane candidates scoring this many nats below the
                                         # best state so far before their moves are dropped
    descent_prune: float = 3.0           # ... and a run once its best is this many nats x
                                         # (share of its moves left)^2 below it, checked
                                         # after 1/16, 1/8, 1/4, 3/8, 1/2, 3/4 of the moves
                                         # (raw, 300 cases, 72 improving candidates: none
                                         # lost, 72 % of the moves saved; 3.5 x (share left):
                                         # one lost, 42 % saved)
    descent_focus: float = 0.8           # share of a lane candidate's arm moves that go to
                                         # the arm whose lane counts changed
    descent_top: int = 0                 # ... and only the best this many lane candidates
                                         # (0: all) get the moves (raw, 1000 cases, before
                                         # the staged screen: all 84.9 %, 4: 82.9 %)
    chunk: int = 500                     # samples per compiled call (anytime granularity)
    converge_window: int = 2000
    converge_tol: float = 0.5

    def validate(self) -> 'TopologyConfig':
        """Raise ValueError naming the first parameter outside its allowed range."""
        def need(name, ok, rng):
            if not ok:
                raise ValueError(f'TopologyConfig.{name}={getattr(self, name)!r} outside {rng}')
        for n in ('p_rotate', 'p_shift', 'p_gap', 'p_arm', 'p_lane', 'p_width'):
            need(n, 0.0 <= getattr(self, n) <= 1.0, '[0, 1]')
        need('p_rotate', self.p_rotate + self.p_shift + self.p_gap + self.p_arm + self.p_lane
             + self.p_width > 0, 'sum of move probabilities > 0')
        need('rotate_max_deg', 0 < self.rotate_max_deg <= 180, '(0, 180]')
        need('shift_max', 0 < self.shift_max <= 100, '(0, 100] m')
        need('gap_step', 0 < self.gap_step <= 20, '(0, 20] m')
        need('width_step', 0 < self.width_step <= 2, '(0, 2] m')
        need('fine_step_prob', 0 <= self.fine_step_prob <= 1, '[0, 1]')
        need('fine_step_scale', 0 < self.fine_step_scale <= 1, '(0, 1]')
        need('split_span_deg', 0 <= self.split_span_deg <= 180, '[0, 180]')
        need('min_sep_deg', 1 <= self.min_sep_deg <= 120, '[1, 120]')
        need('min_arms', 1 <= self.min_arms <= K.MAXA, f'[1, {K.MAXA}]')
        need('max_arms', self.min_arms <= self.max_arms <= K.MAXA, f'[min_arms, {K.MAXA}]')
        need('max_arms', self.max_arms * self.min_sep_deg <= 360, 'max_arms*min_sep_deg <= 360')
        need('min_lanes', 1 <= self.min_lanes <= self.max_lanes, '[1, max_lanes]')
        need('max_lanes', self.max_lanes <= len(self.lane_count_prior) - 1,
             f'[min_lanes, {len(self.lane_count_prior) - 1}] (length of lane_count_prior - 1)')
        need('gap_max', 0 < self.gap_max <= 30, '(0, 30] m')
        need('lane_width_min', 1.0 <= self.lane_width_min < self.lane_width_max, '[1, lane_width_max)')
        need('lane_width_max', self.lane_width_max <= 6.0, '(lane_width_min, 6] m')
        need('lane_width', self.lane_width_min <= self.lane_width <= self.lane_width_max,
             '[lane_width_min, lane_width_max]')
        need('traffic_side', self.traffic_side in (1, -1), '{1, -1}')
        need('arm_count_prior', len(self.arm_count_prior) == K.MAXA + 1
             and min(self.arm_count_prior) >= 0
             and sum(self.arm_count_prior[self.min_arms:self.max_arms + 1]) > 0,
             f'{K.MAXA + 1} non-negative probabilities with mass on [min_arms, max_arms]')
        need('lane_count_prior', min(self.lane_count_prior) >= 0
             and sum(self.lane_count_prior[self.min_lanes:self.max_lanes + 1]) > 0,
             'non-negative probabilities with mass on [min_lanes, max_lanes]')
        need('sigma_track', 0.01 <= self.sigma_track <= 20, '[0.01, 20] m')
        need('sigma_point', 0.01 <= self.sigma_point <= 20, '[0.01, 20] m')
        need('sigma_angle_deg', 0.1 <= self.sigma_angle_deg <= 90, '[0.1, 90]')
        need('pca_radius', 1 <= self.pca_radius <= 50, '[1, 50] m')
        need('clutter_floor', 0 < self.clutter_floor < 1, '(0, 1)')
        need('min_arm_support', 0 <= self.min_arm_support, '[0, inf)')
        need('lane_norm', 0 <= self.lane_norm <= 2, '[0, 2]')
        need('cut_sigma2', 1 <= self.cut_sigma2 <= 700, '[1, 700]')
        need('voxel_size', 0.05 <= self.voxel_size <= 50, '[0.05, 50] m')
        need('voxel_length', 0 <= self.voxel_length <= 100, '[0, 100] m')
        need('voxel_width', 0.05 <= self.voxel_width <= 20, '[0.05, 20] m')
        need('voxel_merge', 1 <= self.voxel_merge <= 20, '[1, 20]')
        need('heading_voxel_merge', 1 <= self.heading_voxel_merge <= 20, '[1, 20]')
        need('heading_sectors', 1 <= self.heading_sectors <= 64, '[1, 64]')
        need('passage_gap', 0 <= self.passage_gap <= 60, '[0, 60] s')
        need('weight_power', 0 <= self.weight_power <= 2, '[0, 2]')
        need('weight_scale', 0 < self.weight_scale <= 100, '(0, 100]')
        need('min_doppler', 0 <= self.min_doppler <= 50, '[0, 50] m/s')
        need('min_radial_cos', 0 <= self.min_radial_cos < 1, '[0, 1)')
        need('min_part_points', 1 <= self.min_part_points <= 1000, '[1, 1000]')
        need('min_track_speed', 0 <= self.min_track_speed <= 50, '[0, 50] m/s')
        need('min_part_length', 0 <= self.min_part_length <= 100, '[0, 100] m')
        need('trim_turn_deg', 0 <= self.trim_turn_deg <= 90, '[0, 90]')
        need('min_center_dist', 0 <= self.min_center_dist <= 100, '[0, 100] m')
        need('arm_reach', 1 <= self.arm_reach <= 100, '[1, 100] m')
        need('recenter_threshold', 0 < self.recenter_threshold, '(0, inf) m')
        need('recenter_window', 0 <= self.recenter_window, '[0, inf)')
        need('t_start', 0 < self.t_start <= 1e4, '(0, 1e4]')
        need('t_end', 0 < self.t_end <= self.t_start, '(0, t_start]')
        need('anneal_samples', 1 <= self.anneal_samples, '[1, inf)')
        need('chains', 1 <= self.chains <= 16, '[1, 16]')
        need('chains_tracked', 1 <= self.chains_tracked <= 16, '[1, 16]')
        need('init_peak_frac', 0 < self.init_peak_frac <= 1, '(0, 1]')
        need('refit_sweeps', 0 <= self.refit_sweeps <= 10, '[0, 10]')
        need('polish_samples', 0 <= self.polish_samples, '[0, inf)')
        need('reheat_fraction', 0 <= self.reheat_fraction <= 1, '[0, 1]')
        need('descent_rounds', 0 <= self.descent_rounds <= 10, '[0, 10]')
        need('descent_samples', 1 <= self.descent_samples <= 10 ** 6, '[1, 1e6]')
        need('descent_temp', 0 < self.descent_temp <= 1, '(0, 1]')
        need('descent_screen', 0 <= self.descent_screen, '[0, inf)')
        need('descent_prune', 0 <= self.descent_prune, '[0, inf)')
        need('descent_focus', 0 <= self.descent_focus <= 1, '[0, 1]')
        need('descent_top', 0 <= self.descent_top <= 1000, '[0, 1000]')
        need('chunk', 1 <= self.chunk <= 10 ** 7, '[1, 1e7]')
        need('converge_window', 1 <= self.converge_window, '[1, inf)')
        need('converge_tol', 0 <= self.converge_tol, '[0, inf)')
        return self

    def preprocess_config(self) -> PreprocessConfig:
        names = {f.name for f in fields(PreprocessConfig)}
        return PreprocessConfig(**{k: v for k, v in asdict(self).items() if k in names})

    def kernel_params(self, continuous_only: bool = False) -> np.ndarray:
        """The parameter vector ``P`` of :mod:`_kernels` (optionally without dimension moves)."""
        P = np.zeros(K.NPARAM)
        p = np.array([self.p_rotate, self.p_shift, self.p_gap, self.p_arm, self.p_lane, self.p_width])
        if continuous_only:
            p[3:5] = 0.0
        cum = np.cumsum(p / p.sum())
        P[K.P_MIN_SEP] = math.radians(self.min_sep_deg)
        P[K.P_MIN_ARMS] = self.min_arms
        P[K.P_MAX_ARMS] = self.max_arms
        P[K.P_MIN_LANES] = self.min_lanes
        P[K.P_MAX_LANES] = self.max_lanes
        P[K.P_GAP_MAX] = self.gap_max
        P[K.P_W_MIN] = self.lane_width_min
        P[K.P_W_MAX] = self.lane_width_max
        P[K.P_ROT] = math.radians(self.rotate_max_deg)
        P[K.P_SHIFT] = self.shift_max
        P[K.P_GAP_STEP] = self.gap_step
        P[K.P_W_STEP] = self.width_step
        P[K.P_SPLIT_SPAN] = math.radians(self.split_span_deg)
        P[[K.P_C_ROT, K.P_C_SHIFT, K.P_C_GAP, K.P_C_ARM, K.P_C_LANE]] = cum[:5]
        P[K.P_FLOOR] = self.clutter_floor
        P[K.P_TRAFFIC] = self.traffic_side
        P[K.P_D2_CUT] = self.cut_sigma2
        P[K.P_SAMPLE_W] = 1.0 if self.p_width > 0 else 0.0
        P[K.P_W_DEFAULT] = self.lane_width
        P[K.P_LANE_NORM] = self.lane_norm
        P[K.P_LANE_SUM] = 1.0 if self.lane_sum else 0.0
        P[K.P_FOCUS] = -1.0
        P[K.P_FINE_P] = self.fine_step_prob
        P[K.P_FINE_SCALE] = self.fine_step_scale
        return P

    @property
    def sample_width(self) -> bool:
        return self.p_width > 0


#: Lane-count steps (entering, leaving) of one arm tried by the descent: one side +-1, or
#: a lane moved across the median (the median line shifts by a lane width).
DESCENT_STEPS = ((1, 0), (-1, 0), (0, 1), (0, -1), (1, -1), (-1, 1))
#: Shares of ``descent_samples`` after which a descent run is screened (``descent_prune``).
DESCENT_CHECKS = (1 / 16, 1 / 8, 1 / 4, 3 / 8, 1 / 2, 3 / 4)


class _Tables:
    """Prior / proposal tables derived from a config (computed once)."""

    def __init__(self, cfg: TopologyConfig):
        self.P = cfg.kernel_params()
        self.P_polish = cfg.kernel_params(continuous_only=True)
        self.logPA = count_log_table(cfg.arm_count_prior, cfg.min_arms, cfg.max_arms, K.MAXA + 1)
        size = cfg.max_lanes + 1
        self.logPn = count_log_table(cfg.lane_count_prior, cfg.min_lanes, cfg.max_lanes, size)
        self.logqn = self.logPn.copy()
        self.cumqn = np.cumsum(np.exp(self.logqn))
        self.gaps = np.linspace(0.0, cfg.gap_max, int(round(cfg.gap_max / 0.5)) + 1)
        self.widths = (np.linspace(cfg.lane_width_min, cfg.lane_width_max, 6)
                       if cfg.sample_width else np.zeros(0))
        self.arm_const = arm_log_const(cfg.gap_max, cfg.lane_width_min, cfg.lane_width_max,
                                       cfg.sample_width)
        self.log_floor = K.log_floor_table(
            cfg.clutter_floor, cfg.cut_sigma2 + cfg.lane_norm * math.log(cfg.max_lanes) + 1.0)


def _as_rng(seed) -> np.random.Generator:
    if isinstance(seed, np.random.Generator):
        return seed
    return np.random.default_rng(seed)


class TopologyEstimator:
    """Anytime MAP estimate of the intersection topology (paper §II)."""

    def __init__(self, cfg: TopologyConfig | None = None, seed=0):
        self.cfg = (cfg or TopologyConfig()).validate()
        self._rng = _as_rng(seed)
        self._t = _Tables(self.cfg)
        self._pcfg = self.cfg.preprocess_config()
        self.reset()

    # ------------------------------------------------------------------ public API
    def reset(self) -> None:
        """Forget observations and chain."""
        self._dets = Detections.empty()
        self._radar = None                     # radar_rows(self._dets), made on first use
        self._obs = ObservationSet.empty()
        self._chains: list[Chain] = []
        self._pp_center = None
        self._since_data = 0
        self._polish_left = 0
        self._last_improve = 0
        self._ref_best = -math.inf
        self.samples_drawn = 0
        self.preprocess_count = 0
        self._deadline = math.inf
        self._rep_key = None

    def set_observations(self, dets: Detections) -> None:
        """Replace the observation window; keep the chain (warm start, re-heated)."""
        self._dets = dets.finite()
        self._radar = None
        self._since_data = 0
        if self._chain is None:
            self._initialise()
            return
        center = self._chain.best_S[:2].copy()
        self._preprocess(center)
        for c in self._chains:
            c.step = min(c.step, int(self.cfg.reheat_fraction * self.cfg.anneal_samples))

    def run(self, n_samples: int | None = None, time_budget_s: float | None = None) -> int:
        """Advance every chain by ``n_samples`` (or until the wall-time budget is used);
        returns the count drawn over all chains, including those of the descent at the end
        of the schedule (:meth:`_descend`)."""
        if n_samples is None and time_budget_s is None:
            raise ValueError('run() needs n_samples or time_budget_s')
        if self._chain is None and len(self._dets):
            self._initialise()
        if self._chain is None or len(self._obs) == 0:
            return 0
        t0 = time.perf_counter()
        self._deadline = math.inf if time_budget_s is None else t0 + time_budget_s
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
            drawn += self._advance(m)
            done += m
            if time_budget_s is not None and time.perf_counter() - t0 >= time_budget_s:
                break
        return drawn

    @property
    def best(self) -> Intersection | None:
        """Best (MAP) intersection so far, arms with lane width and confidence
        ``1 - exp(-passages / 3)`` (vehicle passages the arm explains best); arms that
        explain fewer than ``min_arm_support`` passages are left out (see :meth:`_reported`)."""
        if self._chain is None:
            return None
        S, conf, _ = self._reported()
        return unpack_state(S, self.cfg.traffic_side, conf)

    @property
    def best_log_posterior(self) -> float:
        """log P(I|Z) + const of :attr:`best`."""
        return -math.inf if self._chain is None else self._reported()[2]

    @property
    def state(self) -> str:
        if self._chain is None or len(self._obs) == 0:
            return 'NO_DATA'
        c = self._chain
        if (c.step >= self.cfg.anneal_samples
                and c.step - self._last_improve >= self.cfg.converge_window):
            return 'CONVERGED'
        return 'CONVERGING'

    @property
    def observations(self) -> ObservationSet:
        """The preprocessed observations currently scored."""
        return self._obs

    @property
    def acceptance(self) -> dict:
        if not self._chains:
            return {}
        return acceptance_rates(sum(c.stats for c in self._chains))

    @property
    def n_chains(self) -> int:
        return len(self._chains)

    @property
    def _chain(self) -> Chain | None:
        """The chain with the best state so far (the first on ties); None before data."""
        return max(self._chains, key=lambda c: c.best_lpost) if self._chains else None

    def log_posterior(self, inter: Intersection) -> float:
        """log P(I|Z) + const of any intersection under the current observations."""
        return self._lpost(pack_state(inter))

    # ------------------------------------------------------------------ internals
    def _initialise(self) -> None:
        cfg = self.cfg
        p, o, w = seed_lines(self._dets, self._pcfg)
        c = initial_center(p, o, w)
        if c is None:
            return
        angles = initial_arm_angles(p, o, w, c, math.radians(cfg.min_sep_deg), cfg.max_arms,
                                    peak_frac=cfg.init_peak_frac)
        angles = self._complete_arms(angles, o, w)
        c0 = c
        obs = self._preprocessed(c, angles)
        c, guess = initial_lanes(obs, c, angles, cfg.lane_width, cfg.max_lanes, cfg.gap_max,
                                 cfg.traffic_side, width_range=(cfg.lane_width_min,
                                                                cfg.lane_width_max)
                                 if cfg.sample_width else None)
        arms = [Arm(angle=a, gap=g, lanes_in=max(ni, cfg.min_lanes),
                    lanes_out=max(no, cfg.min_lanes), lane_width=wd)
                for a, (g, ni, no, wd) in zip(angles, guess)]
        S = pack_state(Intersection(center=c, arms=arms))
        n = cfg.chains_tracked if self._dets.has_tracks else cfg.chains
        self._chains = [Chain(S=S.copy(), C=np.zeros((K.MAXA, 0)), ll=0.0, lp=0.0,
                              best_S=S.copy(), best_lpost=-math.inf, step=0,
                              stats=np.zeros(2 * len(K.MOVE_NAMES), np.int64))
                        for _ in range(n)]
        self._polish_left = cfg.polish_samples
        self._preprocess(c, obs if np.hypot(*(c - c0)) <= cfg.recenter_threshold else None, c0)
        if cfg.polish_samples == 0:
            for ch in self._chains:
                self._refit(ch)

    def _refit(self, c: Chain) -> None:
        """Coordinate ascent over each arm's lanes, gap and width (init aid; monotone)."""
        cfg = self.cfg
        if len(self._obs) == 0 or cfg.refit_sweeps == 0:
            return
        for _ in range(cfg.refit_sweeps):
            for k in range(int(c.S[2])):
                K.refit_arm(c.S, k, self._t.P, self._t.logPn, *self._obs.kernel_args(), c.C,
                            self._t.gaps, self._t.widths, self._t.log_floor)
        self._rescore(c)

    def _descend(self, c: Chain) -> None:
        """Greedy descent from chain ``c``'s MAP state at the end of its schedule (beyond the paper).

        A lane-count change moves the optimum of center, angles, gap and width too, so at a
        cold temperature the chain rejects it although the pair of changes scores higher
        (raw detections: in ~3/4 of the wrong lane counts the true counts win once center
        and gaps follow). Candidates: one arm's lane counts changed by a step of
        :data:`DESCENT_STEPS` (that arm's gap and width then set to the best grid point),
        or one arm removed. The lane candidates within ``descent_screen`` nats of the
        current state (the ``descent_top`` best of them if > 0), and every removal (an extra arm is
        only worse until its traffic moves to the neighbour), get ``descent_samples``
        continuous moves at ``descent_temp`` in stages, dropped as soon as they fall behind
        (see :meth:`_descent_run`); the best improvement is kept, for up to
        ``descent_rounds`` rounds. Monotone in the posterior; draws counted in
        ``samples_drawn``.
        """
        cfg = self.cfg
        if cfg.descent_rounds == 0 or len(self._obs) == 0:
            return
        S, L = self._descent_run(c.best_S)
        for _ in range(cfg.descent_rounds):
            lanes, removals = [], []
            for S2, k in self._descent_candidates(S):
                if k < 0:
                    removals.append(S2)
                    continue
                S2, L2 = self._descent_prepare(S2, k)
                if L2 >= L - cfg.descent_screen:
                    lanes.append((L2, len(lanes), S2, k))
            lanes.sort(key=lambda x: (-x[0], x[1]))
            best = None
            top = lanes[:cfg.descent_top] if cfg.descent_top > 0 else lanes
            for S2, k in [(x[2], x[3]) for x in top] + [(S2, -1) for S2 in removals]:
                if time.perf_counter() >= self._deadline:
                    break
                S3, L3 = self._descent_run(S2, L, k)
                if L3 > L + 1e-9:
                    best, L = S3, L3
            if best is None:
                break
            S = best
        if L > c.best_lpost:
            c.best_S[:] = S
            c.best_lpost = L
            c.S[:] = S
            c.ll, _ = self._score(c.S, c.C)
            c.lp = L - c.ll

    def _descent_candidates(self, S):
        cfg = self.cfg
        n = int(S[2])
        for k in range(n):
            i = K.HDR + k * K.STRIDE
            for di, do in DESCENT_STEPS:
                ni, no = S[i + K.NIN] + di, S[i + K.NOUT] + do
                if cfg.min_lanes <= min(ni, no) and max(ni, no) <= cfg.max_lanes:
                    S2 = S.copy()
                    S2[i + K.NIN], S2[i + K.NOUT] = ni, no
                    yield S2, k
            if n > cfg.min_arms:
                S2 = S.copy()
                K.remove_arm_at(S, S2, self._t.P, self._t.logqn, k)
                yield S2, -1

    def _descent_prepare(self, S, k):
        """Arm ``k``'s gap and width set to the best grid point for its lane counts: (S, lpost)."""
        t = self._t
        C = np.zeros((K.MAXA, len(self._obs)))
        self._score(S, C)
        args = self._obs.kernel_args()
        K.refit_arm(S, k, t.P, t.logPn, *args, C, t.gaps, t.widths, t.log_floor, True)
        # refit_arm left C the columns of the refitted S: combine them, no second scoring
        ll = float(K.combine(C, int(S[2]), -1, C[0], False, args[-1], t.P[K.P_FLOOR]))
        return S, ll + self._log_prior(S)

    def _descent_run(self, S, ref=None, focus=-1):
        """``descent_samples`` continuous moves at ``descent_temp`` from ``S``: (best, lpost);
        with ``focus`` >= 0 a share ``descent_focus`` of the arm moves goes to that arm.

        With ``ref`` (the best log posterior so far) the moves run in stages ending at
        :data:`DESCENT_CHECKS` of them, and stop after a stage whose best is more than
        ``descent_prune`` x (share of moves left)^2 nats below ``ref``."""
        t, cfg = self._t, self.cfg
        m = cfg.descent_samples
        C = np.zeros((K.MAXA, len(self._obs)))
        ll, _ = self._score(S, C)
        lp = self._log_prior(S)
        ch = Chain(S=S.copy(), C=C, ll=ll, lp=lp, best_S=S.copy(), best_lpost=ll + lp, step=0,
                   stats=np.zeros(2 * len(K.MOVE_NAMES), np.int64))
        P = t.P_polish
        if focus >= 0:
            P = P.copy()
            P[K.P_FOCUS], P[K.P_FOCUS_P] = focus, cfg.descent_focus
        ends = [m] if ref is None else sorted({max(1, round(m * f)) for f in DESCENT_CHECKS} | {m})
        for end in ends:
            n = end - ch.step
            if n <= 0:
                continue
            advance(ch, n, np.full(n, cfg.descent_temp), int(self._rng.integers(0, 2 ** 31 - 1)),
                    P, t.logPA, t.logPn, t.arm_const, t.logqn, t.cumqn, self._obs)
            self.samples_drawn += n
            if end < m and ch.best_lpost < ref - cfg.descent_prune * (1.0 - end / m) ** 2:
                break
        return ch.best_S, ch.best_lpost

    def _complete_arms(self, angles, o, w):
        """Ensure min_arms <= |A|: add arms opposite / evenly spaced when data are scarce."""
        cfg = self.cfg
        ms = math.radians(cfg.min_sep_deg)
        if not angles:
            if len(o):
                v = (w[:, None] * o).sum(0)
                a0 = math.atan2(v[1], v[0]) if np.hypot(*v) > 0 else 0.0
            else:
                a0 = 0.0
            angles = [a0]
        base = angles[0]
        k = 1
        while len(angles) < cfg.min_arms:
            cand = base + math.pi * k / max(cfg.min_arms - 1, 1)
            cand = (cand + math.pi) % (2 * math.pi) - math.pi
            if all(abs((cand - b + math.pi) % (2 * math.pi) - math.pi) >= ms for b in angles):
                angles.append(cand)
            k += 1
            if k > 32:
                break
        return angles

    def _preprocess(self, center, obs=None, obs_center=None) -> None:
        """(Re-)preprocess around ``center`` (or adopt ``obs`` made around ``obs_center``)
        and re-score the chain and its best state on the new observations."""
        if obs is None:
            S = self._chain.best_S
            angles = S[K.HDR:K.HDR + int(S[2]) * K.STRIDE:K.STRIDE].copy()
            obs, obs_center = self._preprocessed(center, angles), center
        self._obs = obs
        self._pp_center = np.asarray(obs_center, float).copy()
        self.preprocess_count += 1
        for c in self._chains:
            c.best_lpost = self._lpost(c.best_S)
            self._rescore(c)
        self._ref_best = self._chain.best_lpost
        self._last_improve = self._chain.step

    def _preprocessed(self, center, angles):
        if self._radar is None:
            self._radar = radar_rows(self._dets, self._pcfg)
        return preprocess(self._dets, center, self._pcfg, angles, self._radar)

    def _rescore(self, c: Chain) -> None:
        """Chain ``c``'s current state scored in full on the observations held (columns
        remade); its best state takes the current one if that scores higher."""
        if c.C.shape[1] != len(self._obs):
            c.C = np.zeros((K.MAXA, len(self._obs)))
        c.ll, _ = self._score(c.S, c.C)
        c.lp = self._log_prior(c.S)
        if c.ll + c.lp > c.best_lpost:
            c.best_S[:] = c.S
            c.best_lpost = c.ll + c.lp

    def _log_prior(self, S) -> float:
        t = self._t
        return float(K.log_prior(S, t.logPA, t.logPn, t.arm_const))

    def _lpost(self, S) -> float:
        """log P(I|Z) + const of the packed state ``S`` (scored in full)."""
        return self._score(S)[0] + self._log_prior(S)

    def _score(self, S, C=None):
        if C is None:
            C = np.zeros((K.MAXA, len(self._obs)))
        ll = float(K.full_loglik(S, self._t.P, *self._obs.kernel_args(), C))
        return ll, C

    def _advance(self, m: int) -> int:
        """``m`` samples of every chain (+ the descent when the schedule ends), the chains
        in lockstep; returns samples drawn."""
        t, cfg = self._t, self.cfg
        temps = temperatures(self._chains[0].step, m, cfg.t_start, cfg.t_end, cfg.anneal_samples)
        P = t.P_polish if self._polish_left > 0 else t.P
        was_polishing = self._polish_left > 0
        self._polish_left = max(0, self._polish_left - m)
        drawn = self.samples_drawn
        for c in self._chains:
            seed = int(self._rng.integers(0, 2 ** 31 - 1))
            advance(c, m, temps, seed, P, t.logPA, t.logPn, t.arm_const, t.logqn, t.cumqn,
                    self._obs)
            if was_polishing and self._polish_left == 0:
                self._refit(c)
            elif cfg.refit_every and c.step // cfg.refit_every != (c.step - m) // cfg.refit_every:
                self._refit(c)
            if c.step - m < cfg.anneal_samples <= c.step:
                self._descend(c)
            self.samples_drawn += m
        drawn = self.samples_drawn - drawn
        self._since_data += m
        c = self._chain
        if c.best_lpost > self._ref_best + cfg.converge_tol:
            self._ref_best = c.best_lpost
            self._last_improve = c.step
        if (self._since_data <= cfg.recenter_window
                and np.hypot(*(c.best_S[:2] - self._pp_center)) > cfg.recenter_threshold):
            self._preprocess(c.best_S[:2].copy())
        return drawn

    def _reported(self):
        """(state, confidence per arm, log posterior) of the reported estimate.

        The MAP state without the arms that explain less than ``min_arm_support`` vehicle
        passages (trajectory parts; radar / heading voxels: detections per passage, see
        ``ObservationSet.passages``), weakest first, down to ``min_arms``. Beyond the paper: the clutter
        floor lets one or two aligned trajectory parts (turning traffic, a false track) pay
        for an arm's prior. Tracked, seeds 0-399: every true arm explained >= 3 parts, the
        only two spurious arms (seeds 10, 870) 1 and 2.
        """
        S = self._chain.best_S
        key = (S.tobytes(), self.preprocess_count)
        if self._rep_key != key:
            S = S.copy()
            lpost = self._chain.best_lpost
            sup = self._support(S)
            while (len(self._obs) and int(S[2]) > self.cfg.min_arms
                   and sup.min() < self.cfg.min_arm_support):
                S2 = S.copy()
                K.remove_arm_at(S, S2, self._t.P, self._t.logqn, int(np.argmin(sup)))
                S = S2
                sup = self._support(S)
                lpost = None
            if lpost is None:
                lpost = self._lpost(S)
            self._rep = (S, 1.0 - np.exp(-sup / 3.0), lpost)
            self._rep_key = key
        return self._rep

    def _support(self, S) -> np.ndarray:
        """Per arm: the vehicle passages it explains best (above the clutter floor)."""
        n = int(S[2])
        if len(self._obs) == 0 or n == 0:
            return np.zeros(n)
        _, C = self._score(S)
        Cn = C[:n]
        best = Cn.argmax(axis=0)
        good = Cn.max(axis=0) > self.cfg.clutter_floor
        return np.bincount(best[good], self._obs.passages[good], n)


def warmup() -> float:
    """Compile (or load from cache) all kernels once per process; returns seconds taken."""
    t0 = time.perf_counter()
    rng = np.random.default_rng(0)
    xy = rng.normal(0, 20, (40, 2))
    dets = Detections.concat([
        Detections.make(xy, heading=np.arctan2(xy[:, 1], xy[:, 0]),
                        track_id=np.repeat(np.arange(8), 5), t=np.tile(np.arange(5.0), 8)),
        Detections.make(xy, doppler=rng.normal(0, 5, 40), sensor_xy=(30.0, 0.0), rcs=10.0)])
    est = TopologyEstimator(TopologyConfig(chunk=50), seed=0)
    est.set_observations(dets)
    est.run(n_samples=100)
    return time.perf_counter() - t0
