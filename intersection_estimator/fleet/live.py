"""Live map-change detection: the node's current estimate against a prior map (issue 17).

The estimate of the intersection the ego is passing is one drive's view of it
(:func:`.changes.compare`), reported through the same fusion as the offline ``fleet``
(:func:`.fuse.fuse` of that one drive), so a change the node reports live is the change
``fleet`` reports for a bag of the same drive. ROS-free: the node publishes what
:meth:`LiveChanges.update` returns (``msg_adapters/map_changes.py``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from .changes import ChangeConfig, compare
from .corroborate import TrafficOnMap, drive_traffic
from .fuse import FusedChange, fuse
from .match import match_intersection
from .prior_map import MappedIntersection, load_prior_map

__all__ = ['LiveChanges', 'LiveMatch', 'LiveReport']

#: the drive id of the node's own estimate in the fusion (one drive)
LIVE = 'live'


@dataclass
class LiveReport:
    """The current estimate against the map: the mapped intersection it matched (None: none
    within the gate), the changes (confidence >= ``ChangeConfig.min_confidence``), the
    mapped arms no vehicle used, and the passages behind the estimate."""

    mapped: MappedIntersection | None
    changes: list[FusedChange] = field(default_factory=list)
    unobserved: list[int] = field(default_factory=list)
    passages: float = 0.0

    @property
    def intersection_id(self) -> str:
        return '' if self.mapped is None else self.mapped.id


@dataclass
class LiveMatch:
    """The first half of a comparison: the mapped intersection an estimate matched (None:
    none within the gate) and the drive's vehicles map-matched to it (None: not corroborated).
    The node runs the halves in two ticks (map matching is the larger one)."""

    mapped: MappedIntersection | None
    traffic: TrafficOnMap | None = None


class LiveChanges:
    """The prior map's intersections and the comparison of an estimate with them."""

    def __init__(self, mapped: list[MappedIntersection], cfg: ChangeConfig = ChangeConfig()):
        self.mapped, self.cfg = list(mapped), cfg

    @classmethod
    def load(cls, path, origin, projector: str = 'local', cfg: ChangeConfig = ChangeConfig()) -> 'LiveChanges':
        """From a Lanelet2 OSM map (``origin`` = (lat, lon) of the fixed frame); raises
        :class:`.prior_map.PriorMapError` (a ValueError) with a one-line reason."""
        return cls(load_prior_map(path, origin=origin, projector=projector), cfg)

    def match(self, intersection, window=None) -> LiveMatch:
        """The mapped intersection nearest an estimate (``model.Intersection``) and the
        vehicles of ``window`` (the observations the estimate rests on) map-matched to it."""
        if intersection is None:
            return LiveMatch(None)
        X = match_intersection(intersection.center, self.mapped, self.cfg.gate_m)
        return LiveMatch(X, None if X is None else drive_traffic(window, X, self.cfg))

    def update(self, intersection, lanelets, window=None, matched: LiveMatch | None = None) -> LiveReport:
        """Compare an estimate (``model.Intersection`` + lanelets) with the nearest mapped
        intersection; an estimate near none gives an empty report. ``window``: the
        observations the estimate rests on, whose vehicles, map-matched, drop the claims they
        contradict (:mod:`.corroborate`); ``matched``: :meth:`match` of the same estimate,
        done before (then ``window`` is not looked at)."""
        m = self.match(intersection, window) if matched is None else matched
        if intersection is None or m.mapped is None:
            return LiveReport(None)
        view = compare(intersection, lanelets, m.mapped, self.cfg, m.traffic)
        fused = fuse([(LIVE, view)], self.cfg)[m.mapped.id]
        return LiveReport(m.mapped, fused.changes, list(fused.unobserved), float(fused.passages))
