"""Greedy descent at the end of the annealing schedule (beyond the paper).

A lane-count change moves the optimum of center, angles, gap and width too, so at a cold
temperature the chain rejects it although the pair of changes scores higher (raw
detections: in ~3/4 of the wrong lane counts the true counts win once center and gaps
follow). From the MAP state, :func:`descend` tries every candidate of :func:`candidates`:
one arm's lane counts changed by a step of :data:`DESCENT_STEPS` (that arm's gap and
width then set to the best grid point, :func:`.refit.refit_gap_width`), or one arm
removed -- and an arm added where trajectory parts are explained by no arm
(:mod:`.unexplained`, ``descent_add_support``; not in :func:`candidates`, made lazily
within the deadline). The lane candidates within
``descent_screen`` nats of the current state (the ``descent_top`` best of them if > 0),
every removal (an extra arm is only worse until its traffic moves to the neighbour) and
every added arm get ``descent_samples`` continuous moves at
``descent_temp`` (:func:`run_moves`), a share ``descent_focus`` of the arm moves on the
changed (or added) arm, in stages, dropped as soon as they fall behind; the best improvement is
kept, for up to ``descent_rounds`` rounds. Monotone in the posterior. Measured effect and
the choice of the screen: ``docs/tuning.md``.
"""

from __future__ import annotations

from dataclasses import dataclass
import math
import time

import numpy as np

from .mcmc import Posterior
from .moves import MOVE_NAMES, remove_arm_at
from .refit import refit_lane_candidates
from .state import HDR, NARMS, NIN, NOUT, STRIDE, Chain
from .unexplained import best_new_arm, unexplained_angles

__all__ = ['DESCENT_STEPS', 'DESCENT_CHECKS', 'Descent', 'descend', 'candidates', 'run_moves']

#: Lane-count steps (entering, leaving) of one arm tried by the descent: one side +-1, or
#: a lane moved across the median (the median line shifts by a lane width).
DESCENT_STEPS = ((1, 0), (-1, 0), (0, 1), (0, -1), (1, -1), (-1, 1))
#: Shares of ``descent_samples`` after which a descent run is screened (``descent_prune``).
DESCENT_CHECKS = (1 / 16, 1 / 8, 1 / 4, 3 / 8, 1 / 2, 3 / 4)


@dataclass
class Descent:
    """Outcome of :func:`descend`: the best state, its log posterior, samples drawn."""

    S: np.ndarray
    lpost: float
    samples: int


def candidates(S: np.ndarray, cfg, post: Posterior):
    """Yield ``(S2, k)``: ``S`` with arm ``k``'s lane counts changed by a step of
    :data:`DESCENT_STEPS` (within [min_lanes, max_lanes]), and ``(S2, -1)``: ``S`` with
    arm ``k`` removed (while more than ``min_arms`` arms)."""
    n = int(S[NARMS])
    for k in range(n):
        i = HDR + k * STRIDE
        for di, do in DESCENT_STEPS:
            ni, no = S[i + NIN] + di, S[i + NOUT] + do
            if cfg.min_lanes <= min(ni, no) and max(ni, no) <= cfg.max_lanes:
                S2 = S.copy()
                S2[i + NIN], S2[i + NOUT] = ni, no
                yield S2, k
        if n > cfg.min_arms:
            S2 = S.copy()
            remove_arm_at(S, S2, post.t.P, post.t.logqn, k)
            yield S2, -1


def run_moves(S: np.ndarray, cfg, post: Posterior, rng: np.random.Generator, ref=None,
              focus: int = -1):
    """``descent_samples`` continuous moves at ``descent_temp`` from ``S``; with ``focus``
    >= 0 a share ``descent_focus`` of the arm moves goes to that arm. With ``ref`` (the
    best log posterior so far) the moves run in stages ending at :data:`DESCENT_CHECKS` of
    them, and stop after a stage whose best is more than ``descent_prune`` x (share of
    moves left)^2 nats below ``ref``. Returns ``(best state, its log posterior, samples)``."""
    m = cfg.descent_samples
    C = post.columns()
    ll, _ = post.loglik(S, C)
    lp = post.log_prior(S)
    ch = Chain(S=S.copy(), C=C, ll=ll, lp=lp, best_S=S.copy(), best_lpost=ll + lp, step=0,
               stats=np.zeros(2 * len(MOVE_NAMES), np.int64))
    P = post.t.P_polish if focus < 0 else post.t.focused(focus, cfg.descent_focus)
    ends = [m] if ref is None else sorted({max(1, round(m * f)) for f in DESCENT_CHECKS} | {m})
    for end in ends:
        n = end - ch.step
        if n <= 0:
            continue
        post.advance(ch, n, np.full(n, cfg.descent_temp), int(rng.integers(0, 2 ** 31 - 1)), P)
        if end < m and ch.best_lpost < ref - cfg.descent_prune * (1.0 - end / m) ** 2:
            break
    return ch.best_S, ch.best_lpost, ch.step


def _lane_steps(S, k, cfg):
    """The lane counts (entering, leaving) of arm ``k`` after each step of
    :data:`DESCENT_STEPS` within [min_lanes, max_lanes], in that order."""
    i = HDR + k * STRIDE
    out = []
    for di, do in DESCENT_STEPS:
        ni, no = S[i + NIN] + di, S[i + NOUT] + do
        if cfg.min_lanes <= min(ni, no) and max(ni, no) <= cfg.max_lanes:
            out.append((int(ni), int(no)))
    return out


def _screened(S, L, cfg, post, deadline: float = math.inf):
    """The lane candidates of ``S`` worth moves (best first), every removal and every
    added arm: the candidates of :func:`candidates`, the lane ones of each arm refitted in
    one grid pass (:func:`.refit.refit_lane_candidates`, the numbers of one
    ``refit_gap_width`` each); an arm where traffic is unexplained
    (:mod:`.unexplained`), the moves focused on it -- made one by one as they are asked
    for, none after ``deadline`` (a refit over a dozen angles each)."""
    lanes, removals = [], []
    _, C = post.loglik(S)
    for k in range(int(S[NARMS])):
        steps = _lane_steps(S, k, cfg)
        for S2, L2 in (refit_lane_candidates(post, S, k, steps, C) if steps else ()):
            if L2 >= L - cfg.descent_screen:
                lanes.append((L2, len(lanes), S2, k))
        if int(S[NARMS]) > cfg.min_arms:
            S2 = S.copy()
            remove_arm_at(S, S2, post.t.P, post.t.logqn, k)
            removals.append(S2)
    lanes.sort(key=lambda x: (-x[0], x[1]))
    top = lanes[:cfg.descent_top] if cfg.descent_top > 0 else lanes
    yield from [(x[2], x[3]) for x in top] + [(S2, -1) for S2 in removals]
    n = int(S[NARMS])
    for phi in unexplained_angles(S, post, cfg, C):
        if time.perf_counter() >= deadline:
            return
        S2 = best_new_arm(S, phi, post, cfg, C)
        if S2 is not None:
            yield S2, n


def descend(S0: np.ndarray, cfg, post: Posterior, rng: np.random.Generator,
            deadline: float = math.inf) -> Descent:
    """The descent from ``S0`` (see the module docstring) on ``post``; ``cfg`` a
    :class:`.config.TopologyConfig`; candidates stop at ``deadline`` (perf_counter
    time). ``descent_rounds == 0`` or no observations: ``S0`` unchanged, no samples."""
    if cfg.descent_rounds == 0 or len(post.obs) == 0:
        return Descent(S0.copy(), -math.inf, 0)
    S, L, drawn = run_moves(S0, cfg, post, rng)
    for _ in range(cfg.descent_rounds):
        best = None
        for S2, k in _screened(S, L, cfg, post, deadline):
            if time.perf_counter() >= deadline:
                break
            S3, L3, n = run_moves(S2, cfg, post, rng, L, k)
            drawn += n
            if L3 > L + 1e-9:
                best, L = S3, L3
        if best is None:
            break
        S = best
    return Descent(S, L, drawn)
