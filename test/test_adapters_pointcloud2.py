"""PointCloud2 radar reader: layouts, Doppler names and sign, errors, fuzz."""

from types import SimpleNamespace as NS

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from msg_adapters.errors import AdapterError
from msg_adapters.pointcloud2 import DOPPLER_NAMES, radar_cloud_msg, read_pointcloud2
from msg_adapters.types import RclpyTypes, RosbagsTypes, make_header

CODE = {1: 'i1', 2: 'u1', 3: 'i2', 4: 'u2', 5: 'i4', 6: 'u4', 7: 'f4', 8: 'f8'}
F32, F64, I16 = 7, 8, 3


def header(frame='radar', t=5.25):
    return NS(frame_id=frame, stamp=NS(sec=int(t), nanosec=int(round((t % 1) * 1e9))))


def cloud(cols, *, datatypes=None, order=None, pad=0, big=False, height=1, row_pad=0,
          counts=None, gap=0):
    """A PointCloud2-like object with ``cols`` (name -> (n,) values) in any layout.

    order: field order in memory; pad: bytes after the last field; gap: bytes between
    fields; row_pad: bytes after every row; counts: name -> count (values repeated).
    """
    names = list(order or cols)
    datatypes = datatypes or {}
    counts = counts or {}
    bo = '>' if big else '<'
    offsets, off = {}, 0
    for name in names:
        offsets[name] = off
        off += np.dtype(CODE[datatypes.get(name, F32)]).itemsize * counts.get(name, 1) + gap
    step = off + pad
    n = len(next(iter(cols.values())))
    width = n // height
    buf = np.zeros((height, width * step + row_pad), np.uint8)
    for name in names:
        dt = np.dtype(bo + CODE[datatypes.get(name, F32)])
        vals = np.asarray(cols[name]).reshape(height, width)
        for k in range(counts.get(name, 1)):
            raw = vals.astype(dt).view(np.uint8).reshape(height, width, dt.itemsize)
            for b in range(dt.itemsize):
                buf[:, offsets[name] + k * dt.itemsize + b:width * step:step] = raw[:, :, b]
    fields = [NS(name=nm, offset=offsets[nm], datatype=datatypes.get(nm, F32),
                 count=counts.get(nm, 1)) for nm in names]
    return NS(header=header(), height=height, width=width, fields=fields, is_bigendian=big,
              point_step=step, row_step=width * step + row_pad, data=buf.reshape(-1), is_dense=True)


RNG = np.random.default_rng(0)
N = 12
XYZ = np.round(RNG.uniform(-50, 50, (N, 3)), 1)
DOP = np.round(RNG.uniform(-10, 10, N), 2)
RCS = np.round(RNG.uniform(-10, 20, N), 1)
BASE = {'x': XYZ[:, 0], 'y': XYZ[:, 1], 'z': XYZ[:, 2], 'doppler': DOP, 'rcs': RCS}


def check(res, xyz=XYZ, dop=DOP, rcs=RCS, atol=1e-4):
    assert res.frame_id == 'radar' and res.stamp == pytest.approx(5.25)
    np.testing.assert_allclose(res.xyz, xyz, atol=atol)
    np.testing.assert_allclose(res.doppler, dop, atol=atol)
    np.testing.assert_allclose(res.rcs, rcs, atol=atol)


@pytest.mark.parametrize('big', [False, True])
@pytest.mark.parametrize('dtype', [F32, F64])
@pytest.mark.parametrize('order', [('x', 'y', 'z', 'doppler', 'rcs'), ('rcs', 'doppler', 'z', 'y', 'x'),
                                   ('doppler', 'x', 'rcs', 'y', 'z')])
def test_field_order_dtype_endianness(big, dtype, order):
    msg = cloud(BASE, order=order, datatypes=dict.fromkeys(BASE, dtype), big=big, gap=2, pad=5)
    check(read_pointcloud2(msg))


def test_int16_fields_and_mixed_types():
    cols = {'x': np.round(XYZ[:, 0]), 'y': np.round(XYZ[:, 1]), 'z': np.zeros(N),
            'doppler': DOP, 'rcs': np.round(RCS)}
    msg = cloud(cols, datatypes={'x': I16, 'y': I16, 'z': 1, 'doppler': F64, 'rcs': I16},
                big=True)
    res = read_pointcloud2(msg)
    np.testing.assert_array_equal(res.xyz[:, :2], np.round(XYZ[:, :2]))
    np.testing.assert_allclose(res.doppler, DOP, atol=1e-12)
    np.testing.assert_array_equal(res.rcs, np.round(RCS))


@pytest.mark.parametrize('height,row_pad', [(3, 0), (3, 7), (4, 1), (1, 9)])
def test_height_and_row_padding(height, row_pad):
    check(read_pointcloud2(cloud(BASE, height=height, row_pad=row_pad, pad=3)))


def test_count_greater_than_one_uses_first_element():
    msg = cloud(BASE, counts={'doppler': 3, 'x': 2})
    check(read_pointcloud2(msg))


@pytest.mark.parametrize('name', DOPPLER_NAMES)
def test_doppler_names(name):
    cols = dict(BASE)
    cols[name] = cols.pop('doppler')
    res = read_pointcloud2(cloud(cols))
    assert res.doppler_field == name
    check(res)


def test_doppler_sign_and_configured_name():
    cols = dict(BASE, vel_rad=-DOP)
    del cols['doppler']
    res = read_pointcloud2(cloud(cols), doppler_field='vel_rad', doppler_sign=-1.0)
    assert res.doppler_field == 'vel_rad'
    check(res)
    res = read_pointcloud2(cloud(BASE), doppler_sign=-1)
    np.testing.assert_allclose(res.doppler, -DOP, atol=1e-4)


def test_first_matching_doppler_name_wins():
    cols = dict(BASE, velocity=np.zeros(N))
    assert read_pointcloud2(cloud(cols)).doppler_field == 'doppler'
    assert read_pointcloud2(cloud(cols), doppler_field=('velocity', 'doppler')).doppler_field == 'velocity'


def test_missing_doppler_and_rcs_give_nan_and_intensity_is_rcs():
    cols = {'x': XYZ[:, 0], 'y': XYZ[:, 1], 'intensity': RCS}
    res = read_pointcloud2(cloud(cols))
    assert res.doppler_field == '' and np.isnan(res.doppler).all()
    np.testing.assert_allclose(res.xyz[:, 2], 0.0)
    np.testing.assert_allclose(res.rcs, RCS, atol=1e-4)
    res = read_pointcloud2(cloud({'x': XYZ[:, 0], 'y': XYZ[:, 1], 'z': XYZ[:, 2]}))
    assert np.isnan(res.rcs).all() and len(res) == N


def test_empty_cloud():
    msg = NS(header=header(), height=1, width=0, fields=[], is_bigendian=False, point_step=0,
             row_step=0, data=np.zeros(0, np.uint8), is_dense=True)
    res = read_pointcloud2(msg)
    assert len(res) == 0 and res.xyz.shape == (0, 3)
    msg = cloud(BASE)
    msg.width, msg.data = 0, np.zeros(0, np.uint8)
    assert len(read_pointcloud2(msg)) == 0


def test_non_finite_points_dropped_and_counted():
    cols = {k: v.copy() for k, v in BASE.items()}
    cols['x'][1] = np.nan
    cols['z'][3] = np.inf
    cols['doppler'][5] = np.nan
    cols['rcs'][7] = np.nan   # rcs may be missing per point: kept
    res = read_pointcloud2(cloud(cols))
    keep = np.setdiff1d(np.arange(N), [1, 3, 5])
    assert res.dropped == 3 and len(res) == N - 3
    np.testing.assert_allclose(res.xyz, XYZ[keep], atol=1e-4)
    assert np.isnan(res.rcs[list(keep).index(7)])


@pytest.mark.parametrize('mangle,reason', [
    (lambda m: setattr(m, 'data', m.data[:-1]), 'truncated'),
    (lambda m: setattr(m, 'height', 2), 'truncated'),
    (lambda m: setattr(m, 'row_step', m.row_step + 1) or setattr(m, 'height', 1), None),
    (lambda m: setattr(m, 'fields', [f for f in m.fields if f.name != 'y']), 'missing_field'),
    (lambda m: setattr(m.fields[0], 'datatype', 9), 'unknown_datatype'),
    (lambda m: setattr(m.fields[0], 'offset', m.point_step - 2), 'field_overflow'),
    (lambda m: setattr(m, 'point_step', 0), 'bad_layout'),
    (lambda m: setattr(m, 'width', -1), 'bad_layout'),
    (lambda m: setattr(m, 'fields', None), 'malformed'),
    (lambda m: setattr(m, 'header', NS(frame_id='r', stamp=NS(sec='x', nanosec=0))), 'malformed'),
    (lambda m: delattr(m, 'point_step'), 'malformed'),
])
def test_layout_errors(mangle, reason):
    msg = cloud(BASE)
    mangle(msg)
    if reason is None:       # row_step larger than the data of one row: one row, still readable
        assert len(read_pointcloud2(msg)) == N
        return
    with pytest.raises(AdapterError) as err:
        read_pointcloud2(msg)
    assert err.value.reason == reason


def test_unused_field_with_unknown_datatype_is_ignored():
    msg = cloud(BASE)
    msg.fields.append(NS(name='weird', offset=0, datatype=42, count=1))
    check(read_pointcloud2(msg))


def test_max_points():
    with pytest.raises(AdapterError) as err:
        read_pointcloud2(cloud(BASE), max_points=N - 1)
    assert err.value.reason == 'too_large'


def test_builder_roundtrip_rclpy_and_rosbags():
    from rosbags.typesys import Stores, get_typestore
    from sensor_msgs.msg import PointCloud2
    T = RclpyTypes()
    msg = radar_cloud_msg(T, make_header(T, 'radar', 5.25), XYZ, DOP, RCS)
    assert isinstance(msg, PointCloud2) and msg.point_step == 20
    check(read_pointcloud2(msg))
    ts = get_typestore(Stores.ROS2_JAZZY)
    R = RosbagsTypes(ts)
    raw = ts.serialize_cdr(radar_cloud_msg(R, make_header(R, 'radar', 5.25), XYZ, DOP, RCS),
                           'sensor_msgs/msg/PointCloud2')
    back = ts.deserialize_cdr(raw, 'sensor_msgs/msg/PointCloud2')
    assert isinstance(back.data, np.ndarray)
    check(read_pointcloud2(back))
    from rclpy.serialization import deserialize_message
    check(read_pointcloud2(deserialize_message(bytes(raw), PointCloud2)))


def test_large_cloud_is_vectorised():
    import time
    n = 1_000_000
    msg = NS(header=header(), height=1, width=n, is_bigendian=False, point_step=20, row_step=20 * n,
             fields=[NS(name=k, offset=4 * i, datatype=F32, count=1)
                     for i, k in enumerate(('x', 'y', 'z', 'doppler', 'rcs'))],
             data=np.ones(20 * n, np.uint8), is_dense=True)
    t = time.perf_counter()
    assert len(read_pointcloud2(msg)) == n
    assert time.perf_counter() - t < 2.0


# ---------------------------------------------------------------------------- fuzz

NAMES = ['x', 'y', 'z', 'doppler', 'velocity', 'v_r', 'rcs', 'intensity', 'other']
field_st = st.builds(lambda name, off, dt, cnt: NS(name=name, offset=off, datatype=dt, count=cnt),
                     st.sampled_from(NAMES), st.integers(-4, 40), st.integers(-1, 12), st.integers(-1, 3))
junk_st = st.one_of(st.none(), st.text(max_size=3), st.floats(allow_nan=True), st.integers(-2**40, 2**40),
                    st.lists(st.integers(0, 300), max_size=5))


@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(fields=st.lists(field_st, max_size=8), height=st.integers(-1, 4), width=st.integers(-1, 9),
       step=st.integers(-1, 48), row_extra=st.integers(-8, 8), big=st.booleans(),
       data=st.binary(max_size=600), mangle=st.dictionaries(
           st.sampled_from(['height', 'width', 'point_step', 'row_step', 'data', 'fields',
                            'is_bigendian', 'header']), junk_st, max_size=2))
def test_fuzz_only_adapter_errors(fields, height, width, step, row_extra, big, data, mangle):
    msg = NS(header=header(), height=height, width=width, fields=fields, is_bigendian=big,
             point_step=step, row_step=max(width, 0) * max(step, 0) + row_extra,
             data=np.frombuffer(data, np.uint8), is_dense=False)
    for k, v in mangle.items():
        setattr(msg, k, v)
    try:
        res = read_pointcloud2(msg)
    except AdapterError as err:
        assert err.reason
        return
    n = len(res)
    assert res.xyz.shape == (n, 3) and res.doppler.shape == (n,) and res.rcs.shape == (n,)
    assert np.isfinite(res.xyz).all()


@settings(max_examples=150, deadline=None)
@given(perm=st.permutations(['x', 'y', 'z', 'doppler', 'rcs']),
       dts=st.lists(st.sampled_from([3, 5, 7, 8]), min_size=5, max_size=5),
       gap=st.integers(0, 3), pad=st.integers(0, 9), big=st.booleans(),
       height=st.sampled_from([1, 2, 3, 4, 6]), row_pad=st.integers(0, 5))
def test_fuzz_valid_layouts_read_back(perm, dts, gap, pad, big, height, row_pad):
    cols = {k: np.round(v) for k, v in BASE.items()}   # integer values survive INT16/INT32
    msg = cloud(cols, order=perm, datatypes=dict(zip(perm, dts)), gap=gap, pad=pad, big=big,
                height=height, row_pad=row_pad)
    check(read_pointcloud2(msg), xyz=np.round(XYZ), dop=np.round(DOP), rcs=np.round(RCS), atol=0)
