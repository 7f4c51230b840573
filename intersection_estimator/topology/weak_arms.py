"""Arms that the posterior nearly pays for (beyond the paper).

The MAP state (paper §II-D) leaves out an arm whose traffic does not pay for the arm's
prior: on real junctions that is often a road one vehicle drove out of (or into) in the
recorded window. Its trajectory part is then explained by no arm (below the clutter
floor) and the state with the arm, refitted, scores only a little lower: on the SUMO dev
seeds 0-199 (tracked) the nine candidates within 1.3 nats of the MAP all lie on a true arm
the MAP lacks (seven of them driven by one vehicle), the first candidate that lies on no
true arm is 1.46 nats behind, and on Table I 0-599 none is closer than 1.56 nats
(docs/real_junctions.md, "Arms one vehicle drove").

:func:`add_weak_arms` adds, strongest first, the arms of :func:`.unexplained.best_new_arm`
over groups of unexplained trajectory parts of at least ``weak_arm_support`` vehicle
passages, while the state with the arm is at most ``weak_arm_nats`` below the state
without it, the new arm explains that many passages itself and as many tracks drive it
across the line ``weak_arm_box`` (25 m) out on its axis (:func:`box_tracks`: a road leads
to the junction; without the line, false tracks 45-60 m out made two Table I arms in 1000
cases). It runs on the reported
state, after the arms without support were dropped (:mod:`.support`); an added arm's
confidence is that of its passages (one vehicle: 0.28). Only windows with trajectories:
radar and heading voxels of one vehicle are too coarse to place a road.
Off: ``TopologyConfig.weak_arm_nats = 0``.
"""

from __future__ import annotations

import numpy as np

from .mcmc import Posterior
from .side_by_side import REACH, Tracks, aligned, arm_frame
from .state import GAP, HDR, NARMS, NIN, NOUT, STRIDE, WID
from .unexplained import arm_support, best_new_arm, unexplained_angles

__all__ = ['add_weak_arms', 'box_tracks', 'near_tracks']


def _on_arm(S: np.ndarray, k: int, tr: Tracks, outside: float, reach: float = REACH):
    """``(on, s, n)``: the rows of ``tr`` that head along arm ``k`` of ``S`` (within
    :data:`.side_by_side.ALIGN_DEG`), beside its lanes (within ``reach`` lane widths beyond
    them, by default :data:`.side_by_side.REACH`) and at least ``outside`` metres out on its
    axis; ``s`` every row's distance out; ``n`` the number of tracks (the length of a
    per-track count)."""
    i0 = HDR + k * STRIDE
    s, t, c = arm_frame(S, k, tr.xy, tr.h)
    band = 0.5 * S[i0 + GAP] + (max(S[i0 + NIN], S[i0 + NOUT]) + reach) * S[i0 + WID]
    on = aligned(c) & (np.abs(t) <= band) & (s >= outside)
    return on, s, (int(tr.tix[-1]) + 1 if len(tr.tix) else 0)


def box_tracks(S: np.ndarray, k: int, tr: Tracks, outside: float, box: float) -> int:
    """Tracks that drove along arm ``k`` of ``S`` across the line ``box`` metres out on its
    axis: rows on the arm (:func:`_on_arm`) both between ``outside`` and ``box`` metres out
    and beyond. The road leads to the junction: a false track far out does not cross, nor
    does a vehicle of a neighbouring arm (another heading)."""
    on, s, n = _on_arm(S, k, tr, outside)
    near = np.bincount(tr.tix[on & (s <= box)], minlength=n) > 0
    far = np.bincount(tr.tix[on & (s > box)], minlength=n) > 0
    return int((near & far).sum())


def near_tracks(S: np.ndarray, k: int, tr: Tracks, outside: float, box: float,
                min_rows: int, reach: float = REACH) -> int:
    """Tracks with at least ``min_rows`` rows on arm ``k`` of ``S`` (:func:`_on_arm`, within
    ``reach`` lane widths beside its lanes) between ``outside`` and ``box`` metres out:
    vehicles that drove the arm next to the box, also where the road comes into view only
    there (a side road behind a corner)."""
    on, s, n = _on_arm(S, k, tr, outside, reach)
    return int((np.bincount(tr.tix[on & (s <= box)], minlength=n) >= min_rows).sum())


def add_weak_arms(post: Posterior, S: np.ndarray, lpost: float, cfg,
                  tracks: Tracks) -> tuple[np.ndarray, float]:
    """``(S, log posterior)`` with the arms added that the posterior nearly pays for
    (module doc) given the window's ``tracks``; ``cfg`` a :class:`.config.TopologyConfig`.
    The same array ``S`` when ``weak_arm_nats`` is 0 or no candidate qualifies."""
    if cfg.weak_arm_nats <= 0 or len(post.obs) == 0:
        return S, lpost
    while True:
        _, C = post.loglik(S)                 # S's columns, shared by every candidate
        best = None
        for phi in unexplained_angles(S, post, cfg, C, max_angles=3,
                                      min_support=cfg.weak_arm_support):
            S2 = best_new_arm(S, phi, post, cfg, C)
            if S2 is None:
                continue
            ll2, C2 = post.loglik(S2)
            L2 = ll2 + post.log_prior(S2)
            k = int(S2[NARMS]) - 1
            if (L2 >= lpost - cfg.weak_arm_nats and (best is None or L2 > best[1])
                    and arm_support(post, S2, cfg.clutter_floor, C2)[k] >= cfg.weak_arm_support
                    and box_tracks(S2, k, tracks, cfg.part_outside, cfg.weak_arm_box)
                    >= cfg.weak_arm_support):
                best = (S2, L2)
        if best is None:
            return S, lpost
        S, lpost = best
