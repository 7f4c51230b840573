"""Cost model of the topology sampler against its limit (issue 18, item 3).

Per sample of the chain (paper §II, Algorithm 1) and of the descent, the incremental
likelihood (paper §II-C2, :func:`.mcmc.run_chain`) does two kinds of per-observation work:
it computes per-arm *density entries* (``exp`` of an energy, :func:`.likelihood.arm_column`)
and recomputes *log terms* ``w log(max density + floor)``. The kernel counts what it does
(:data:`.mcmc.WORK_FIELDS`); an audited replay of the same case (same seed, so the same
samples) counts what a move must do at least: the entries that are nonzero under the old or
the new state (every other entry is 0 before and after, beyond the energy cut) and the log
terms whose best density changed.

A plain compiled loop over the same observations, doing the same per-observation arithmetic
without the sampler (:func:`plain_densities`: the sampler's own density kernel in a bare
loop; :func:`plain_logs`), prices an entry at ``a``
ns and a log term at ``b`` ns. Then, for a phase that took ``T`` with ``E`` entries and
``L`` log terms done and ``E*``, ``L*`` needed:

* ``x plain = T / (a E + b L)``: the sampler's overhead over a plain loop doing its work
  (proposals, bookkeeping, Python between the compiled calls);
* ``x limit = T / (a E* + b L*)``: how far it is from doing only the work a move needs.

Counts are exact (the test compares them with a brute-force count); the times come from one
run and are never asserted in a test.
"""

from __future__ import annotations

import math
import time

import numpy as np
from numba import njit

from .likelihood import arm_column_into
from .mcmc import WORK_FIELDS, W_ENTRIES, W_LOGS, W_MUST_ENTRIES, W_MUST_LOGS, W_VISITS
from .state import NARMS, P_FLOOR

__all__ = ['plain_densities', 'plain_logs', 'plain_prices', 'case_cost', 'summarise',
           'format_cost']

PHASES = ('chain', 'descent')


@njit(cache=True)
def plain_densities(S, P, ox, oy, hx, hy, has_o, dcls, isp, isa, reps):
    """``reps`` x every arm's density of every observation (the closest lane, paper eq. for
    P(z_i|I)): the sampler's own kernel :func:`.likelihood.arm_column_into` called in a plain
    loop, scratch made up front, no bookkeeping; returns the densities' sum (so the work is
    not optimised away)."""
    acc = 0.0
    n = ox.shape[0]
    out = np.empty(n)
    energy = np.empty(n)
    for _ in range(reps):
        for k in range(int(S[NARMS])):
            arm_column_into(S, k, P, ox, oy, hx, hy, has_o, dcls, isp, isa, out, energy)
            for i in range(n):
                acc += out[i]
    return acc


@njit(cache=True, fastmath=True)
def plain_logs(M, wts, floor, reps):
    """``reps`` x the log term ``w log(M + floor)`` of every observation (paper §II-C2 with
    the clutter floor), in one plain loop; returns their sum."""
    acc = 0.0
    for _ in range(reps):
        for i in range(M.shape[0]):
            acc += wts[i] * math.log(M[i] + floor)
    return acc


def _ns_per_item(fn, args, items: int, min_s: float = 2e-3) -> float:
    """ns per item of ``fn(*args, reps)``: repetitions doubled until a call takes ``min_s``;
    the best of three such calls."""
    if items == 0:
        return math.nan
    fn(*args, 1)
    reps = 1
    while True:
        t0 = time.perf_counter()
        fn(*args, reps)
        dt = time.perf_counter() - t0
        if dt >= min_s or reps >= 1 << 20:
            break
        reps *= 2
    best = dt
    for _ in range(2):
        t0 = time.perf_counter()
        fn(*args, reps)
        best = min(best, time.perf_counter() - t0)
    return 1e9 * best / (reps * items)


def plain_prices(post, S) -> dict:
    """ns per density entry and per log term of the plain loops on ``post``'s observations,
    state ``S`` (its arms)."""
    args = post.obs.kernel_args()
    n, nobs = int(S[NARMS]), len(post.obs)
    ll, C = post.loglik(S)
    M = C[:n].max(axis=0) if n else np.zeros(nobs)
    return {'ns_per_entry': _ns_per_item(plain_densities, (S, post.t.P, *args[:8]), n * nobs),
            'ns_per_log': _ns_per_item(plain_logs, (M, args[8], float(post.t.P[P_FLOOR])), nobs)}


def _estimator(dets, mode: str, samples: int, seed: int, audit: bool):
    """The topology step of ``pipeline.estimate(dets, mode=mode, topology_samples=samples,
    seed=seed)`` (same configuration, same random stream), run with or without the audit."""
    from ..pipeline import _seeds, in_mode
    from .config import TopologyConfig
    from .estimator import TopologyEstimator
    est = TopologyEstimator(TopologyConfig(), _seeds(seed)[0], audit=audit)
    est.set_observations(in_mode(dets, mode))
    est.run(n_samples=samples)
    return est


def case_cost(dets, mode: str, samples: int, seed: int) -> dict:
    """Cost model of one bench case: per phase (chain, descent) the samples, the work done
    and needed (:data:`.mcmc.WORK_FIELDS`), the phase's time [ms] in a run without the audit,
    and the plain loops' prices on the final observations and MAP state."""
    est = _estimator(dets, mode, samples, seed, audit=False)
    audited = _estimator(dets, mode, samples, seed, audit=True)
    chain_samples = samples * est.n_chains
    out = {'observations': len(est.observations), 'arms': 0,
           'samples': {'chain': chain_samples,
                       'descent': est.samples_drawn - chain_samples}}
    for ph in PHASES:
        w, wa = est.work[ph], audited.work[ph]
        if not np.array_equal(w[:W_MUST_ENTRIES], wa[:W_MUST_ENTRIES]):
            raise RuntimeError(f'cost model: the audited replay took other samples ({ph})')
        out[ph] = {**{f: int(wa[j]) for j, f in enumerate(WORK_FIELDS)},
                   'ms': 1e3 * est.timings[ph]}
    if len(est.observations) and est.n_chains:
        S = est._best_chain().best_S
        out['arms'] = int(S[NARMS])
        out['plain'] = plain_prices(est._post, S)
    return out


def summarise(costs: list[dict]) -> dict:
    """The cost model over cases: per phase, work per sample (done / needed), ns per density
    entry and per visited observation, the plain loops' median prices, ``x_plain`` and
    ``x_limit`` (module docstring), from the sums over the cases."""
    costs = [c for c in costs if c and 'plain' in c]
    if not costs:
        return {'cases': 0}
    a = float(np.median([c['plain']['ns_per_entry'] for c in costs]))
    b = float(np.median([c['plain']['ns_per_log'] for c in costs]))
    out = {'cases': len(costs), 'plain_ns_per_entry': a, 'plain_ns_per_log': b,
           'observations_mean': float(np.mean([c['observations'] for c in costs])),
           'arms_mean': float(np.mean([c['arms'] for c in costs]))}
    for ph in PHASES:
        n = sum(c['samples'][ph] for c in costs)
        tot = {f: sum(c[ph][f] for c in costs) for f in WORK_FIELDS}
        ns = 1e6 * sum(c[ph]['ms'] for c in costs)
        done, need = a * tot['entries'] + b * tot['logs'], a * tot['must_entries'] + b * tot['must_logs']
        out[ph] = {'samples_per_case': n / len(costs),
                   **{f'{f}_per_sample': tot[f] / n if n else None for f in WORK_FIELDS},
                   'ms_per_case': ns / 1e6 / len(costs),
                   'ns_per_entry': ns / tot['entries'] if tot['entries'] else None,
                   'ns_per_visit': ns / tot['visits'] if tot['visits'] else None,
                   'x_plain': ns / done if done else None, 'x_limit': ns / need if need else None}
    return out


def format_cost(s: dict) -> str:
    """The cost-model rows of the ``bench --profile`` table."""
    if not s.get('cases'):
        return 'cost model: no cases'
    f = (lambda v, d=1: '-' if v is None else f'{v:.{d}f}')
    rows = [('samples per case', 'samples_per_case', 0),
            ('density entries computed / sample', 'entries_per_sample', 1),
            ('  ... that can change / sample', 'must_entries_per_sample', 1),
            ('log terms recomputed / sample', 'logs_per_sample', 1),
            ('  ... that change / sample', 'must_logs_per_sample', 1),
            ('observations visited / sample', 'visits_per_sample', 1),
            ('phase time per case [ms]', 'ms_per_case', 2),
            ('ns per density entry computed', 'ns_per_entry', 2),
            ('ns per visited observation', 'ns_per_visit', 2),
            ('x plain (time / plain loop, same work)', 'x_plain', 2),
            ('x limit (time / plain loop, needed work)', 'x_limit', 2)]
    lines = [f"cost model  cases={s['cases']}  observations {s['observations_mean']:.0f}  "
             f"arms {s['arms_mean']:.2f}  plain loop {s['plain_ns_per_entry']:.2f} ns / entry, "
             f"{s['plain_ns_per_log']:.2f} ns / log",
             f"{'':42s} {'chain':>10s} {'descent':>10s}"]
    for label, key, d in rows:
        lines.append(f'{label:42s} ' + ' '.join(f'{f(s[ph][key], d):>10s}' for ph in PHASES))
    return '\n'.join(lines)
