"""Radar ``sensor_msgs/msg/PointCloud2`` <-> numpy (DESIGN.md §4, §6).

Reading accepts any layout a driver may produce: fields in any order and at any offset,
datatypes INT8..FLOAT64 (``sensor_msgs/PointField`` constants), ``count > 1`` (the first
element is used), either endianness, ``point_step`` with padding, ``row_step`` with row
padding and ``height > 1``. Only the fields that are read must be valid; others are
ignored; a ``row_step`` smaller than ``width * point_step`` (drivers that leave it 0) is
read as unpadded rows. Doppler is looked up under its common names; its sign is configurable
(``doppler_sign=-1`` for drivers where positive = approaching). The result is always
"positive = moving away from the sensor".
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ._common import as_u8, header_of
from .errors import AdapterError, guarded

__all__ = ['DOPPLER_NAMES', 'RCS_NAMES', 'POINTFIELD_DTYPES', 'RadarCloud',
           'read_pointcloud2', 'radar_cloud_msg']

#: Field names under which radar drivers publish the radial velocity, in lookup order.
DOPPLER_NAMES = ('doppler', 'velocity', 'radial_velocity', 'v_r')
#: Field names read as radar cross section / return strength, in lookup order.
RCS_NAMES = ('rcs', 'intensity', 'amplitude')
#: ``sensor_msgs/PointField`` datatype constant -> numpy type code (without byte order).
POINTFIELD_DTYPES = {1: 'i1', 2: 'u1', 3: 'i2', 4: 'u2', 5: 'i4', 6: 'u4', 7: 'f4', 8: 'f8'}


@dataclass
class RadarCloud:
    """Radar points in the sensor (message) frame.

    xyz: (N, 3) float64 [m]; doppler: (N,) [m/s], positive = moving away, NaN without a
    Doppler field; rcs: (N,) or NaN; dropped: points removed as non-finite;
    doppler_field: the field name the Doppler came from ('' if none).
    """

    frame_id: str
    stamp: float
    xyz: np.ndarray
    doppler: np.ndarray
    rcs: np.ndarray
    dropped: int = 0
    doppler_field: str = ''

    def __len__(self) -> int:
        return len(self.xyz)


def _names(arg, default) -> tuple[str, ...]:
    if arg is None:
        return default
    return (arg,) if isinstance(arg, str) else tuple(arg)


def _field_table(fields) -> dict[str, tuple[int, int, int]]:
    """name -> (offset, datatype, count), first occurrence wins."""
    table = {}
    for f in fields:
        name = str(f.name)
        if name not in table:
            table[name] = (int(f.offset), int(f.datatype), max(int(f.count), 1))
    return table


def _column_dtype(name, spec, point_step, order):
    offset, datatype, _ = spec
    code = POINTFIELD_DTYPES.get(datatype)
    if code is None:
        raise AdapterError('unknown_datatype', f'field {name!r} has datatype {datatype}')
    dt = np.dtype(order + code)
    if offset < 0 or offset + dt.itemsize > point_step:
        raise AdapterError('field_overflow', f'field {name!r} at offset {offset} (+{dt.itemsize}) '
                                             f'beyond point_step {point_step}')
    return dt


def _layout(msg, max_points):
    """Validated (height, width, point_step, row_stride, raw uint8 data)."""
    height, width = int(msg.height), int(msg.width)
    step, row_step = int(msg.point_step), int(msg.row_step)
    if height < 0 or width < 0 or step < 0 or row_step < 0:
        raise AdapterError('bad_layout', f'negative size {height}x{width} step {step}')
    n = height * width
    if max_points is not None and n > max_points:
        raise AdapterError('too_large', f'{n} points > max_points {max_points}')
    data = as_u8(msg.data)
    if n == 0:
        return height, width, step, row_step, data
    if step <= 0:
        raise AdapterError('bad_layout', f'point_step {step} for {n} points')
    stride = row_step if row_step >= width * step else width * step
    need = stride * (height - 1) + width * step
    if need > len(data):
        raise AdapterError('truncated', f'{height}x{width} points of {step} B need {need} B, '
                                        f'data has {len(data)} B')
    return height, width, step, stride, data


def _points(data, height, width, step, stride):
    """Contiguous (height*width*step) bytes, dropping row padding."""
    if height <= 1 or stride == width * step:
        return data[:height * width * step]
    rows = np.lib.stride_tricks.as_strided(data, shape=(height, width * step), strides=(stride, 1))
    return np.ascontiguousarray(rows).reshape(-1)


@guarded
def read_pointcloud2(msg, *, doppler_field=None, doppler_sign: float = 1.0, rcs_field=None,
                     max_points: int | None = None) -> RadarCloud:
    """Radar cloud from a PointCloud2 (rclpy or rosbags message), vectorised.

    doppler_field / rcs_field: a name or names to look up (default :data:`DOPPLER_NAMES`,
    :data:`RCS_NAMES`); doppler_sign: multiplies the field so that the result is positive
    when moving away. Points with a non-finite x, y, z or Doppler are dropped and counted.
    Raises :class:`AdapterError` for layouts that cannot be read.
    """
    frame_id, stamp = header_of(msg)
    height, width, step, stride, data = _layout(msg, max_points)
    if height * width == 0:
        e = np.zeros(0)
        return RadarCloud(frame_id, stamp, np.zeros((0, 3)), e, e.copy(), 0, '')
    table = _field_table(msg.fields)
    for axis in ('x', 'y'):
        if axis not in table:
            raise AdapterError('missing_field', f'no {axis!r} field (have {sorted(table)})')
    dop_name = next((n for n in _names(doppler_field, DOPPLER_NAMES) if n in table), '')
    rcs_name = next((n for n in _names(rcs_field, RCS_NAMES) if n in table), '')
    order = '>' if bool(msg.is_bigendian) else '<'
    wanted = {'x': 'x', 'y': 'y', 'z': 'z', 'doppler': dop_name, 'rcs': rcs_name}
    cols = {k: v for k, v in wanted.items() if v and v in table}
    dtype = np.dtype({'names': list(cols),
                      'formats': [_column_dtype(v, table[v], step, order) for v in cols.values()],
                      'offsets': [table[v][0] for v in cols.values()],
                      'itemsize': max(step, 1)})
    n = height * width
    arr = np.frombuffer(_points(data, height, width, step, stride), dtype=dtype, count=n)

    def col(key):
        return arr[key].astype(np.float64) if key in cols else np.full(n, np.nan)

    xyz = np.stack([col('x'), col('y'), col('z') if 'z' in cols else np.zeros(n)], axis=1)
    doppler = col('doppler') * float(doppler_sign)
    ok = np.isfinite(xyz).all(axis=1)
    if dop_name:
        ok &= np.isfinite(doppler)
    rcs = col('rcs')
    rcs[~np.isfinite(rcs)] = np.nan
    dropped = int(n - ok.sum())
    if dropped:
        xyz, doppler, rcs = xyz[ok], doppler[ok], rcs[ok]
    return RadarCloud(frame_id, stamp, xyz, doppler, rcs, dropped, dop_name)


def radar_cloud_msg(types, header, xyz, doppler, rcs=None):
    """PointCloud2 with float32 fields x, y, z, doppler, rcs (DESIGN.md §4), little endian.

    types: a message namespace (:mod:`msg_adapters.types`); header: a std_msgs/Header of
    that namespace; xyz (N, 3) or (N, 2) (z = 0) in the header frame.
    """
    xyz = np.asarray(xyz, dtype=np.float64)
    n = len(xyz)
    if xyz.shape[1:] == (2,):
        xyz = np.concatenate([xyz, np.zeros((n, 1))], axis=1)
    pts = np.zeros((n, 5), dtype='<f4')
    pts[:, :3] = xyz
    pts[:, 3] = np.asarray(doppler, dtype=np.float64).reshape(n)
    pts[:, 4] = np.nan if rcs is None else np.asarray(rcs, dtype=np.float64).reshape(n)
    PointField = types.get('sensor_msgs/msg/PointField')
    fields = [PointField(name=name, offset=4 * i, datatype=7, count=1)
              for i, name in enumerate(('x', 'y', 'z', 'doppler', 'rcs'))]
    return types.get('sensor_msgs/msg/PointCloud2')(
        header=header, height=1, width=n, fields=fields, is_bigendian=False,
        point_step=20, row_step=20 * n, data=pts.view(np.uint8).reshape(-1),
        is_dense=bool(np.isfinite(pts[:, :4]).all()))

