"""Observations in the fixed frame: the one container every input becomes.

Adapters (``msg_adapters``) turn radar clouds, pose arrays and tracked objects into
:class:`Detections`; the simulator produces them directly; preprocessing (paper §II-A)
reads whichever fields are present:

* ``track_id >= 0``  -> tracked objects (trajectories, paper §II-A last paragraph, §III-A)
* finite ``heading`` -> detections with an orientation (lidar / camera)
* finite ``doppler`` -> radar detections; the direction comes from the Doppler sign,
  the line of sight from ``sensor_xy`` and the current center estimate.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

__all__ = ['Detections']

_FLOAT_NAN = ('heading', 'doppler', 'rcs', 'speed')


@dataclass
class Detections:
    """Struct of arrays, one row per detection, all in the fixed frame.

    xy: (N, 2) position [m]; t: (N,) stamp [s]; heading: (N,) driving direction [rad]
    or NaN; doppler: (N,) ego-motion-compensated radial velocity [m/s], positive = moving
    away from the sensor, or NaN; sensor_xy: (N, 2) sensor position at detection time;
    rcs: (N,) [dBsm] or NaN; track_id: (N,) int64, -1 without identity; speed: (N,) [m/s]
    or NaN; label: (N,) int16 object class (Autoware label ids, 0 = unknown).
    """

    xy: np.ndarray
    t: np.ndarray
    heading: np.ndarray
    doppler: np.ndarray
    sensor_xy: np.ndarray
    rcs: np.ndarray
    track_id: np.ndarray
    speed: np.ndarray
    label: np.ndarray

    @classmethod
    def make(cls, xy, t=None, *, heading=None, doppler=None, sensor_xy=None, rcs=None,
             track_id=None, speed=None, label=None) -> 'Detections':
        """Build from whatever is known; missing columns get their 'unknown' value."""
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        n = len(xy)

        def col(v, fill, dtype):
            if v is None:
                return np.full(n, fill, dtype=dtype)
            a = np.asarray(v, dtype=dtype)
            return np.full(n, a, dtype=dtype) if a.ndim == 0 else a.reshape(n)

        sxy = (np.full((n, 2), np.nan) if sensor_xy is None
               else np.broadcast_to(np.asarray(sensor_xy, np.float64), (n, 2)).copy())
        return cls(xy=xy, t=col(t, 0.0, np.float64), heading=col(heading, np.nan, np.float64),
                   doppler=col(doppler, np.nan, np.float64), sensor_xy=sxy,
                   rcs=col(rcs, np.nan, np.float64), track_id=col(track_id, -1, np.int64),
                   speed=col(speed, np.nan, np.float64), label=col(label, 0, np.int16))

    @classmethod
    def empty(cls) -> 'Detections':
        return cls.make(np.zeros((0, 2)))

    def __len__(self) -> int:
        return len(self.xy)

    def subset(self, idx) -> 'Detections':
        """Rows selected by a boolean mask or index array."""
        return Detections(**{f.name: getattr(self, f.name)[idx] for f in fields(self)})

    @staticmethod
    def concat(parts) -> 'Detections':
        parts = [p for p in parts if p is not None and len(p)]
        if not parts:
            return Detections.empty()
        return Detections(**{f.name: np.concatenate([getattr(p, f.name) for p in parts])
                             for f in fields(Detections)})

    def finite(self) -> 'Detections':
        """Drop rows with a non-finite position or stamp."""
        if np.isfinite(self.xy.sum()) and np.isfinite(self.t.sum()):   # fast path: all finite
            return self
        ok = np.isfinite(self.xy).all(axis=1) & np.isfinite(self.t)
        return self if ok.all() else self.subset(ok)

    def track_mask(self, skip_labels=()) -> np.ndarray:
        """Rows of identified road users (``track_id >= 0``) with a finite position and stamp,
        without those whose classification label is in ``skip_labels``: the rows a lane's
        traffic is read from (``lanes.init.track_rows``, ``lanes.halts``)."""
        ok = (self.track_id >= 0) & np.isfinite(self.xy).all(axis=1) & np.isfinite(self.t)
        if len(skip_labels):
            ok &= ~np.isin(self.label, np.asarray(skip_labels, np.int64))
        return ok

    @property
    def has_tracks(self) -> bool:
        return bool(len(self)) and bool((self.track_id >= 0).any())

    @property
    def has_heading(self) -> bool:
        return bool(len(self)) and bool(np.isfinite(self.heading).any())

    @property
    def has_doppler(self) -> bool:
        return bool(len(self)) and bool(np.isfinite(self.doppler).any())
