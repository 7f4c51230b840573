"""Arms proposed where traffic is left unexplained (beyond the paper).

The chain's add-arm move (paper Algorithm 1) draws a new arm's angle, offset, gap and
lane counts at random; for an arm with two or three vehicle passages, the draw must land
on its angle *and* on lane counts and an offset that fit, or the proposal is rejected --
at the cold end of the schedule that almost never happens. Yet the arm's trajectory parts
are there, explained by no arm (each below the clutter floor), and the state with the arm
scores higher: on SUMO dev seeds 11, 42, 47, 164 and 174 (tracked) the MAP state plus the
missing arm at its true angle, refitted (:func:`.refit.refit_arm`), wins by 1-4 nats.

This module turns those parts into candidates of the greedy descent (:mod:`.descent`):

1. :func:`unexplained_angles` -- the observations whose best arm density is at most the
   clutter floor (the arm-support rule of :mod:`.support`), each with the direction of
   the arm it would belong to: its travel axis (entering parts point at the center,
   leaving ones away; an offset arm's traffic keeps its direction where its position
   angle drifts), or its position angle when it has no orientation. Groups within
   :data:`HALF_WIDTH` of their strongest direction, strongest first, count when their
   vehicle passages reach ``descent_add_support`` and some angle near them keeps
   ``min_sep`` from every arm.
2. :func:`with_arm` -- the state with an arm added at an angle, its lane counts, gap,
   width and axis offset refitted on the grid (two sweeps of :func:`.refit.refit_arm`);
   :func:`best_new_arm` -- the best of them over angles within :data:`SEARCH` of a
   group's direction that keep ``min_sep``.

The descent then runs its continuous moves on each candidate, focused on the new arm,
and keeps it only if the posterior rises (monotone, as every descent candidate).
Off: ``TopologyConfig.descent_add_support = 0``.
"""

from __future__ import annotations

import math

import numpy as np

from ..model import direction_class
from .mcmc import Posterior
from .refit import refit_arm
from .state import ANG, CX, CY, HDR, MAXA, NARMS, NIN, NOUT, STRIDE, WID, arm_angles, wrap

__all__ = ['arm_support', 'unexplained_angles', 'with_arm', 'best_new_arm', 'SEARCH']

#: observations within this angle of a group's strongest direction join it [rad]
HALF_WIDTH = math.radians(12.0)
#: angles tried for a group's arm, around its direction [rad]: the parts' directions are
#: biased near the box (turning traffic, an offset axis), by 8-11 deg on SUMO seeds 42, 174,
#: and an arm 8 deg off its lanes scores below none
SEARCH = np.radians(np.arange(-12.0, 12.1, 2.0))


def arm_support(post: Posterior, S: np.ndarray, clutter_floor: float, C=None) -> np.ndarray:
    """Per arm of ``S``: the vehicle passages it explains best (above the clutter floor;
    what no arm explains is :func:`unexplained_angles`' to group). ``C``: the columns of
    ``S`` if at hand (:meth:`.mcmc.Posterior.loglik`)."""
    n = int(S[NARMS])
    if len(post.obs) == 0 or n == 0:
        return np.zeros(n)
    if C is None:
        _, C = post.loglik(S)
    Cn = C[:n]
    best = Cn.argmax(axis=0)
    good = Cn.max(axis=0) > clutter_floor
    return np.bincount(best[good], post.obs.passages[good], n)


def _directions(obs, center) -> np.ndarray:
    """Per observation: the direction of the arm it would belong to [rad] -- its travel
    axis pointed away from the center (orientation known), else its position angle."""
    pos = np.arctan2(obs.y - center[1], obs.x - center[0])
    # an entering part heads to the center: its arm points the other way
    sign = -direction_class(obs.x, obs.y, obs.hx, obs.hy, center)
    axis = np.arctan2(sign * obs.hy, sign * obs.hx)
    return np.where(obs.has_o, axis, pos)


def unexplained_angles(S: np.ndarray, post: Posterior, cfg, C=None, max_angles: int = 2,
                       min_support: float | None = None) -> list:
    """Directions [rad] of up to ``max_angles`` groups of unexplained observations of state
    ``S`` (module doc, step 1), strongest first; ``cfg`` a :class:`.config.TopologyConfig`
    (``clutter_floor``, ``descent_add_support``, ``min_sep_deg``, ``max_arms``). A group
    counts if some angle within :data:`SEARCH` of its direction keeps ``min_sep`` from
    every arm (its traffic's directions lean towards a neighbour arm near the box). ``C``:
    the columns of ``S`` if at hand (:meth:`.mcmc.Posterior.loglik`); ``min_support``: the
    passages a group needs (None: ``descent_add_support``)."""
    obs = post.obs
    n = int(S[NARMS])
    need = cfg.descent_add_support if min_support is None else min_support
    if len(obs) == 0 or need <= 0 or n >= min(cfg.max_arms, MAXA):
        return []
    if C is None:
        _, C = post.loglik(S)
    free = C[:n].max(axis=0) <= cfg.clutter_floor if n else np.ones(len(obs), bool)
    if not free.any():
        return []
    ang = _directions(obs, S[CX:CY + 1])[free]
    w = obs.passages[free]
    near = np.abs(wrap(ang[:, None] - ang[None, :])) <= HALF_WIDTH
    out = []
    left = np.ones(len(ang), bool)
    while len(out) < max_angles and left.any():
        mass = (near & left[None, :]) @ w * left
        j = int(np.argmax(mass))
        if mass[j] < need:
            break
        grp = near[j] & left
        phi = math.atan2(float(w[grp] @ np.sin(ang[grp])), float(w[grp] @ np.cos(ang[grp])))
        left &= ~grp
        if _valid_angles(S, phi, cfg, out).size:
            out.append(phi)
    return out


def _valid_angles(S, phi, cfg, extra=()) -> np.ndarray:
    """The angles of the :data:`SEARCH` grid around ``phi`` that keep ``min_sep`` from
    every arm of ``S`` and every angle of ``extra``."""
    grid = phi + SEARCH
    taken = np.r_[arm_angles(S), np.asarray(extra, float)]
    if taken.size == 0:
        return grid
    sep = np.abs(wrap(grid[:, None] - taken[None, :])).min(axis=1)
    return grid[sep >= math.radians(cfg.min_sep_deg)]


def with_arm(S: np.ndarray, phi: float, post: Posterior, lane_width: float, C=None):
    """``(S2, log posterior)``: ``S`` with an arm at angle ``phi`` appended (one lane each
    way, no gap, offset or bend), its lanes, gap, width and offset refitted (module doc,
    step 2). ``C``: the columns of ``S`` if at hand (not changed): only the new arm's
    column is computed then."""
    n = int(S[NARMS])
    S2 = S.copy()
    i = HDR + n * STRIDE
    S2[i:i + STRIDE] = 0.0
    S2[i + ANG], S2[i + NIN], S2[i + NOUT], S2[i + WID] = wrap(phi), 1, 1, lane_width
    S2[NARMS] = n + 1
    t = post.t
    if C is None:
        C2 = post.columns()
        post.loglik(S2, C2)
    else:
        C2 = C.copy()        # refit_arm computes the new arm's column itself
    for _ in range(2):
        refit_arm(S2, n, t.P, t.logPn, *post.obs.kernel_args(), C2, t.gaps, t.widths,
                  t.log_floor)
    return S2, post.from_columns(S2, C2)     # refit_arm left C2 the columns of S2


def best_new_arm(S: np.ndarray, phi: float, post: Posterior, cfg, C=None):
    """The best-scoring :func:`with_arm` over the valid angles of the :data:`SEARCH` grid
    around ``phi`` (module doc, step 2); None when no angle keeps ``min_sep``. ``C``: the
    columns of ``S`` if at hand."""
    if C is None:
        _, C = post.loglik(S)
    best, best_L = None, -math.inf
    for a in _valid_angles(S, phi, cfg):
        S2, L2 = with_arm(S, a, post, cfg.lane_width, C)
        if L2 > best_L:
            best, best_L = S2, L2
    return best
