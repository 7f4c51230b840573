"""Message-class namespaces, so one builder makes rclpy messages (node) or rosbags messages (bags).

A namespace has one method, ``get(msgtype)``, returning a callable that builds a message
of that type from keyword arguments, e.g.::

    types = RclpyTypes()                      # or RosbagsTypes(bagio.typestore())
    Point = types.get('geometry_msgs/msg/Point')
    p = Point(x=1.0, y=2.0)                   # missing fields get their defaults

Builders pass plain values: Python or numpy scalars, numpy arrays / bytes for numeric
arrays and sequences, lists of messages for message arrays. Each namespace converts them
to what its message classes need (rclpy: ``array.array`` for sequences and Python
scalars; rosbags: numpy arrays of the field's dtype, every field present).
``msgtype`` may be written ``pkg/msg/Type`` or ``pkg/Type``.
"""

from __future__ import annotations

import array
import importlib

import numpy as np

from ._common import split_stamp

__all__ = ['RclpyTypes', 'RosbagsTypes', 'make_header', 'make_time', 'full_name']

_NP = {'bool': np.bool_, 'byte': np.uint8, 'octet': np.uint8, 'char': np.uint8,
       'int8': np.int8, 'uint8': np.uint8, 'int16': np.int16, 'uint16': np.uint16,
       'int32': np.int32, 'uint32': np.uint32, 'int64': np.int64, 'uint64': np.uint64,
       'float32': np.float32, 'float64': np.float64, 'float': np.float32, 'double': np.float64,
       'boolean': np.bool_}
_TYPECODE = {'int8': 'b', 'uint8': 'B', 'octet': 'B', 'byte': 'B', 'char': 'B',
             'int16': 'h', 'uint16': 'H', 'int32': 'i', 'uint32': 'I', 'int64': 'q',
             'uint64': 'Q', 'float': 'f', 'double': 'd', 'float32': 'f', 'float64': 'd'}


def full_name(msgtype: str) -> str:
    """``pkg/Type`` -> ``pkg/msg/Type``."""
    parts = msgtype.split('/')
    return f'{parts[0]}/msg/{parts[1]}' if len(parts) == 2 else msgtype


def _scalar(kind: str, value):
    if kind.startswith(('string', 'wstring')):    # also bounded: string<=N
        return str(value)
    if kind in ('bool', 'boolean'):
        return bool(value)
    if kind in ('float', 'double', 'float32', 'float64'):
        return float(value)
    return int(value)


def _numeric(value, dtype) -> np.ndarray:
    if isinstance(value, (bytes, bytearray, memoryview)):
        return np.frombuffer(value, dtype=np.uint8).astype(dtype, copy=False)
    return np.asarray(value).astype(dtype, copy=False).reshape(-1)


class RclpyTypes:
    """rclpy message classes, imported lazily (``import sensor_msgs.msg`` on first use)."""

    def __init__(self):
        self._cache = {}

    def get(self, msgtype: str):
        name = full_name(msgtype)
        if name not in self._cache:
            pkg, _, cls_name = name.split('/')
            cls = getattr(importlib.import_module(f'{pkg}.msg'), cls_name)
            self._cache[name] = self._factory(cls)
        return self._cache[name]

    def points(self, xy, z: float = 0.0) -> list:
        """``geometry_msgs/Point`` list for (N, 2) ``xy``."""
        Point = self.get('geometry_msgs/msg/Point').msgclass
        return [Point(x=x, y=y, z=z) for x, y in _xy_list(xy)]

    @staticmethod
    def _factory(cls):
        kinds = cls.get_fields_and_field_types()

        def build(**kw):
            return cls(**{k: RclpyTypes._convert(kinds[k], v) for k, v in kw.items()})
        build.msgclass = cls
        return build

    @staticmethod
    def _convert(kind: str, value):
        if kind.startswith('sequence<'):
            inner = kind[9:].split(',')[0].rstrip('>')
            if inner in _TYPECODE:
                arr = _numeric(value, _NP[inner] if inner in _NP else np.uint8)
                return array.array(_TYPECODE[inner], arr.tobytes())
            if inner.startswith(('string', 'wstring')):
                return [str(v) for v in value]
            return list(value)
        if kind.endswith(']'):
            inner = kind[:kind.index('[')]
            if inner in _NP:
                return _numeric(value, _NP[inner])
            return list(value)
        if '/' in kind:
            return value
        return _scalar(kind, value)


def _xy_list(xy) -> list:
    return np.asarray(xy, dtype=np.float64).reshape(-1, 2).tolist()


class RosbagsTypes:
    """rosbags message classes of a ``Typestore``; every field gets a default."""

    def __init__(self, typestore):
        self.typestore = typestore
        self._cache = {}

    def get(self, msgtype: str):
        name = full_name(msgtype)
        if name not in self._cache:
            cls = self.typestore.types[name]
            fields = self.typestore.fielddefs[name][1]
            self._cache[name] = self._factory(cls, fields)
        return self._cache[name]

    def points(self, xy, z: float = 0.0) -> list:
        """``geometry_msgs/Point`` list for (N, 2) ``xy`` (fast path: polylines are long)."""
        Point = self.get('geometry_msgs/msg/Point').msgclass
        return [Point(x, y, z) for x, y in _xy_list(xy)]

    def _factory(self, cls, fields):
        def build(**kw):
            unknown = set(kw) - {f for f, _ in fields}
            if unknown:
                raise TypeError(f'{cls.__msgtype__} has no field(s) {sorted(unknown)}')
            return cls(**{f: (self._convert(spec, kw[f]) if f in kw else self._default(spec))
                          for f, spec in fields})
        build.msgclass = cls
        return build

    def _convert(self, spec, value):
        node, arg = spec
        if node in (3, 4):  # rosbags Nodetype ARRAY, SEQUENCE (1 BASE, 2 NAME)
            inner, _ = arg
            if inner[0] == 1 and inner[1][0] in _NP:
                return _numeric(value, _NP[inner[1][0]])
            if inner[0] == 1:
                return [_scalar(inner[1][0], v) for v in value]
            return list(value)
        if node == 1:
            return _scalar(arg[0], value)
        return value

    def _default(self, spec):
        node, arg = spec
        if node == 1:
            return _scalar(arg[0], '' if arg[0] == 'string' else 0)
        if node == 2:
            return self.get(arg)()
        inner, size = arg
        n = size if node == 3 else 0
        if inner[0] == 1 and inner[1][0] in _NP:
            return np.zeros(n, dtype=_NP[inner[1][0]])
        return [self._default(inner) for _ in range(n)]


def make_time(types, t: float):
    """``builtin_interfaces/Time`` for ``t`` seconds."""
    sec, nsec = split_stamp(t)
    return types.get('builtin_interfaces/msg/Time')(sec=sec, nanosec=nsec)


def make_header(types, frame_id: str, t: float):
    """``std_msgs/Header`` with ``frame_id`` and stamp ``t`` seconds."""
    return types.get('std_msgs/msg/Header')(stamp=make_time(types, t), frame_id=frame_id)
