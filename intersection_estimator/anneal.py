"""Metropolis-Hastings with simulated annealing (paper §II, Algorithm 1; Kirkpatrick 1983).

A proposal ``I'`` from a move is accepted with probability
``min(1, [P(I'|Z) / P(I|Z)]^(1/T) * q(I|I') / q(I'|I))``; the temperature follows a
geometric schedule from ``t_start`` to ``t_end`` over ``anneal_samples`` steps and then
stays at ``t_end``. The best (MAP) state seen is kept. The loop itself is compiled
(:func:`_kernels.run_chain`); this module holds the schedule and the chain container.
"""

from __future__ import annotations

from dataclasses import dataclass
import numpy as np

from . import _kernels as K

__all__ = ['temperatures', 'Chain', 'advance', 'acceptance_rates']


def temperatures(k0: int, n: int, t_start: float, t_end: float, anneal_samples: int) -> np.ndarray:
    """Temperatures of steps ``k0 .. k0+n-1`` (geometric, then constant ``t_end``)."""
    k = np.minimum(np.arange(k0, k0 + n, dtype=np.float64), anneal_samples)
    frac = k / max(anneal_samples, 1)
    return t_start * (t_end / t_start) ** frac


@dataclass(eq=False)
class Chain:
    """Chain state: current and best packed state, cached per-arm likelihood columns."""

    __slots__ = ('S', 'C', 'll', 'lp', 'best_S', 'best_lpost', 'step', 'stats')

    S: np.ndarray
    C: np.ndarray
    ll: float
    lp: float
    best_S: np.ndarray
    best_lpost: float
    step: int
    stats: np.ndarray


def advance(chain: Chain, n: int, temps: np.ndarray, seed: int, P, logPA, logPn, arm_const,
            logqn, cumqn, obs) -> None:
    """Draw ``n`` samples in place (one compiled call)."""
    ll, lp, best = K.run_chain(chain.S, chain.C, chain.ll, chain.lp, chain.best_S,
                               chain.best_lpost, P, logPA, logPn, arm_const, logqn, cumqn,
                               *obs.kernel_args(), n, temps, seed, chain.stats)
    chain.ll, chain.lp, chain.best_lpost = float(ll), float(lp), float(best)
    chain.step += n


def acceptance_rates(stats: np.ndarray) -> dict:
    """Per move: (proposed, accepted)."""
    return {name: (int(stats[2 * i]), int(stats[2 * i + 1]))
            for i, name in enumerate(K.MOVE_NAMES)}

