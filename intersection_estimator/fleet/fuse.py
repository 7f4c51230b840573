"""Several drives' views of one mapped intersection -> its changes (issue 17, "fused").

Each drive is an independent vote on every change any drive showed (keyed by
:attr:`Finding.key`). A drive showing the change adds its log likelihood ratio
(``logit(p)`` with ``p`` its finding's confidence; for absences the passages it saw, also
the drives' ``weak`` findings below 0.5, so that absence evidence adds up; the kind's prior
log odds are added once); a drive that saw the element without the change subtracts ``logit(q)`` with
``q`` = :meth:`DriveView.contradiction` (how well it saw it; <= 0.5 counts nothing, e.g. a
drive that simply took no vehicle through a new turn does not speak against it). The sum
is the log odds of the change (naive Bayes over independent passes), so
evidence adds up and confidence grows with every independent drive that shows it.
A change is reported when its fused confidence is above ``min_confidence`` (log odds 0 =
no evidence either way is not a change).

Absences share one share (:func:`shared_share`): how often drivers take a lane is a habit
of the junction (a lane beside the one everybody takes for their turn stays empty in every
drive), not a fresh draw per drive. Summed as independent, the drives' absence evidence
grows without bound for such a lane, and the false "lane removed" claims of an unchanged map
grew with the drives (docs/fleet.md, "Fusion: drives share one share of a lane"). The
drives' passages are pooled under the over-dispersed share instead, and the summed evidence
is scaled by what that pooling keeps of it; with exact shares (drivers spread evenly over
the lanes) it keeps everything.

Independent of completion order: drives are sorted by their id before anything is added,
so the floating-point sums are the same whichever task finished first.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import math

import numpy as np

from .changes import ChangeConfig, DriveView, Finding, _absence_llr, _logit, _mixed

__all__ = ['FusedChange', 'FusedIntersection', 'fuse', 'shared_share']


@dataclass
class FusedChange:
    kind: str
    key: str
    confidence: float
    map_arm: int
    direction: str
    map_lanes: list
    evidence: dict


@dataclass
class FusedIntersection:
    id: str
    drives: list[str]
    changes: list[FusedChange]
    candidates: list[FusedChange]          # shown by some drive, outvoted by the others
    unobserved: list[int] = field(default_factory=list)
    passages: float = 0.0


def _fuse_key(key: str, views: list[tuple[str, DriveView]], cfg: ChangeConfig) -> FusedChange:
    first = _any(views, key)          # kind, arm, direction: the same in every drive (in the key)
    L, sup, con, unobs, passages = first.prior, [], [], [], 0.0
    lanes: set = set()
    extra: dict = {}
    shown = []
    for drive, v in views:
        f = next((f for f in v.findings + v.weak if f.key == key), None)
        if f is not None:
            shown.append(f)
            sup.append(drive)
            passages += float(f.evidence.get('passages', 0.0))
            lanes.update(f.map_lanes)
            for k in ('offset_m', 'lanes_estimated'):
                if k in f.evidence:
                    extra.setdefault(k, []).append(float(f.evidence[k]))
        else:
            q = v.contradiction(first)
            (con if q > 0.5 else unobs).append(drive)
            L -= _logit(q) if q > 0.5 else 0.0
    keep = shared_share(shown, cfg)
    L += keep * sum(f.log_lr for f in shown)
    ev = {'drives_showing': len(sup), 'drives_contradicting': len(con), 'drives_not_seeing': len(unobs),
          'passages': passages, 'log_odds': L}
    if keep < 1.0:
        ev['absence_kept'] = keep
    ev.update({f'mean_{k}': sum(x) / len(x) for k, x in sorted(extra.items())})
    if 'angle_deg' in first.evidence:      # where an added arm points (first drive showing it)
        ev['angle_deg'] = float(first.evidence['angle_deg'])
    ev['showing'] = sup
    return FusedChange(first.kind, key, 1.0 / (1.0 + math.exp(-min(max(L, -50.0), 50.0))), first.map_arm, first.direction,
                       sorted(lanes), ev)


def shared_share(shown: list[Finding], cfg: ChangeConfig) -> float:
    """Share (<= 1) of the drives' summed absence evidence that one share of the element,
    shared by all drives, keeps (module doc): ``-ln E[(1 - f)^(sum P_i)]`` over the sum of
    the drives' ``-ln E[(1 - f_i)^P_i]`` (:func:`.changes._absence_llr`), both at the drives'
    passage-weighted share and off-lane share (the ratio is the sharing alone), under the
    spread of ``f`` that all drives together show: their lane-choice concentration posteriors
    (:class:`.changes.LaneChoice`; the config's ``share_concentration`` without one) pooled
    (the concentration too is a habit of the junction; flat prior: their product). 1 for
    one drive, for findings that are no absence and with exact shares. A drive that shows the
    absence with no passage adds nothing to either sum (its term is 0), so it does not stop the
    others' pooling."""
    if any('share' not in f.evidence for f in shown):
        return 1.0
    ab = [f for f in shown if f.evidence.get('passages', 0.0) > 0.0]
    if len(ab) < 2:
        return 1.0
    P = np.array([float(f.evidence['passages']) for f in ab])
    share = np.array([float(f.evidence['share']) for f in ab])
    off = np.array([float(f.evidence.get('lane_off_share', 0.0)) for f in ab])
    post = _pooled_posterior([f.evidence.get('lane_choice_post') or ((cfg.share_concentration, 1.0),)
                              for f in ab])
    if all(k <= 0.0 for k, _ in post):
        return 1.0                        # exact shares: the drives' empty lanes are independent
    s_all, o_all = float(P @ share / P.sum()), float(P @ off / P.sum())
    own = sum(_mixed(post, lambda k, p=p: _absence_llr(p, s_all, cfg, k, o_all)) for p in P)
    pooled = _mixed(post, lambda k: _absence_llr(float(P.sum()), s_all, cfg, k, o_all))
    keep = pooled / own if own > 0.0 else 1.0
    return 1.0 if keep > 1.0 - 1e-9 else keep


def _pooled_posterior(posts: list) -> tuple:
    """``[(k, w), ...]`` per drive over one grid (flat prior) -> the posterior of all drives
    together: the product of the drives' weights (a point a drive dropped as negligible,
    1e-9), normalised."""
    grid = sorted({float(k) for post in posts for k, _ in post})
    logw = np.zeros(len(grid))
    for post in posts:
        d = {float(k): w for k, w in post}
        logw += np.log([max(d.get(k, 0.0), 1e-9) for k in grid])
    w = np.exp(logw - logw.max())
    w /= w.sum()
    return tuple((k, float(x)) for k, x in zip(grid, w) if x > 1e-6)


def _any(views, key) -> Finding:
    return next(f for _, v in views for f in v.findings + v.weak if f.key == key)


def fuse(views: list[tuple[str, DriveView]], cfg: ChangeConfig = ChangeConfig()) -> dict[str, FusedIntersection]:
    """``[(drive id, view), ...]`` (any order) -> ``{mapped intersection id: FusedIntersection}``."""
    by: dict = {}
    for drive, v in sorted(views, key=lambda dv: (dv[1].intersection, dv[0])):
        by.setdefault(v.intersection, []).append((drive, v))
    out = {}
    for ident, vs in sorted(by.items()):
        # within a drive, its several views of one intersection (passes) count as one drive each
        keys = sorted({f.key for _, v in vs for f in v.findings + v.weak})
        fused = [_fuse_key(k, vs, cfg) for k in keys]
        unobs = sorted(set.intersection(*(set(v.unobserved) for _, v in vs)))
        out[ident] = FusedIntersection(
            id=ident, drives=sorted({d for d, _ in vs}),
            changes=[c for c in fused if c.confidence > cfg.min_confidence],
            candidates=[c for c in fused if c.confidence <= cfg.min_confidence],
            unobserved=unobs, passages=float(sum(v.passages for _, v in vs)))
    return out
