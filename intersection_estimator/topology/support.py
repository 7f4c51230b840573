"""The reported estimate: arms without support left out (beyond the paper).

The clutter floor of the likelihood lets one or two aligned trajectory parts (turning
traffic, a false track) pay for an arm's prior. :func:`reported` drops, weakest first and
down to ``min_arms``, the arms of the MAP state that explain fewer than
``min_arm_support`` vehicle passages (:func:`arm_support`: trajectory parts; radar /
heading voxels count detections per passage, ``ObservationSet.passages``). The default
1.5 keeps an arm that one vehicle entered and another left (real-junction traffic in short
windows, docs/tuning.md) and drops a single aligned part. An arm's confidence is
``1 - exp(-passages / 3)``.

In windows with trajectories, arms that the posterior nearly pays for are then added
(:mod:`.weak_arms`: a road one vehicle drove, its part explained by no arm). With the
window's trajectories the lane counts of the state left are then set by what
overlapping trajectory parts show side by side (:mod:`.side_by_side`: at least the lanes
shown, at most one more once enough parts were compared, one lane where no two parts
overlap), the changed arms' gap, width
and offset refitted; the log posterior reported is that of the changed state.
"""

from __future__ import annotations

import numpy as np

from .mcmc import Posterior
from .moves import remove_arm_at
from .side_by_side import Tracks, fit_counts
from .state import NARMS
from .unexplained import arm_support
from .weak_arms import add_weak_arms, near_tracks

__all__ = ['arm_support', 'drop_empty_arms', 'reported']


def reported(post: Posterior, S: np.ndarray, lpost: float, cfg, tracks: Tracks | None = None):
    """``(state, confidence per arm, log posterior)`` of the estimate reported for the MAP
    state ``S`` of log posterior ``lpost``; ``cfg``: a :class:`.config.TopologyConfig`.
    With the window's ``tracks`` arms the posterior nearly pays for are added
    (:mod:`.weak_arms`) and the lane counts are set by what the traffic shows side by side
    (:mod:`.side_by_side`)."""
    S = S.copy()
    sup = arm_support(post, S, cfg.clutter_floor)
    if len(post.obs):
        S2, sup = _leave_out(post, S, sup, cfg, lambda S, sup, k: sup[k] < cfg.min_arm_support)
        if S2 is not S:
            S, lpost = S2, post(S2)
    if tracks is not None:
        S2, lpost = add_weak_arms(post, S, lpost, cfg, tracks)
        if S2 is not S:                       # an arm was added
            S, sup = S2, arm_support(post, S2, cfg.clutter_floor)
    if len(post.obs):
        S, raised = fit_counts(post, S, tracks, cfg)
        if raised is not None:
            lpost = raised
            sup = arm_support(post, S, cfg.clutter_floor)
    if tracks is not None and cfg.empty_arm_drop and len(post.obs):
        S2, sup2 = drop_empty_arms(post, S, sup, cfg, tracks)
        if S2 is not S:
            S, sup, lpost = S2, sup2, post(S2)
    return S, 1.0 - np.exp(-sup / 3.0), lpost


def drop_empty_arms(post: Posterior, S: np.ndarray, sup: np.ndarray, cfg, tracks: Tracks):
    """``(S, support)`` without the arms that, their lane counts set, explain fewer than
    ``weak_arm_support`` vehicle passages and along which fewer than as many tracks drove
    between ``part_outside`` and ``weak_arm_box`` (:func:`.weak_arms.near_tracks`, parts of
    ``min_part_points`` rows within ``empty_arm_reach`` lane widths beside the arm's lanes:
    farther out a track drives another road beside it, docs/real_junctions.md "Stop 56").
    Such an arm is the MAP's many-lane side that reached onto a curved neighbouring
    approach's traffic; once :mod:`.side_by_side` set its counts, nothing is left on it.
    Weakest first, down to ``min_arms``; the same ``S`` when none is left out."""
    bar = cfg.weak_arm_support
    return _leave_out(post, S, sup, cfg, lambda S, sup, k: sup[k] < bar and near_tracks(
        S, k, tracks, cfg.part_outside, cfg.weak_arm_box, cfg.min_part_points,
        cfg.empty_arm_reach) < bar)


def _leave_out(post: Posterior, S: np.ndarray, sup: np.ndarray, cfg, out):
    """``(S, support)`` without the arms ``out(S, support, k)`` names, the weakest first
    (support recomputed after each), down to ``min_arms``; the same ``S`` when none is left
    out."""
    while int(S[NARMS]) > cfg.min_arms:
        cand = [k for k in range(int(S[NARMS])) if out(S, sup, k)]
        if not cand:
            break
        S2 = S.copy()
        remove_arm_at(S, S2, post.t.P, post.t.logqn, min(cand, key=lambda k: sup[k]))
        S, sup = S2, arm_support(post, S2, cfg.clutter_floor)
    return S, sup
