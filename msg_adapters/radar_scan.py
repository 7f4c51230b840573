"""``radar_msgs/msg/RadarScan`` (polar returns in the sensor frame) -> :class:`RadarCloud`.

Each ``RadarReturn`` has ``range`` [m], ``azimuth`` [rad, counter-clockwise, REP 103],
``elevation`` [rad, negative below the sensor], ``doppler_velocity`` [m/s] and
``amplitude`` [dB]; amplitude becomes the cloud's ``rcs`` column.
"""

from __future__ import annotations

import numpy as np

from ._common import header_of
from .errors import AdapterError, guarded
from .pointcloud2 import RadarCloud

__all__ = ['read_radar_scan', 'radar_scan_msg']

_COLS = ('range', 'azimuth', 'elevation', 'doppler_velocity', 'amplitude')


@guarded
def read_radar_scan(msg, *, doppler_sign: float = 1.0, max_points: int | None = None) -> RadarCloud:
    """Polar returns -> cartesian points in the sensor frame; non-finite returns dropped."""
    frame_id, stamp = header_of(msg)
    returns = msg.returns
    if max_points is not None and len(returns) > max_points:
        raise AdapterError('too_large', f'{len(returns)} returns > max_points {max_points}')
    a = np.array([[float(getattr(r, c)) for c in _COLS] for r in returns],
                 dtype=np.float64).reshape(-1, len(_COLS))
    rng, az, el, dop, amp = a.T
    ok = np.isfinite(a[:, :4]).all(axis=1)
    rxy = rng * np.cos(el)
    xyz = np.stack([rxy * np.cos(az), rxy * np.sin(az), rng * np.sin(el)], axis=1)
    amp = np.where(np.isfinite(amp), amp, np.nan)
    return RadarCloud(frame_id, stamp, xyz[ok], dop[ok] * float(doppler_sign), amp[ok],
                      int((~ok).sum()), 'doppler_velocity')


def radar_scan_msg(types, header, rng, azimuth, elevation, doppler, amplitude=None):
    """RadarScan from arrays of polar returns (types: see :mod:`msg_adapters.types`)."""
    n = len(np.atleast_1d(rng))
    cols = [np.broadcast_to(np.asarray(v if v is not None else 0.0, float), (n,))
            for v in (rng, azimuth, elevation, doppler, amplitude)]
    Ret = types.get('radar_msgs/msg/RadarReturn')
    returns = [Ret(**dict(zip(_COLS, (float(c[i]) for c in cols)))) for i in range(n)]
    return types.get('radar_msgs/msg/RadarScan')(header=header, returns=returns)
