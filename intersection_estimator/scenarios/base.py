"""The scenario type of the families: a sim :class:`~intersection_estimator.sim.Scenario`
(so bag writer, bench and evaluate take it unchanged) with data streams and extras."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..sim import Scenario

__all__ = ['FamilyScenario']


@dataclass
class FamilyScenario(Scenario):
    """``real``: mode -> (Detections, cycle) given as data (AV2 tracks) instead of the
    sensor model; ``labels``: track id -> Autoware label for the tracked / heading rows
    the sensor models make (they label every vehicle CAR); ``extra_gt``: per lane id,
    additions to gt.json (``traffic_line``); ``info``: provenance for gt.json."""

    real: dict = field(default_factory=dict, repr=False)
    labels: dict = field(default_factory=dict, repr=False)
    extra_gt: dict = field(default_factory=dict, repr=False)
    info: dict = field(default_factory=dict)

    def _stream(self, mode: str, rng_seed_offset: int = 0):
        key = (mode, int(rng_seed_offset))
        if mode in self.real and int(rng_seed_offset) == 0:
            return self.real[mode]
        fresh = key not in self._cache
        dets, cyc = super()._stream(mode, rng_seed_offset)
        if fresh and self.labels and mode == 'tracked':
            ids = dets.track_id
            lab = np.array([self.labels.get(int(i), int(x)) for i, x in zip(ids, dets.label)],
                           dtype=dets.label.dtype)
            dets.label[:] = lab
        return dets, cyc
