"""Detections -> topology (paper §II) -> lane course (paper §III): one pipeline for all.

:func:`estimate` is the one-shot call the benchmark uses; :class:`OnlineEstimator` is the
anytime pipeline the node and the replay drive tick by tick: observations arrive at any
time, each tick spends a budget (samples or wall time) and the current best estimate can
be read at any time.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field, replace
import math
import threading
import time

import numpy as np

from .convergence import ConvergenceConfig, ConvergenceTracker
from .lanes import LaneConfig, LaneCourseEstimator, lanelets_from_topology
from .model import Intersection, Lanelet
from .observability import Observability, assess
from .observations import Detections
from .ranges import check_table
from .topology import TopologyConfig, TopologyEstimator
from .topology.preprocess import radar_filter
from .tracking import RadarTracker, TrackerConfig, is_radar_track, radar_rows_of, track_radar

__all__ = ['EstimateResult', 'PipelineConfig', 'OnlineEstimator', 'estimate', 'mode_of', 'needs_sampling',
           'IDLE_SAMPLING_TICKS']


@dataclass
class EstimateResult:
    """A snapshot of the estimate: topology, lanelets and what it cost.

    ``state`` is what a user gates on: in :class:`OnlineEstimator` the hysteresis state of
    :mod:`.convergence` (NO_DATA / CONVERGING / CONVERGED, meanings documented there);
    ``sampler_state`` is the topology chain's own plateau test (``TopologyEstimator.state``),
    which flickers while data arrives. :func:`estimate` (one batch, no time series) reports
    the sampler's state as both.
    """

    intersection: Intersection | None
    lanelets: list[Lanelet]
    timing_ms: dict = field(default_factory=dict)
    topology_samples: int = 0
    lane_samples: int = 0
    log_posterior: float = float('-inf')
    state: str = 'NO_DATA'
    observations: int = 0
    lanes_updated: bool = True        # lanelets differ from the previous tick's
    sampler_state: str | None = None  # TopologyEstimator.state of this tick (None: = state)
    phases_ms: dict = field(default_factory=dict)   # estimate(): where the time went (bench --profile)
    counters: dict = field(default_factory=dict)    # estimate(): how often a phase ran

    def __post_init__(self):
        if self.sampler_state is None:
            self.sampler_state = self.state
    observability: Observability | None = None   # do the data show an intersection at all?

    def stats(self) -> dict:
        d = {'topology_samples': int(self.topology_samples), 'lane_samples': int(self.lane_samples),
             'elapsed_s': round(sum(self.timing_ms.get(k, 0.0) for k in ('topology', 'lanes')) / 1e3, 6),
             'state': self.state, 'observations': int(self.observations)}
        if self.observability is not None:
            d['observability'] = self.observability.to_json()
        return d


def mode_of(dets: Detections) -> str:
    """'tracked' when trajectories are present, else 'raw' (lane course needs tracks, §III)."""
    return 'tracked' if dets.has_tracks else 'raw'


def _seeds(seed) -> tuple[np.random.Generator, np.random.Generator]:
    ss = np.random.SeedSequence(seed if isinstance(seed, (int, np.integer)) else
                                np.random.default_rng(seed).integers(2**63))
    a, b = ss.spawn(2)
    return np.random.default_rng(a), np.random.default_rng(b)


def estimate(dets: Detections, *, mode: str | None = None, topology_samples: int = 5000,
             lane_samples: int = 20000, seed: int = 0,
             topology_config: TopologyConfig | None = None,
             lane_config: LaneConfig | None = None,
             tracker_config: TrackerConfig | None = None) -> EstimateResult:
    """Estimate topology and lane course from one batch of detections (bench entry point).

    ``mode`` 'raw' ignores track ids (paper §II raw-detection experiment); its radar rows
    go through the radar tracker (:mod:`.tracking`, ``tracker_config.enabled``) and the
    tracks through the tracked pipeline; with the tracker off, or when it reports no
    track, the paper's raw model runs and the lane course is skipped (straight lanelets
    from the topology instead).
    """
    mode = mode or mode_of(dets)
    if mode not in ('tracked', 'raw', 'heading'):
        raise ValueError(f"mode must be 'tracked', 'raw' or 'heading', got {mode!r}")
    topology_config = topology_config or TopologyConfig()
    tt = time.perf_counter()
    dets, mode = radar_tracked(in_mode(dets, mode), mode, tracker_config or TrackerConfig(),
                               topology_config)
    rng_topo, rng_lanes = _seeds(seed)
    topo = TopologyEstimator(topology_config, rng_topo)
    t0 = time.perf_counter()
    topo.set_observations(dets)
    ta = time.perf_counter()
    topo.run(n_samples=topology_samples)
    t1 = time.perf_counter()
    best = topo.best
    observability = assess(dets)           # reading the topology result: timed with it
    tb = time.perf_counter()
    lanelets, n_lane, lane_s = _lanes(best, dets, mode, lane_samples, lane_config, rng_lanes)
    t2 = time.perf_counter()
    timing = {'topology': (tb - t0) * 1e3, 'lanes': (t2 - tb) * 1e3, 'total': (t2 - tt) * 1e3,
              'tracking': (t0 - tt) * 1e3}
    state = topo.state
    return EstimateResult(best, lanelets, timing, topo.samples_drawn, n_lane,
                          topo.best_log_posterior, state, len(dets), sampler_state=state,
                          phases_ms={'tracking': (t0 - tt) * 1e3,
                                     **_phases(topo, (t0, ta, t1, tb, t2), lane_s)},
                          counters={'topology_preprocess': int(topo.preprocess_count),
                                    'topology_chains': int(topo.n_chains)},
                          observability=observability)


def radar_tracked(dets: Detections, mode: str, cfg: TrackerConfig,
                  topology: TopologyConfig) -> tuple[Detections, str]:
    """(detections, mode) the estimators read: in 'raw' mode with the tracker on, the radar
    rows that pass the clutter filter (:func:`.preprocess.radar_filter`) become radar tracks
    and the window is 'tracked' (the other rows stay as they are); else unchanged."""
    if mode != 'raw' or not cfg.enabled:
        return dets, mode
    radar = radar_rows_of(dets)
    tracks = track_radar(dets, cfg, radar_filter(dets, topology.preprocess_config(), moving_only=False))
    if not len(tracks):
        return dets, mode
    return Detections.concat([tracks, dets.subset(~radar)]), 'tracked'


def in_mode(dets: Detections, mode: str) -> Detections:
    """``dets`` as :func:`estimate` reads them in ``mode``: every mode but 'tracked' ignores
    track ids (paper §II raw-detection experiment)."""
    if mode == 'tracked':
        return dets
    return replace(dets, track_id=np.full(len(dets), -1, np.int64))


def _phases(topo, marks, lane_s: dict) -> dict:
    """Where :func:`estimate`'s time went [ms], in disjoint phases that add up to its time:
    the topology estimator's own timers (``TopologyEstimator.timings``: ``topology_preprocess``,
    ``_rescore``, ``_initialise``, ``_chain``, ``_refit``, ``_descent``; §II-A to II-C) and
    ``topology_other`` (the rest of its ``set_observations`` + ``run``), ``topology_report``
    (the reported MAP estimate), the lane course's timers and ``lanes_other``."""
    t0, ta, t1, tb, t2 = marks
    timers = {f'topology_{k}': 1e3 * v for k, v in dict(getattr(topo, 'timings', {}) or {}).items()}
    out = dict(timers)
    out['topology_other'] = max((t1 - t0) * 1e3 - sum(timers.values()), 0.0)
    out['topology_report'] = (tb - t1) * 1e3
    lanes = {f'lanes_{k}': 1e3 * v for k, v in lane_s.items()}
    out.update(lanes)
    out['lanes_other'] = max((t2 - tb) * 1e3 - sum(lanes.values()), 0.0)
    return out


def _lanes(best, dets, mode, lane_samples, lane_config, rng):
    """(lanelets, lane samples drawn, the lane estimator's phase timers [s])."""
    if best is None:
        return [], 0, {}
    if mode != 'tracked' or lane_samples <= 0:
        return with_support(best, lanelets_from_topology(best), None), 0, {}
    lanes = LaneCourseEstimator(lane_config or LaneConfig(), rng)
    lanes.initialise(best, dets)
    lanes.run(n_samples=lane_samples)
    return (with_support(best, lanes.lanelets, lanes.lane_support()), lanes.samples_drawn,
            dict(lanes.timings))


def with_support(best: Intersection, lanelets: list[Lanelet], lane_support: dict | None):
    """Fill ``Arm.support`` (vehicle passages) in ``best`` and return ``lanelets``.

    With trajectories (``lane_support`` from the lane step): the trajectory parts on the
    arm's entering and leaving lanes. Without: the passages behind the topology step's
    arm confidence ``1 - exp(-passages / 3)`` (TopologyEstimator.best), inverted; the
    lanelets of such an arm take its confidence (no per-lane count without tracks).
    """
    for i, arm in enumerate(best.arms):
        if lane_support is not None:
            arm.support = float(sum(n for lid, n in lane_support.items()
                                    if lid.startswith(f'a{i}_')))
        else:
            arm.support = float(min(-3.0 * np.log(max(1.0 - arm.confidence, 1e-300)), 1e6))
    if lane_support is None:
        for ll in lanelets:
            ll.confidence = float(best.arms[ll.arm].confidence)
    return lanelets


_RANGES = {'window_s': ('(0, inf)', 'observations older than this are forgotten [s]'),
           'max_observations': ('[100, inf)', 'cap on observations in the window'),
           'topology_samples': ('[1, inf)', 'topology samples per tick (sample budget)'),
           'lane_samples': ('[0, inf)', 'lane-course samples per tick (sample budget)'),
           'budget_s': ('[0.001, 10]', 'wall time per tick [s]'),
           'lane_share': ('[0, 1)', 'share of the tick budget for the lane course'),
           'lane_period': ('[0, 60]', 'lane course re-estimated at most this often [s]'),
           'reset_distance': ('(0, inf)', 'ego past the center by this -> next intersection [m]'),
           'restart_growth': ('(1, inf)', 'window grown this many times -> restart the chains')}


@dataclass(frozen=True)
class PipelineConfig:
    """Settings of the anytime pipeline (node parameters map 1:1 onto these)."""

    window_s: float = 120.0           # observations older than this are dropped [s]
    max_observations: int = 200_000   # hard cap of the window (oldest dropped first)
    topology_samples: int = 5000      # per tick, in sample budget mode
    lane_samples: int = 20000         # per tick, in sample budget mode
    budget_s: float = 0.150           # per tick, in wall budget mode [s]
    lane_share: float = 0.6           # share of the wall budget given to the lane course
    lanes_enabled: bool = True
    lane_period: float = 1.0          # lane course at most this often (stamp time) [s]
    reset_distance: float = 25.0      # ego past the center by this much -> next intersection [m]
    restart_growth: float = 1.5       # race a fresh topology chain when the window grew by this factor
    topology: TopologyConfig = field(default_factory=TopologyConfig)
    lanes: LaneConfig = field(default_factory=LaneConfig)
    convergence: ConvergenceConfig = field(default_factory=ConvergenceConfig)  # reported state
    radar_tracking: TrackerConfig = field(default_factory=TrackerConfig)      # radar rows -> tracks

    def validate(self) -> None:
        """Raise ValueError naming the first parameter outside its allowed range."""
        check_table(self, _RANGES, 'PipelineConfig')
        self.topology.validate()
        self.lanes.validate()
        self.convergence.validate()
        self.radar_tracking.validate()


class OnlineEstimator:
    """Anytime pipeline: ``add`` observations whenever they come, ``tick`` to estimate.

    Deterministic for a given seed and sequence of calls when ticks use a sample budget.
    """

    def __init__(self, config: PipelineConfig | None = None, seed: int = 0):
        self.config = config or PipelineConfig()
        self.config.validate()
        self._seed = seed
        self._resets = 0
        self._lock = threading.Lock()   # add() may run in another thread than tick()
        self._track_lock = threading.Lock()   # one feed of the radar tracker at a time
        self.evicted = 0                # observations the max_observations cap pushed out, ever
        # radar rows -> tracks, at each tick (track_queued); kept over resets (the vehicles drive on)
        self._tracker = RadarTracker(self.config.radar_tracking) if self.config.radar_tracking.enabled else None
        self._clutter_cfg = self.config.topology.preprocess_config()
        self._radar_queue: list[Detections] = []   # radar rows not yet through the tracker
        self._queued = 0
        self.reset()

    def reset(self) -> None:
        """Forget observations and chains (e.g. when the ego has left the intersection)."""
        with self._lock:
            self._reset()

    def _reset(self) -> None:
        rng_topo, rng_lanes = _seeds(self._seed + 7919 * self._resets)
        self._resets += 1
        self._parts: list[Detections] = []
        self._n = 0
        self._topo = TopologyEstimator(self.config.topology, rng_topo)
        self._lanes = LaneCourseEstimator(self.config.lanes, rng_lanes)
        self._lane_topo = None            # the topology the lane course was initialised on
        self._lane_stale = False          # observations came since that initialisation
        self._lane_t = -np.inf
        self._prepare_s = deque(maxlen=INIT_COSTS)  # [s] recent first halves of lane initialisations
        self._finish_s = deque(maxlen=INIT_COSTS)   # [s] ... second halves + refinements
        self._report_s = deque(maxlen=INIT_COSTS)  # [s] recent reports of the MAP state
        self._no_room = False             # this tick has no room for a whole lane initialisation
        self._deferred = False            # the last lane initialisation due waited a tick
        self._dirty = False
        self._idle_ticks = 0              # ticks since the last new observations
        self._approached = False
        self._restart_n, self._races = 0, 0
        self._convergence = ConvergenceTracker(self.config.convergence)
        self._observability, self._obs_t = None, -np.inf
        self.result = EstimateResult(None, [])

    @property
    def n_observations(self) -> int:
        return self._n

    @property
    def idle(self) -> bool:
        """Would the next tick draw no sample (unchanged, converged estimate; see
        :func:`needs_sampling`)? Its result is then the previous one."""
        return not needs_sampling(self._dirty, self.result.sampler_state, self._idle_ticks)

    @property
    def resets(self) -> int:
        """How often the estimator started over (1 after construction): a change tells a
        publisher that the previous intersection's outputs are void."""
        return self._resets

    def window(self) -> Detections:
        """The observations currently in the window, as the estimators read them
        (:meth:`_estimated`; queued radar rows tracked first)."""
        self.track_queued()
        with self._lock:
            return self._estimated(Detections.concat(self._parts))

    def add(self, dets: Detections) -> int:
        """Append finite detections to the window; returns how many finite ones came.

        The window never holds more than ``max_observations``, not even between ticks: the
        oldest observations (in arrival order) give way to new ones, and a message larger
        than the cap keeps its newest rows. What gave way is counted in :attr:`evicted`.
        With the radar tracker on, the radar rows are queued for it (:meth:`track_queued`,
        at the next tick: the node's input callbacks stay short, and the tracker's time is
        the tick's, inside its budget); more than ``max_observations`` queued rows are
        tracked at once. The count returned is of the rows that came.
        """
        dets = dets.finite()
        came = len(dets)
        if came:
            self._append(dets)
            radar = radar_rows_of(dets) if self._tracker is not None else None
            if radar is not None and radar.any():
                with self._lock:
                    self._radar_queue.append(dets.subset(radar))
                    self._queued += len(self._radar_queue[-1])
                    full = self._queued > self.config.max_observations
                if full:
                    self.track_queued()
        return came

    def _append(self, dets: Detections) -> None:
        """``dets`` into the window under the cap (module docstring of :meth:`add`)."""
        n = len(dets)
        with self._lock:
            self._make_room(n)
            self._parts.append(dets if n <= self.config.max_observations
                               else dets.subset(_newest(dets.t, self.config.max_observations)))
            self._n += len(self._parts[-1])
            self.evicted += n - len(self._parts[-1])
            self._dirty = True

    def track_queued(self) -> int:
        """Feed the queued radar rows to the tracker (one scan per stamp; rows the clutter
        filter drops are no scan's) and add the rows it hands out to the window; returns
        their count. Called by :meth:`tick` and :meth:`window`."""
        if self._tracker is None:
            return 0
        with self._track_lock:          # batches reach the tracker in the order they were queued
            with self._lock:
                queue, self._radar_queue, self._queued = self._radar_queue, [], 0
            if not queue:
                return 0
            dets = Detections.concat(queue)
            tracks = self._tracker.feed(dets, radar_filter(dets, self._clutter_cfg, moving_only=False))
            if len(tracks):
                self._append(tracks)
            return len(tracks)

    @staticmethod
    def _estimated(dets: Detections) -> Detections:
        """What the estimators read of the window: with tracked objects of its own the
        radar tracks are left out (the radar rows count as in the paper, beside the
        objects); without, and once the tracker reported a track, the radar tracks replace
        the radar rows (as :func:`radar_tracked` does for a batch)."""
        radar_track = is_radar_track(dets.track_id)
        if not radar_track.any():
            return dets
        if ((dets.track_id >= 0) & ~radar_track).any():
            return dets.subset(~radar_track)
        return dets.subset(~radar_rows_of(dets))

    @property
    def radar_scans_late(self) -> int:
        """Radar scans that came after the tracker had gone past their stamp (later than its
        ``reorder_s``), left out of the tracks (0 without the tracker)."""
        return 0 if self._tracker is None else self._tracker.scans_late

    def _make_room(self, n: int) -> None:
        """Drop the oldest parts (the front one maybe in part, as a view: no copy) so that
        ``n`` more observations fit under the cap (with the lock held)."""
        over = self._n + min(n, self.config.max_observations) - self.config.max_observations
        while over > 0 and self._parts:
            first = self._parts[0]
            k = min(over, len(first))
            if k == len(first):
                self._parts.pop(0)
            else:
                self._parts[0] = first.subset(slice(k, None))
            self._n -= k
            self.evicted += k
            over -= k

    def _window(self, now: float) -> Detections:
        cfg = self.config
        dets = Detections.concat(self._parts)
        keep = dets.t >= now - cfg.window_s
        if keep.sum() > cfg.max_observations:   # exactly the newest: ties at the cut-off too
            idx = np.flatnonzero(keep)
            keep = np.zeros(len(dets), bool)
            keep[idx[_newest(dets.t[idx], cfg.max_observations)]] = True
            self.evicted += len(idx) - cfg.max_observations
        if not keep.all():
            dets = dets.subset(keep)
        self._parts = [dets]
        self._n = len(dets)
        return dets

    def passed(self, ego_xy, ego_yaw: float) -> bool:
        """True when the ego, seen approaching a converged estimate, is now ``reset_distance``
        past its center (an early, wrong center behind the ego must not throw data away).
        Gated on the sampler's own state, as before the reported state had hysteresis. An
        estimate of fewer than three arms is a road, not an intersection: a point of a road
        behind the ego is no reason to drop what was seen of the junction ahead."""
        best = self.result.intersection
        if best is None or self.result.sampler_state != 'CONVERGED' or len(best.arms) < 3:
            return False
        d = np.asarray(ego_xy, float) - best.center
        along = float(d @ np.array([np.cos(ego_yaw), np.sin(ego_yaw)]))
        if along < 0.0 and float(np.hypot(*d)) < 150.0:
            self._approached = True
        return self._approached and along > self.config.reset_distance

    def tick(self, now: float, *, wall_budget: bool = False,
             budget_s: float | None = None) -> EstimateResult:
        """Spend one tick's budget on the current window and return the best estimate.

        In wall mode the budget (``budget_s``, default ``config.budget_s``) covers the whole
        tick -- preprocessing, chain restarts and lane initialisation included: the topology
        chain runs until ``1 - lane_share`` of it has passed, the lane course until its end
        (each gets at least ``MIN_SHARE`` of it, so that data growing faster than the
        machine cannot starve the sampler). The caller leaves room for publishing in
        ``budget_s`` (the node: ``IntersectionEstimatorNode._publish_lanes_now``).
        The lane course's initialisation (§III-A) cannot stop at a deadline, so the
        topology first runs only until that initialisation, at its recent cost, would still
        end in time; when the lane course is due this tick it stops there, else it goes on
        to its own end (:meth:`_topology_phase`).
        """
        cfg = self.config
        t0 = time.perf_counter()
        total = cfg.budget_s if budget_s is None else budget_s
        deadline = t0 + total
        self.track_queued()
        topo_end = t0 + total * (1 - cfg.lane_share if cfg.lanes_enabled else 1.0)
        self._no_room = False
        with self._lock:
            dirty, self._dirty = self._dirty, False
            self._idle_ticks = 0 if dirty else self._idle_ticks + 1
            if not needs_sampling(dirty, self.result.sampler_state, self._idle_ticks - 1):
                # nothing new and converged: the estimate stands, at no cost (an idle node,
                # a gap in bag time); sampling resumes with the next observations
                self.result = replace(self.result, timing_ms={'topology': 0.0, 'lanes': 0.0, 'total': 0.0},
                                      lanes_updated=False)
                return self.result
            dets = self._estimated(self._window(now) if dirty else Detections.concat(self._parts))
        restart = False
        if dirty:
            self._topo.set_observations(dets)
            self._lane_stale = True
            restart = len(dets) >= cfg.restart_growth * self._restart_n
        if not wall_budget:
            if restart:
                self._restart(dets, None, total)
            else:
                self._topo.run(n_samples=cfg.topology_samples)
        else:
            self._topology_phase(dets, restart, now, topo_end, deadline, total)
        t1 = time.perf_counter()
        best = self._topo.best
        # before the lane step, whose wall deadline then absorbs it (at lane cadence)
        if dirty and now - self._obs_t >= cfg.lane_period or self._observability is None:
            self._observability, self._obs_t = assess(dets), now
        t2 = time.perf_counter()
        lanelets = self._tick_lanes(best, dets, now, deadline if wall_budget else None, total)
        if best is not None:
            with_support(best, lanelets, self._lanes.lane_support()
                         if self._lane_topo is not None and cfg.lanes_enabled and dets.has_tracks else None)
        t3 = time.perf_counter()
        sampler_state = self._topo.state
        self.result = EstimateResult(
            best, lanelets, {'topology': (t2 - t0) * 1e3, 'lanes': (t3 - t2) * 1e3,
                             'total': (t3 - t0) * 1e3},
            self._topo.samples_drawn, self._lanes.samples_drawn if self._lane_topo is not None else 0,
            self._topo.best_log_posterior, self._convergence.update(now, sampler_state, best),
            len(dets), self._lanes_updated, sampler_state, observability=self._observability)
        return self.result

    def _topology_phase(self, dets: Detections, restart: bool, now: float, topo_end: float,
                        deadline: float, total: float) -> None:
        """Wall-mode topology step: until the latest start of the lane work this tick may do
        (:meth:`_lanes_start`) if that comes before ``topo_end``, then on to ``topo_end``
        unless the lane course is initialised this tick (:meth:`_lanes_due`).

        When even the least topology share leaves no room for a whole lane
        re-initialisation (``_no_room``), it is spread over the next ticks: the first such
        tick is the topology's alone (in the node, the tick that publishes the waiting
        lanelets), the next -- after that wait (``_deferred``) -- prepares its first half
        (trajectories, frames, stop lines, the approach lanes shaped by their traffic), the
        one after finishes it (connectors, the lane graph, the sampler). The first
        initialisation never waits."""
        least = time.perf_counter() + MIN_SHARE * total
        lanes_start = self._lanes_start(deadline, total)
        self._no_room = lanes_start < least and self._lanes.graph is not None and not self._lanes.pending
        if self._no_room:                  # the first half only, and no sampler after it
            lanes_start = self._lanes_start(deadline, total, first_half=True)
        first = topo_end if self._no_room and not self._deferred \
            else min(topo_end, max(lanes_start, least))
        if restart:
            self._restart(dets, first, total)
        else:
            self._topo.run(time_budget_s=_left(first, total))
        t = time.perf_counter()
        best = self._topo.best                 # the MAP state's report, cached for the tick
        self._report_s.append(time.perf_counter() - t)
        if (first < topo_end and time.perf_counter() < topo_end
                and not self._lanes_due(best, dets, now)):
            self._topo.run(time_budget_s=topo_end - time.perf_counter())

    def _lanes_start(self, deadline: float, total: float, first_half: bool = False) -> float:
        """Latest start of this tick's lane work that ends by ``deadline``: the report of the
        topology's MAP state and the lane initialisation -- both halves, only the second when
        the first is prepared, each with a least sampler share after it; or (``first_half``)
        the first half alone, with no sampler -- each planned at the longest of its recent
        costs (0 before the first). On a large junction's radar window (SUMO seed 121) the
        report alone is 11-13 ms a tick, which the plan once left out."""
        report, prepare = max(self._report_s, default=0.0), max(self._prepare_s, default=0.0)
        if first_half:
            return deadline - report - prepare
        init = max(self._finish_s, default=0.0) + (0.0 if self._lanes.pending else prepare)
        return deadline - report - init - MIN_SHARE * total

    def _lanes_due(self, best, dets: Detections, now: float) -> bool:
        """Will :meth:`_tick_lanes` initialise the lane course (§III-A) this tick, or a half
        of it?"""
        return self._lane_step(best, dets, now) in ('initialise', 'prepare', 'finish')

    def _lane_step(self, best, dets: Detections, now: float) -> str:
        """What :meth:`_tick_lanes` does: 'none' (no topology), 'straight' (lanelets from
        the topology), 'keep' (the last lanelets stand), 'initialise', 'run'; in a wall-mode
        tick without room for an initialisation that is due (:meth:`_topology_phase`)
        'defer' (it waits while the last lanelets stand), then 'prepare' (its first half),
        and 'finish' in the tick after that (the second half and the sampler) -- in the
        node, the tick that publishes the waiting lane course leaves the estimation less
        than a lane update costs on a large junction, and both together overran the budget
        by a fifth; a whole initialisation after one such tick still overran it."""
        cfg = self.config
        if best is None:
            return 'none'
        if not cfg.lanes_enabled or not dets.has_tracks:
            return 'straight'
        if self._lanes.pending:
            return 'finish'
        same_topology = same_lanes(best, self._lane_topo)
        if same_topology and now - self._lane_t < cfg.lane_period:
            return 'keep'
        due = not same_topology or self._lane_stale
        if due and self._no_room:
            return 'prepare' if self._deferred else 'defer'
        return 'initialise' if due else 'run'

    def _restart(self, dets: Detections, topo_end: float | None, total: float) -> None:
        """Race a fresh chain (data-driven initialisation) against the warm one.

        Early on, little data can lead the warm chain into a model (e.g. a straight road
        far from the real center) that its local moves (paper Alg. 1) cannot leave when
        the rest of the traffic arrives. Whenever the window has grown by
        ``restart_growth`` since the last race, both chains get half of this tick's
        topology budget (samples, or the wall time left until ``topo_end``) and the one
        with the higher posterior goes on.
        """
        self._restart_n = len(dets)
        self._races += 1
        rng = np.random.default_rng(np.random.SeedSequence([self._seed, self._resets, self._races]))
        fresh = TopologyEstimator(self.config.topology, rng)
        fresh.set_observations(dets)
        if topo_end is None:
            half = self.config.topology_samples // 2
            fresh.run(n_samples=half)
            self._topo.run(n_samples=half)
        else:
            fresh.run(time_budget_s=0.5 * _left(topo_end, total))
            self._topo.run(time_budget_s=_left(topo_end, 0.5 * total))
        if _prefers(fresh, self._topo):
            self._topo = fresh

    def _tick_lanes(self, best, dets, now, deadline, total) -> list[Lanelet]:
        """Lane course (§III) at most every ``lane_period`` of stamp time, and at once when
        the topology it rests on changed; in between the last lanelets stand. With a
        ``deadline`` (wall mode) it runs until then, initialisation included."""
        cfg = self.config
        self._lanes_updated = True
        step = self._lane_step(best, dets, now)
        if step == 'none':
            return []
        if step == 'straight':
            return lanelets_from_topology(best)
        self._deferred = step == 'defer'
        if step in ('keep', 'defer'):
            self._lanes_updated = False
            return self._lanes.lanelets
        timings = self._lanes.timings            # the lane estimator's own timers [s]
        if step == 'prepare':                    # the last lanelets stand one more tick
            self._lanes.prepare(best, dets)
            self._prepare_s.append(self._lanes.halves['prepare'])
            self._lanes_updated = False
            return self._lanes.lanelets
        self._lane_t = now
        if step == 'initialise':
            self._lanes.initialise(best, dets)
            self._lane_topo, self._lane_stale = best, False
        elif step == 'finish':
            self._lane_topo, self._lane_stale = self._lanes.finish(), False
        if deadline is not None:
            # the sampler stops at the deadline; the refinement after it (§III-C), at its
            # last cost, does not
            self._lanes.run(time_budget_s=max(_left(deadline, total) - timings.get('refine', 0.0),
                                              MIN_SHARE * total))
        else:
            self._lanes.run(n_samples=cfg.lane_samples)
        if step == 'initialise':
            self._prepare_s.append(self._lanes.halves['prepare'])
        if step in ('initialise', 'finish'):
            self._finish_s.append(self._lanes.halves['finish'] + timings.get('refine', 0.0))
        return self._lanes.lanelets


#: Ticks on unchanged observations that still sample while the topology has not converged.
IDLE_SAMPLING_TICKS = 25


def needs_sampling(new_data: bool, state: str, idle_ticks: int) -> bool:
    """Does a tick draw samples? Always when observations arrived since the last tick; on
    unchanged ones only while the topology chain has not converged (§II-C: no better state
    within ``converge_window`` samples after the annealing) and for at most
    :data:`IDLE_SAMPLING_TICKS` ticks (``idle_ticks`` = ticks without new data before this
    one). A converged estimate on the same posterior is left as it is until new data come:
    an idle node or a gap in bag time costs next to nothing."""
    if new_data:
        return True
    return state != 'CONVERGED' and idle_ticks < IDLE_SAMPLING_TICKS


#: Least share of the tick budget a step gets even when the tick is already late.
MIN_SHARE = 0.05

#: Lane initialisations whose longest wall time the next ticks plan with.
INIT_COSTS = 5


def _newest(t: np.ndarray, k: int) -> np.ndarray:
    """Indices (in their order) of the ``k`` newest stamps of ``t``; among equal stamps the
    later rows (later arrivals) win, so exactly ``k`` are kept even when all stamps agree."""
    order = np.argsort(t, kind='stable')[-k:]
    return np.sort(order)


def _left(end: float, total: float) -> float:
    """Seconds until ``end``, at least ``MIN_SHARE`` of ``total``."""
    return max(end - time.perf_counter(), MIN_SHARE * total)


def same_lanes(a: Intersection, b: Intersection | None, center_m: float = 1.0,
               angle_deg: float = 3.0) -> bool:
    """Does a lane course built on ``b`` stand for ``a``? The same arms with the same lane
    counts and traffic side, centers within ``center_m``, each arm of ``a`` within
    ``angle_deg`` of its own arm of ``b``. A tolerance, not a grid: a MAP state that
    jitters across a grid line (the 1 m / 3 deg key before) re-initialised the lane
    course on ~57 % of the live ticks on a large radar junction (SUMO seed 121)."""
    if b is None or len(a.arms) != len(b.arms) or a.traffic_side != b.traffic_side:
        return False
    if float(np.hypot(*(np.asarray(a.center, float) - np.asarray(b.center, float)))) > center_m:
        return False
    free = list(b.arms)
    tol = math.radians(angle_deg)
    for arm in a.arms:
        hit = next((o for o in free if abs(math.remainder(arm.angle - o.angle, 2 * math.pi)) <= tol
                    and (arm.lanes_in, arm.lanes_out) == (o.lanes_in, o.lanes_out)), None)
        if hit is None:
            return False
        free.remove(hit)
    return True


def _prefers(a: TopologyEstimator, b: TopologyEstimator) -> bool:
    """Does chain ``a``'s best model beat ``b``'s? Each chain preprocesses the data around
    its own center (trajectory split, Doppler direction, §II-A), so their posteriors are
    not comparable as they stand: both models are scored under both observation sets."""
    if a.best is None:
        return False
    if b.best is None:
        return True
    gain_a = a.best_log_posterior - a.log_posterior(b.best)
    gain_b = b.best_log_posterior - b.log_posterior(a.best)
    return gain_a > gain_b


def warmup() -> float:
    """Compile (or load from numba's cache) every kernel once; returns seconds spent.

    The node calls this before its first tick, so that a tick never pays for JIT
    compilation; ``make setup`` calls it after installing, to fill the cache. It runs the
    pipeline on a small synthetic crossing (:func:`_warmup_detections`: trajectories, radar
    and heading rows; no simulator) in each input mode, with a schedule short enough to
    reach the refits and the descent.
    """
    t0 = time.perf_counter()
    dets = _warmup_detections()
    # a short schedule that still reaches every step: polish, refits, descent
    cfg = TopologyConfig(polish_samples=50, refit_every=50, anneal_samples=150,
                         descent_samples=20, chunk=50)
    for mode in ('tracked', 'raw', 'heading'):
        estimate(dets, mode=mode, topology_samples=200, lane_samples=200, seed=0,
                 topology_config=cfg)
    assess(dets.subset(np.isfinite(dets.doppler)))   # radar alone: the positions' axis
    return time.perf_counter() - t0


def _warmup_detections() -> Detections:
    """A four-arm crossing, right-hand traffic, one lane per direction, every turn driven:
    tracked objects, the radar detections of the same vehicles (sensor on arm 0) and
    untracked heading rows, in time order; deterministic (seeded noise)."""
    rng = np.random.default_rng(0)
    arms = np.radians([0.0, 90.0, 180.0, 270.0])
    parts, tid = [], 0
    for a in arms:
        for b in arms:
            if a == b:
                continue
            u, v = np.array([np.cos(a), np.sin(a)]), np.array([np.cos(b), np.sin(b)])
            n_u, n_v = np.array([-u[1], u[0]]), np.array([-v[1], v[0]])
            r = np.arange(60.0, 10.0, -1.0)[:, None]
            p_in, p_out = r * u + 1.75 * n_u, r[::-1] * v - 1.75 * n_v
            s = np.linspace(0.0, 1.0, 12)[1:-1, None]    # quadratic blend through the box
            mid = (1 - s) ** 2 * p_in[-1] + 2 * s * (1 - s) * 0.5 * (p_in[-1] + p_out[0]) \
                + s ** 2 * p_out[0]
            xy = np.vstack([p_in, mid, p_out]) + rng.normal(0.0, 0.2, (len(p_in) * 2 + 10, 2))
            d = np.gradient(xy, axis=0)
            t = tid * 20.0 + np.arange(len(xy)) * 0.1
            parts.append((xy, t, np.arctan2(d[:, 1], d[:, 0]), tid))
            tid += 1
    sensor = np.array([30.0, -5.0])
    out = []
    for xy, t, h, k in parts:
        vel = 10.0 * np.stack([np.cos(h), np.sin(h)], axis=1)
        los = (xy - sensor) / np.linalg.norm(xy - sensor, axis=1)[:, None]
        out += [Detections.make(xy, t, heading=h, track_id=k, speed=10.0),
                Detections.make(xy[::2], t[::2], doppler=(vel * los).sum(1)[::2],
                                sensor_xy=sensor, rcs=10.0),
                Detections.make(xy[1::3], t[1::3], heading=h[1::3])]
    dets = Detections.concat(out)
    return dets.subset(np.argsort(dets.t, kind='stable'))    # in time order, as windows are
