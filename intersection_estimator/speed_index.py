"""Speed index (issue 18): a fixed reference workload timed in the same process and run as
the benchmark, so that timings from two machines or two days compare.

The reference has the two shapes the estimator's time goes into:

* a compiled (numba) Metropolis loop of the topology sampler's shape (paper §II-C,
  Algorithm 1: propose a change of the state, re-score the observations it touches with the
  incremental likelihood, accept or reject) over a fixed synthetic likelihood: 4096
  observations with a heading, a 3-parameter state (a driving line's offset and angle),
  each step re-scoring a block of 128 observations with exp / log / cos, as the sampler's
  kernels do;
* a numpy pass of the preprocessing's shape (§II-A voxelisation): grid codes of 16384
  points, ``np.unique`` with the inverse, ``np.bincount`` reductions, ``np.hypot``.

Its time ``ref_ms`` is *the index* of a run: a machine that is 1.5x slower, or busier, has
a 1.5x larger ``ref_ms`` and 1.5x larger estimator timings, and the timings divided by
``ref_ms`` ("x ref") stay put. ``ref_ms`` is the *mean* of many short repetitions (~6 ms on
a quiet 2.45 GHz EPYC core), 5 before the cases, one after each case in the case's own
process and 5 after (see :class:`SpeedMeter`): interleaved, they see the load the cases saw.
The mean, not the median: on a shared machine a short repetition is preempted now and then
(a long case almost always, in proportion to its length), and only the mean carries that
cost in proportion, as it lands in the cases' times. Compare two runs through the "x ref" figures, never the
milliseconds; docs/benchmark.md says how.

The workload is frozen: :data:`REF_VERSION` names it, and any change to it (sizes, formula,
seed) must bump the version, because figures of different versions do not compare. It
lives in its own module, not in ``_kernels.py``, so that changes of the estimator's kernels
never change the reference. All random data come from one seeded numpy Generator.
"""

from __future__ import annotations

import math
import statistics
import time

from numba import njit
import numpy as np

__all__ = ['REF_VERSION', 'reference_once', 'after_case', 'SpeedMeter', 'in_ref', 'relative_summary',
           'format_index', 'profile_summary', 'format_profile']

REF_VERSION = 1
_SEED = 20190618          # the synthetic data, fixed forever (with REF_VERSION)
_N_OBS, _BLOCK, _STEPS = 4096, 128, 400
_N_POINTS, _VOXEL = 16384, 0.5


@njit(cache=True)
def _ref_score(x, y, h, w, c0, c1, c2, i):
    """log-likelihood of observation ``i`` under the state (the synthetic likelihood)."""
    d = -math.sin(c1) * x[i] + math.cos(c1) * y[i] - c0
    return w[i] * math.log(1e-3 + math.exp(-d * d / 4.5) * (1.0 + math.cos(h[i] - c1 - c2)))


@njit(cache=True)
def _ref_start(x, y, h, w, scores):
    """Scores of every observation at the start state (0, 0, 0), in place."""
    for i in range(x.shape[0]):
        scores[i] = _ref_score(x, y, h, w, 0.0, 0.0, 0.0, i)


@njit(cache=True)
def _ref_chain(x, y, h, w, prop, log_u, starts, scores):
    """Metropolis over a 3-parameter state with block-wise incremental re-scoring; returns
    (accepted moves, final log-likelihood). A move re-scores only its block of observations
    (the ones it "touches", as a sampler move touches one arm's); no allocation in the loop."""
    new = np.empty(_BLOCK)
    s0, s1, s2 = 0.0, 0.0, 0.0          # offset [m], angle [rad], heading bias [rad]
    accepted = 0
    for s in range(prop.shape[0]):
        c0, c1, c2 = s0, s1, s2
        k = s % 3
        if k == 0:
            c0 += prop[s]
        elif k == 1:
            c1 += 0.05 * prop[s]
        else:
            c2 += 0.1 * prop[s]
        b = starts[s]
        delta = 0.0
        for j in range(_BLOCK):
            v = _ref_score(x, y, h, w, c0, c1, c2, b + j)
            new[j] = v
            delta += v - scores[b + j]
        if log_u[s] < delta:
            s0, s1, s2 = c0, c1, c2
            for j in range(_BLOCK):
                scores[b + j] = new[j]
            accepted += 1
    return accepted, scores.sum()


def _data():
    """The fixed synthetic inputs (made once per process, not timed)."""
    rng = np.random.default_rng(_SEED)
    t = rng.uniform(-60.0, 60.0, _N_OBS)
    x, y = t, 0.2 * t + rng.normal(0.0, 1.5, _N_OBS) + 3.0
    h = np.full(_N_OBS, math.atan(0.2)) + rng.normal(0.0, 0.2, _N_OBS)
    w = rng.uniform(0.5, 1.0, _N_OBS)
    prop = rng.normal(0.0, 0.3, _STEPS)
    log_u = np.log(rng.uniform(0.0, 1.0, _STEPS))
    starts = rng.integers(0, _N_OBS - _BLOCK, _STEPS)
    pts = rng.normal(0.0, 25.0, (_N_POINTS, 2))
    return (x, y, h, w, prop, log_u, starts), pts


def _numpy_pass(pts):
    """Voxel grid pass of the preprocessing's shape: codes, unique + inverse, reductions."""
    ij = np.floor(pts / _VOXEL).astype(np.int64)
    codes = ij[:, 0] * 1_000_003 + ij[:, 1]
    keys, inv = np.unique(codes, return_inverse=True)
    count = np.bincount(inv, minlength=len(keys))
    mean_x = np.bincount(inv, weights=pts[:, 0], minlength=len(keys)) / count
    r = np.hypot(pts[:, 0] - mean_x[inv], pts[:, 1])
    return int(len(keys)), float(r.sum())


class _Reference:
    def __init__(self):
        self.chain_args, self.pts = _data()
        self.scores0 = np.zeros(_N_OBS)
        _ref_start(*self.chain_args[:4], self.scores0)
        self.fingerprint = None

    def once(self) -> tuple[float, tuple]:
        """One repetition: (wall ms, fingerprint); raises if the fingerprint (what the workload
        computed) ever differs from the first one's -- the work must be the same every time."""
        scores = self.scores0.copy()
        t0 = time.perf_counter()
        acc, ll = _ref_chain(*self.chain_args, scores)
        n_vox, r = _numpy_pass(self.pts)
        ms = 1e3 * (time.perf_counter() - t0)
        fp = (int(acc), round(float(ll), 6), n_vox, round(r, 3))
        if self.fingerprint is None:
            self.fingerprint = fp
        elif fp != self.fingerprint:
            raise RuntimeError(f'speed index reference is not deterministic: {fp} != {self.fingerprint}')
        return ms, fp


_REF: _Reference | None = None
#: after-case repetitions cost at most this share of the cases' time (per process)
REF_SHARE = 0.25
_SPENT = {'reference_ms': 0.0, 'cases_ms': 0.0}


def reference_once() -> tuple[float, tuple]:
    """Time one repetition of the reference workload (compiled on first use, untimed)."""
    global _REF
    if _REF is None:
        _REF = _Reference()
        _REF.once()            # JIT compile / cache load, first-touch of the data
    return _REF.once()


def after_case(case_ms: float) -> float | None:
    """A repetition after a benchmark case that took ``case_ms``, in the case's process, unless
    the repetitions so far cost more than :data:`REF_SHARE` of the cases' time (then None).
    Interleaved with the cases, the repetitions see the load the cases saw."""
    _SPENT['cases_ms'] += max(float(case_ms), 0.0)
    if _SPENT['reference_ms'] > REF_SHARE * _SPENT['cases_ms']:
        return None
    ms = reference_once()[0]
    _SPENT['reference_ms'] += ms
    return ms


class SpeedMeter:
    """Collects reference repetitions over a run: ``warm(k)`` before the first case, ``sample()``
    after each one (so a change of load during the run lands in the index as in the figures)."""

    def __init__(self):
        self.samples: list[float] = []

    def sample(self) -> float:
        ms, _ = reference_once()
        self.samples.append(ms)
        return ms

    def warm(self, k: int = 5) -> None:
        for _ in range(k):
            self.sample()

    def add(self, ms: float) -> None:
        """A repetition measured elsewhere (a worker process) in this run."""
        self.samples.append(float(ms))

    def result(self) -> dict:
        """The run's index: ``ref_ms`` (mean of all repetitions, see the module docstring)
        and its spread (median, p10, p90, min)."""
        s = sorted(self.samples)
        if not s:
            return {'version': REF_VERSION, 'ref_ms': None, 'repetitions': 0}
        q = statistics.quantiles(s, n=10) if len(s) >= 2 else [s[0]] * 9
        return {'version': REF_VERSION, 'ref_ms': float(statistics.fmean(s)),
                'median_ms': float(statistics.median(s)), 'p10_ms': float(q[0]),
                'p90_ms': float(q[-1]), 'min_ms': float(s[0]), 'repetitions': len(s)}


def in_ref(ms, ref_ms):
    """A time in multiples of the reference ("x ref"); None when either is unknown."""
    if ms is None or not ref_ms:
        return None
    return float(ms) / float(ref_ms)


def relative_summary(summary: dict, ref_ms) -> dict:
    """Every ``*_ms_*`` figure of a bench summary as a multiple of ``ref_ms`` (``*_ref_*``)."""
    return {k.replace('_ms_', '_ref_'): in_ref(v, ref_ms) for k, v in summary.items()
            if '_ms_' in k and (v is None or isinstance(v, (int, float)))}


def format_index(index: dict | None) -> str:
    """One line for the bench table: the index of this run and how to read the "x ref" figures."""
    if not index or not index.get('ref_ms'):
        return 'speed index: not measured'
    return (f"speed index: ref {index['ref_ms']:.2f} ms (p10-p90 {index['p10_ms']:.2f}-"
            f"{index['p90_ms']:.2f}, {index['repetitions']} repetitions, v{index['version']}); "
            'times in x ref compare across machines and days (docs/benchmark.md)')


# ---------------------------------------------------------------- phase profile (--profile)
def _pct(vals, q):
    return float(np.percentile(vals, q)) if vals else None


def profile_summary(cases: list[dict], ref_ms) -> dict:
    """Per phase over the cases that carry a ``profile``: median / p95 / mean [ms], the share of
    the summed time, and the median in x ref; counters as means."""
    rows = [c['profile'] for c in cases if c.get('profile')]
    phases = sorted({k for r in rows for k in r.get('phases_ms', {})}, key=_phase_order)
    total = sum(sum(r.get('phases_ms', {}).values()) for r in rows) or None
    out = {}
    for k in phases:
        vals = [r['phases_ms'][k] for r in rows if k in r.get('phases_ms', {})]
        out[k] = {'median_ms': _pct(vals, 50), 'p95_ms': _pct(vals, 95),
                  'mean_ms': float(np.mean(vals)), 'share': sum(vals) / total if total else None,
                  'median_ref': in_ref(_pct(vals, 50), ref_ms), 'cases': len(vals)}
    counters = sorted({k for r in rows for k in r.get('counters', {})})
    return {'phases': out, 'counters': {k: float(np.mean([r['counters'][k] for r in rows
                                                          if k in r.get('counters', {})]))
                                        for k in counters}, 'cases': len(rows)}


_ORDER = ('topology_preprocess', 'topology_initialise', 'topology_chain', 'topology_refit',
          'topology_descent', 'topology_rescore', 'topology_other', 'topology_report',
          'lanes_initialise', 'lanes_mcmc', 'lanes_refine', 'lanes_other')


def _phase_order(k):
    return (_ORDER.index(k) if k in _ORDER else len(_ORDER), k)


def format_profile(profile: dict, mode: str) -> str:
    """The --profile table: one row per phase."""
    lines = [f"profile  mode={mode}  cases={profile['cases']}",
             f"{'phase':20s} {'median ms':>10s} {'p95 ms':>9s} {'mean ms':>9s} {'share':>7s} {'x ref':>7s}"]
    f = (lambda v, d=1: '-' if v is None else f'{v:.{d}f}')
    for k, r in profile['phases'].items():
        share = '-' if r['share'] is None else f"{100 * r['share']:.1f} %"
        lines.append(f"{k:20s} {f(r['median_ms']):>10s} {f(r['p95_ms']):>9s} {f(r['mean_ms']):>9s} "
                     f"{share:>7s} {f(r['median_ref'], 2):>7s}")
    if profile['counters']:
        lines.append('counters (mean per case): ' + ', '.join(
            f'{k} {v:.2f}' for k, v in profile['counters'].items()))
    return '\n'.join(lines)
