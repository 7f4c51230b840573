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

Independent of completion order: drives are sorted by their id before anything is added,
so the floating-point sums are the same whichever task finished first.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import math

from .changes import ChangeConfig, DriveView, Finding, _logit

__all__ = ['FusedChange', 'FusedIntersection', 'fuse']


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


def _fuse_key(key: str, views: list[tuple[str, DriveView]]) -> FusedChange:
    first = _any(views, key)          # kind, arm, direction: the same in every drive (in the key)
    L, sup, con, unobs, passages = first.prior, [], [], [], 0.0
    lanes: set = set()
    extra: dict = {}
    for drive, v in views:
        f = next((f for f in v.findings + v.weak if f.key == key), None)
        if f is not None:
            L += f.log_lr
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
    ev = {'drives_showing': len(sup), 'drives_contradicting': len(con), 'drives_not_seeing': len(unobs),
          'passages': passages, 'log_odds': L}
    ev.update({f'mean_{k}': sum(x) / len(x) for k, x in sorted(extra.items())})
    if 'angle_deg' in first.evidence:      # where an added arm points (first drive showing it)
        ev['angle_deg'] = float(first.evidence['angle_deg'])
    ev['showing'] = sup
    return FusedChange(first.kind, key, 1.0 / (1.0 + math.exp(-min(max(L, -50.0), 50.0))), first.map_arm, first.direction,
                       sorted(lanes), ev)


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
        fused = [_fuse_key(k, vs) for k in keys]
        unobs = sorted(set.intersection(*(set(v.unobserved) for _, v in vs)))
        out[ident] = FusedIntersection(
            id=ident, drives=sorted({d for d, _ in vs}),
            changes=[c for c in fused if c.confidence > cfg.min_confidence],
            candidates=[c for c in fused if c.confidence <= cfg.min_confidence],
            unobserved=unobs, passages=float(sum(v.passages for _, v in vs)))
    return out
