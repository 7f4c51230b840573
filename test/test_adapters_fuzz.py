"""Fuzz: mangled messages of every input family raise nothing but AdapterError (issue 8)."""

import copy
import dataclasses
from types import SimpleNamespace as NS

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from intersection_estimator.bagio import typestore
from msg_adapters.detections import AdapterOptions, to_detections
from msg_adapters.errors import AdapterError
from msg_adapters.odometry import EgoPoseBuffer, odometry_msg, read_odometry
from msg_adapters.pointcloud2 import radar_cloud_msg
from msg_adapters.pose_array import pose_array_msg
from msg_adapters.radar_scan import radar_scan_msg
from msg_adapters.tracked_objects import (autoware_tracked_objects_msg, derived_object_array_msg,
                                          tracked_object_array_msg)
from msg_adapters.types import RosbagsTypes, make_header


def to_ns(obj):
    """A rosbags message as a mutable attribute tree (lists stay lists, arrays stay arrays)."""
    if dataclasses.is_dataclass(obj):
        return NS(**{f.name: to_ns(getattr(obj, f.name)) for f in dataclasses.fields(obj)})
    if isinstance(obj, list):
        return [to_ns(v) for v in obj]
    return obj


def paths(obj, prefix=()):
    out = []
    items = (vars(obj).items() if isinstance(obj, NS)
             else enumerate(obj) if isinstance(obj, list) else ())
    for k, v in items:
        if isinstance(k, str) and k.startswith('__'):
            continue
        out.append(prefix + (k,))
        out.extend(paths(v, prefix + (k,)))
    return out


def mutate(obj, path, value, delete):
    *head, last = path
    for k in head:
        obj = obj[k] if isinstance(obj, list) else getattr(obj, k)
    if isinstance(obj, list):
        if delete:
            del obj[last]
        else:
            obj[last] = value
    elif delete:
        delattr(obj, last)
    else:
        setattr(obj, last, value)


def samples():
    T = RosbagsTypes(typestore())
    h = make_header(T, 'base_link', 10.5)
    xy, yaw = [[1.0, 2.0], [3.0, 4.0]], [0.1, 2.0]
    return {
        'cloud': radar_cloud_msg(T, make_header(T, 'radar', 10.5), [[1, 2, 0], [3, 4, 0]], [1, -1], [5, 6]),
        'scan': radar_scan_msg(T, make_header(T, 'radar', 10.5), [5, 6], [0.1, 0.2], [0, 0], [1, 2], [3, 4]),
        'poses': pose_array_msg(T, h, xy, yaw),
        'ours': tracked_object_array_msg(T, h, [1, 2], xy, yaw, [3, 4]),
        'autoware': autoware_tracked_objects_msg(T, h, [1, 2], xy, yaw, [3, 4]),
        'derived': derived_object_array_msg(T, h, [1, 2], xy, yaw, [3, 4]),
        'odom': odometry_msg(T, 10.6, 1, 2, 0.3, vx=2.0),
    }


BASE = {k: to_ns(v) for k, v in samples().items()}
JUNK = st.one_of(st.none(), st.text(max_size=4), st.integers(-2**70, 2**70),
                 st.floats(allow_nan=True, allow_infinity=True), st.booleans(),
                 st.lists(st.integers(-5, 300), max_size=4), st.binary(max_size=8),
                 st.builds(lambda: np.array([np.nan, 1e308])), st.builds(NS),
                 st.builds(lambda: [NS(x=1)]))   # builds: fresh objects, mutations must not leak


def ego():
    buf = EgoPoseBuffer('map', 'base_link')
    buf.add_msg(BASE['odom'])
    buf.add(read_odometry(BASE['odom']).__class__(10.4, 'map', 'base_link', 0.0, 0.0, 0.0))
    return buf


OPTS = AdapterOptions(mounts={'radar': (3.0, 0.0, 0.0)}, labels=None)


@pytest.mark.parametrize('kind', sorted(BASE))
def test_unmangled_samples_convert(kind):
    d = to_detections(copy.deepcopy(BASE[kind]), ego(), OPTS)
    assert len(d) == (0 if kind == 'odom' else 2)


@settings(max_examples=600, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(kind=st.sampled_from(sorted(BASE)), data=st.data())
def test_mangled_messages_raise_only_adapter_error(kind, data):
    msg = copy.deepcopy(BASE[kind])
    for _ in range(data.draw(st.integers(1, 3))):
        avail = paths(msg)
        if not avail:
            break
        path = data.draw(st.sampled_from(avail))
        mutate(msg, path, data.draw(JUNK), data.draw(st.booleans()))
    try:
        d = to_detections(msg, ego(), OPTS)
    except AdapterError as err:
        assert err.reason
        return
    assert np.isfinite(d.xy).all() and len(d.t) == len(d)
