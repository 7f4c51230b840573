"""rosbag2 (MCAP, sqlite3) reading and writing with rosbags -- no ROS runtime, no rclpy.

* :func:`typestore` -- rosbags' Jazzy types + ``intersection_estimator_msgs`` + the schemas
  of packages without a wheel (``msg_adapters/schemas``: Autoware, radar_msgs,
  derived_object_msgs).
* :func:`open_bags` -- one or more bags (directories, ``.mcap`` or ``.db3`` files) as one
  time-ordered stream of deserialised messages. Each bag is decoded with the schemas it
  embeds, so types that are not installed still decode. A truncated MCAP (recording
  killed, copy cut short) yields what can be read and records the truncation in
  :attr:`BagSet.problems` (or raises at the end with ``strict=True``).
* :func:`detect_topics` -- input topics per role, by message type.
* :class:`BagWriter` -- MCAP output bags (zstd chunks), messages built with ``writer.types``.
* :func:`write_scenario_bag` -- a simulated scenario on the node's input topics.

Every failure is a :class:`BagError` whose ``reason`` is one of ``missing``,
``not_a_bag``, ``corrupt``, ``truncated``, ``no_usable_topic``, ``exists`` and whose
``str()`` is one line.
"""

from __future__ import annotations

import heapq
import math
import struct
import sys
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Iterable, Iterator

import numpy as np

__all__ = ['BagError', 'BagMessage', 'BagSet', 'BagWriter', 'TopicInfo', 'typestore',
           'open_bags', 'detect_topics', 'write_scenario_bag', 'SCENARIO_TOPICS',
           'SCENARIO_FRAMES', 'SCENARIO_RADAR_MOUNT', 'BAG_T0', 'LATCHED', 'ROLE_TYPES',
           'ScenarioBagInfo', 'scenario_messages', 'scenario_mount']

# ----------------------------------------------------------------------------- constants

#: Topics written by :func:`write_scenario_bag` (the node's default input topics).
SCENARIO_TOPICS = {
    'odometry': '/localization/odometry',
    'radar': '/perception/radar/points',
    'objects': '/perception/objects',
    'autoware': '/perception/autoware/objects',
    'detections': '/perception/detections',
    'tf_static': '/tf_static',
}
#: Frames of scenario bags: fixed frame, ego frame, radar frame (mounted on the ego).
SCENARIO_FRAMES = {'fixed': 'map', 'base': 'base_link', 'radar': 'radar'}
#: Radar mount (x, y, yaw) in base_link of scenario bags with the default SimConfig
#: (``sensor_mount`` = 3.7 m ahead); also written to ``/tf_static`` (base_link -> radar).
SCENARIO_RADAR_MOUNT = (3.7, 0.0, 0.0)
#: Bag time of the scenario's t = 0 [s] (2023-11-14T22:13:20Z): avoids zero stamps.
BAG_T0 = 1_700_000_000.0

#: Message types per input role (autoware_auto_* is the pre-2024 Autoware name).
ROLE_TYPES = {
    'radar_clouds': ('sensor_msgs/msg/PointCloud2',),
    'radar_scans': ('radar_msgs/msg/RadarScan',),
    'pose_arrays': ('geometry_msgs/msg/PoseArray',),
    'tracked_objects': ('intersection_estimator_msgs/msg/TrackedObjectArray',
                        'autoware_perception_msgs/msg/TrackedObjects',
                        'autoware_auto_perception_msgs/msg/TrackedObjects',
                        'autoware_perception_msgs/msg/PredictedObjects',
                        'autoware_auto_perception_msgs/msg/PredictedObjects',
                        'derived_object_msgs/msg/ObjectArray'),
    'detected_objects': ('autoware_perception_msgs/msg/DetectedObjects',
                         'autoware_auto_perception_msgs/msg/DetectedObjects'),
    'odometry': ('nav_msgs/msg/Odometry',),
}
_INPUT_ROLES = ('radar_clouds', 'radar_scans', 'pose_arrays', 'tracked_objects', 'detected_objects')
_MSGS_PKG = 'intersection_estimator_msgs'


class BagError(Exception):
    """A bag that cannot be used; ``reason`` is a stable key, ``str()`` one line."""

    def __init__(self, reason: str, message: str, path=None):
        self.reason, self.message, self.path = reason, ' '.join(str(message).split()), path
        where = f'{path}: ' if path is not None else ''
        super().__init__(f'{reason}: {where}{self.message}')


# ----------------------------------------------------------------------------- types


def _msg_dirs() -> list[tuple[str, Path]]:
    """(package, msg dir) of our messages: installed share dir first, else the source tree."""
    cands = []
    try:
        from ament_index_python.packages import get_package_share_directory
        cands.append(Path(get_package_share_directory(_MSGS_PKG)) / 'msg')
    except Exception:  # not on AMENT_PREFIX_PATH: fine, try the others
        pass
    cands.append(Path(sys.prefix) / 'share' / _MSGS_PKG / 'msg')
    cands.append(Path(__file__).resolve().parents[1] / 'msgs' / _MSGS_PKG / 'msg')
    for d in cands:
        if d.is_dir() and any(d.glob('*.msg')):
            return [(_MSGS_PKG, d)]
    return []


def schema_dirs() -> list[tuple[str, Path]]:
    """(package, msg dir) for every schema package shipped in ``msg_adapters/schemas``."""
    import msg_adapters
    root = Path(msg_adapters.__file__).resolve().parent / 'schemas'
    return sorted((d.parent.name, d) for d in root.glob('*/msg') if d.is_dir())


def _read_msg_dirs(dirs) -> dict:
    from rosbags.typesys import get_types_from_msg
    typs = {}
    for pkg, d in dirs:
        for f in sorted(d.glob('*.msg')):
            typs.update(get_types_from_msg(f.read_text(), f'{pkg}/msg/{f.stem}'))
    return typs


@lru_cache(maxsize=1)
def typestore():
    """rosbags ``Typestore``: ROS 2 Jazzy + our messages + ``msg_adapters/schemas`` (cached)."""
    from rosbags.typesys import Stores, get_typestore
    ts = get_typestore(Stores.ROS2_JAZZY)
    dirs = _msg_dirs()
    if not dirs:
        raise BagError('missing', f'no .msg files of {_MSGS_PKG} found (installed share dir or source tree)')
    ts.register(_read_msg_dirs(dirs + schema_dirs()))
    return ts


@lru_cache(maxsize=256)
def _is_default(msgtype: str, fmt: str, text: str) -> bool:
    """The embedded schema is exactly what the default typestore writes (bags by rosbags)."""
    base = typestore()
    if fmt not in ('msg', 'ros2msg') or msgtype not in base.types:
        return False
    try:
        return base.generate_msgdef(msgtype, ros_version=2)[0] == text
    except Exception:
        return False


@lru_cache(maxsize=256)
def _parse_schema(msgtype: str, fmt: str, text: str) -> dict:
    from rosbags.typesys import get_types_from_idl, get_types_from_msg
    if fmt in ('msg', 'ros2msg'):
        return get_types_from_msg(text, msgtype)
    sep = '=' * 80 + '\n'
    typs = {}
    for part in text.split(sep):
        if part.startswith('IDL: '):
            part = part.split('\n', 1)[1] if '\n' in part else ''
        if part.strip():
            typs.update(get_types_from_idl(part))
    return typs


def _bag_typestore(schemas: Iterable[tuple[str, str, str]]):
    """Typestore for one bag: its embedded schemas win, the default fills the rest."""
    from rosbags.typesys import Stores, get_typestore
    base = typestore()
    typs = {}
    for msgtype, fmt, text in schemas:
        if not text or msgtype in typs or _is_default(msgtype, fmt, text):
            continue
        try:
            parsed = _parse_schema(msgtype, fmt, text)
        except Exception:  # an unparsable embedded schema: fall back to the default for it
            continue
        for k, v in parsed.items():
            typs.setdefault(k, v)
    same = all(k in base.fielddefs and _fields(base.fielddefs[k]) == _fields(v) for k, v in typs.items())
    if same:
        return base
    for k, v in base.fielddefs.items():
        typs.setdefault(k, v)
    ts = get_typestore(Stores.EMPTY)
    ts.register(typs)
    return ts


def _fields(fielddef):
    return [(f[0].lower(), f[1]) for f in fielddef[1]]


# ----------------------------------------------------------------------------- reading


@dataclass(frozen=True)
class TopicInfo:
    """One topic of a :class:`BagSet`: type and message count (summed over bags)."""

    topic: str
    msgtype: str
    count: int


@dataclass(frozen=True)
class BagMessage:
    """One message: topic, type, bag time [ns], deserialised message (rosbags class)."""

    topic: str
    msgtype: str
    t_ns: int
    msg: object

    @property
    def t(self) -> float:
        return self.t_ns * 1e-9


def _mcap_files(path: Path) -> list[Path]:
    if path.is_file():
        return [path]
    meta = path / 'metadata.yaml'
    if meta.exists():
        try:
            from ruamel.yaml import YAML
            info = YAML(typ='safe').load(meta.read_text())['rosbag2_bagfile_information']
            files = [path / Path(p).name for p in info['relative_file_paths']]
            return [p for p in files if p.suffix == '.mcap' and p.exists()]
        except Exception:
            pass
    return sorted(path.glob('*.mcap'))


class _Bag:
    """One bag: rosbags Reader, or the MCAP record scanner when the index is gone."""

    def __init__(self, path: Path):
        self.path = path
        self.problem: BagError | None = None
        self._reader = None
        self._scan_files: list[Path] = []
        self.connections: list[tuple[str, str, int]] = []  # topic, msgtype, count
        self.span = (0, 0)                                  # first, last message time [ns]
        self._open()

    def _open(self):
        from rosbags.rosbag2 import Reader
        from rosbags.rosbag2.errors import ReaderError
        if not self.path.exists():
            raise BagError('missing', 'no such file or directory', self.path)
        try:
            reader = Reader(self.path)
            reader.open()
        except (ReaderError, FileNotFoundError, OSError, KeyError, ValueError, TypeError,
                struct.error, AssertionError, IndexError) as exc:
            self._open_fallback(exc)
            return
        except Exception as exc:  # sqlite3.DatabaseError and friends
            raise BagError('corrupt', f'{type(exc).__name__}: {exc}', self.path) from exc
        self._reader = reader
        if reader.message_count:
            self.span = (reader.start_time, reader.end_time - 1)
        self.typestore = _bag_typestore(
            (c.msgtype, c.msgdef.format.name.lower(), c.msgdef.data) for c in reader.connections)
        self.connections = [(c.topic, c.msgtype, c.msgcount) for c in reader.connections]

    def _open_fallback(self, exc):
        """The rosbags reader refused the bag: scan MCAP records if there are any."""
        files = _mcap_files(self.path) if (self.path.is_dir() or self.path.suffix == '.mcap') else []
        if not files or not all(_has_mcap_magic(f) for f in files):
            what = 'not a rosbag2 bag (no metadata.yaml, .mcap or .db3)' if not files else 'no MCAP magic'
            raise BagError('not_a_bag', f'{what}: {exc}', self.path) from exc
        self._scan_files = files
        schemas, channels, counts, problem, times = {}, {}, {}, None, []
        for f in files:
            try:
                for rec in _scan_mcap(f):
                    _collect(rec, schemas, channels, counts)
                    if rec[0] == 'message':
                        times.append(rec[2])
            except BagError as err:
                problem = err
        if times:
            self.span = (min(times), max(times))
        self.problem = problem or BagError('corrupt', f'index unreadable ({exc}); read by scanning',
                                           self.path)
        if not channels:
            raise BagError(self.problem.reason, f'{self.problem.message}; no readable channel', self.path)
        self._schemas, self._channels = schemas, channels
        self.typestore = _bag_typestore(
            (schemas[s][0], schemas[s][1], schemas[s][2]) for _, _, s in channels.values() if s in schemas)
        self.connections = [(t, schemas.get(s, ('',))[0], counts.get(cid, 0))
                            for cid, (t, _, s) in channels.items()]

    def raw(self, topics: set | None) -> Iterator[tuple[int, str, str, bytes]]:
        """(t_ns, topic, msgtype, cdr bytes) in bag order; stops at the first damage."""
        if self._reader is not None:
            yield from self._raw_reader(topics)
        else:
            yield from self._raw_scan(topics)

    def _raw_reader(self, topics):
        conns = [c for c in self._reader.connections if topics is None or c.topic in topics]
        try:
            for conn, t, data in self._reader.messages(connections=conns):
                yield t, conn.topic, conn.msgtype, data
        except Exception as exc:  # damaged chunk / page after the index was read
            self.problem = BagError('corrupt', f'stopped reading: {type(exc).__name__}: {exc}', self.path)

    def _raw_scan(self, topics):
        schemas, channels = dict(self._schemas), dict(self._channels)
        for f in self._scan_files:
            try:
                for rec in _scan_mcap(f):
                    if rec[0] != 'message':
                        _collect(rec, schemas, channels, {})
                        continue
                    _, cid, t, data = rec
                    if cid in channels:
                        topic, _, sid = channels[cid]
                        if topics is None or topic in topics:
                            yield t, topic, schemas.get(sid, ('',))[0], data
            except BagError:
                break  # already recorded in self.problem when the bag was opened

    def close(self):
        if self._reader is not None:
            self._reader.close()
            self._reader = None


def _expand(path: Path) -> list[Path]:
    """A directory without metadata.yaml stands for the bag files in it."""
    if path.is_dir() and not (path / 'metadata.yaml').exists():
        files = sorted(list(path.glob('*.mcap')) + list(path.glob('*.db3')))
        return files or [path]
    return [path]


def _collect(rec, schemas, channels, counts):
    kind = rec[0]
    if kind == 'schema':
        schemas[rec[1]] = rec[2:]
    elif kind == 'channel':
        channels[rec[1]] = rec[2:]
    elif kind == 'message':
        counts[rec[1]] = counts.get(rec[1], 0) + 1


class BagSet:
    """Several bags read as one time-ordered stream (see :func:`open_bags`)."""

    def __init__(self, paths, *, strict: bool = False):
        paths = [Path(paths)] if isinstance(paths, (str, Path)) else [Path(p) for p in paths]
        paths = [q for p in paths for q in _expand(p)]
        if not paths:
            raise BagError('missing', 'no bag given')
        self.strict = strict
        self.bags: list[_Bag] = []
        try:
            for p in paths:
                self.bags.append(_Bag(p))
        except BagError:
            self.close()
            raise

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def close(self):
        for b in self.bags:
            b.close()

    @property
    def problems(self) -> list[BagError]:
        """Damage found so far (truncation, corrupt chunks); complete after iterating."""
        return [b.problem for b in self.bags if b.problem is not None]

    @property
    def truncated(self) -> bool:
        return bool(self.problems)

    @property
    def message_count(self) -> int:
        """Messages in all bags (as indexed; for a damaged bag: as far as readable)."""
        return sum(t.count for t in self.topics)

    @property
    def time_span(self) -> tuple[float, float]:
        """(first, last) message time [s] over all bags; (0, 0) when empty."""
        spans = [b.span for b in self.bags if b.span != (0, 0)]
        if not spans:
            return 0.0, 0.0
        return min(s[0] for s in spans) * 1e-9, max(s[1] for s in spans) * 1e-9

    @property
    def topics(self) -> list[TopicInfo]:
        acc: dict[str, list] = {}
        for b in self.bags:
            for topic, msgtype, count in b.connections:
                entry = acc.setdefault(topic, [msgtype, 0])
                entry[1] += count
        return [TopicInfo(t, m, c) for t, (m, c) in sorted(acc.items())]

    def raw_messages(self, topics=None) -> Iterator[tuple[int, str, str, bytes]]:
        """(t_ns, topic, msgtype, CDR bytes), merged by time over all bags."""
        sel = None if topics is None else set(topics)
        streams = [b.raw(sel) for b in self.bags]
        yield from streams[0] if len(streams) == 1 else heapq.merge(*streams, key=lambda r: r[0])
        self._check()

    def messages(self, topics=None) -> Iterator[BagMessage]:
        """Deserialised :class:`BagMessage` s, merged by time; undecodable ones are skipped
        and counted in :attr:`undecodable`."""
        self.undecodable = 0
        stores = {}
        for b in self.bags:
            for topic, _, _ in b.connections:
                stores.setdefault(topic, b.typestore)
        for t, topic, msgtype, data in self.raw_messages(topics):
            try:
                msg = stores[topic].deserialize_cdr(data, msgtype)
            except Exception:
                self.undecodable += 1
                continue
            yield BagMessage(topic, msgtype, t, msg)

    undecodable = 0

    def first_message(self, topic: str):
        """The first deserialised message of ``topic`` (None if there is none)."""
        for b in self.bags:
            for t, tp, msgtype, data in b.raw({topic}):
                try:
                    return b.typestore.deserialize_cdr(data, msgtype)
                except Exception:
                    return None
        return None

    def detect_topics(self) -> dict[str, list[str]]:
        """:func:`detect_topics` over this set, peeking into PointCloud2 topics."""
        clouds = [t.topic for t in self.topics if t.msgtype in ROLE_TYPES['radar_clouds']]
        return detect_topics(self.topics, first_messages={t: self.first_message(t) for t in clouds})

    def _check(self):
        if self.strict and self.problems:
            raise self.problems[0]


def open_bags(paths, *, strict: bool = False) -> BagSet:
    """Open bags (rosbag2 directories, ``.mcap`` or ``.db3`` files) for reading.

    Raises :class:`BagError` ('missing', 'not_a_bag', 'corrupt') when a bag cannot be
    opened. A bag whose index is damaged (truncated MCAP) is read by scanning its records:
    the readable messages are yielded and the damage is listed in ``problems``;
    ``strict=True`` raises it after the last readable message instead.
    """
    return BagSet(paths, strict=strict)


def detect_topics(connections, first_messages=None) -> dict[str, list[str]]:
    """Input topics per role by message type (:data:`ROLE_TYPES`): ``{'radar_clouds': [...],
    'radar_scans': [...], 'pose_arrays': [...], 'tracked_objects': [...],
    'detected_objects': [...], 'odometry': [...]}``, empty roles omitted, topics sorted.
    Object roles are all read by ``msg_adapters.tracked_objects.read_objects``.

    connections: :class:`TopicInfo` s or anything with ``topic`` and ``msgtype``.
    PointCloud2 topics count as radar when their first message (``first_messages[topic]``)
    has a Doppler field, or -- without a message -- when the topic name says 'radar'.
    Raises ``BagError('no_usable_topic')`` when no input topic is found.
    """
    from msg_adapters.pointcloud2 import DOPPLER_NAMES
    first_messages = first_messages or {}
    roles: dict[str, list[str]] = {}
    for c in sorted(connections, key=lambda c: c.topic):
        for role, types in ROLE_TYPES.items():
            if c.msgtype not in types:
                continue
            if role == 'radar_clouds':
                msg = first_messages.get(c.topic)
                names = {str(f.name) for f in getattr(msg, 'fields', [])}
                if not (names & set(DOPPLER_NAMES) if msg is not None else 'radar' in c.topic.lower()):
                    continue
            roles.setdefault(role, []).append(c.topic)
    if 'odometry' in roles:  # prefer localisation output over wheel odometry
        roles['odometry'].sort(key=lambda t: ('localization' not in t and 'kinematic' not in t, t))
    if not any(r in roles for r in _INPUT_ROLES):
        have = ', '.join(f'{c.topic} [{c.msgtype}]' for c in connections) or 'no topics'
        raise BagError('no_usable_topic', f'no radar, object or detection topic among: {have}')
    return roles


# ----------------------------------------------------------------------------- MCAP scan

_MAGIC = b'\x89MCAP0\r\n'


def _has_mcap_magic(path: Path) -> bool:
    try:
        with path.open('rb') as f:
            return f.read(8) == _MAGIC
    except OSError:
        return False


def _decompress(kind: str, data: bytes, size: int, partial: bool) -> bytes:
    if kind == '':
        return data
    if kind == 'zstd':
        import zstandard
        d = zstandard.ZstdDecompressor()
        return d.decompressobj().decompress(data) if partial else d.decompress(data, max_output_size=size)
    if kind == 'lz4':
        import lz4.frame
        return lz4.frame.decompress(data)
    raise BagError('corrupt', f'unsupported chunk compression {kind!r}')


class _Buf:
    """Little-endian cursor over bytes; ``short`` is raised when the data ends early."""

    class Short(Exception):
        pass

    def __init__(self, data: bytes):
        self.data, self.pos = data, 0

    def take(self, n: int) -> bytes:
        if self.pos + n > len(self.data):
            raise _Buf.Short()
        out = self.data[self.pos:self.pos + n]
        self.pos += n
        return out

    def u(self, fmt: str) -> int:
        return struct.unpack('<' + fmt, self.take(struct.calcsize(fmt)))[0]

    def string(self) -> str:
        return self.take(self.u('I')).decode('utf-8', 'replace')


def _records(buf: _Buf, path) -> Iterator[tuple]:
    """Schema / channel / message records of a record stream (file body or chunk)."""
    while buf.pos < len(buf.data):
        try:
            op, n = buf.u('B'), buf.u('Q')
            body = _Buf(buf.take(n))
        except _Buf.Short:
            raise BagError('truncated', f'file ends inside a record at byte {buf.pos}', path) from None
        if op == 0x02:  # footer: the file is complete
            return
        try:
            yield from _record(op, body, n, path)
        except _Buf.Short:
            raise BagError('corrupt', f'record 0x{op:02x} shorter than its fields', path) from None


def _record(op: int, body: _Buf, n: int, path) -> Iterator[tuple]:
    if op == 0x03:
        sid, name, enc = body.u('H'), body.string(), body.string()
        yield ('schema', sid, name, enc, body.take(body.u('I')).decode('utf-8', 'replace'))
    elif op == 0x04:
        cid, sid, topic, _enc = body.u('H'), body.u('H'), body.string(), body.string()
        yield ('channel', cid, topic, 'cdr', sid)
    elif op == 0x05:
        cid, _seq, log_time, _pub = body.u('H'), body.u('I'), body.u('Q'), body.u('Q')
        yield ('message', cid, log_time, body.data[body.pos:])
    elif op == 0x06:
        _st, _et, usize, _crc = body.u('Q'), body.u('Q'), body.u('Q'), body.u('I')
        kind, clen = body.string(), body.u('Q')
        raw = body.data[body.pos:body.pos + clen]
        try:
            data = _decompress(kind, raw, usize, partial=False)
        except BagError:
            raise
        except Exception as exc:
            raise BagError('corrupt', f'chunk does not decompress: {exc}', path) from exc
        yield from _records(_Buf(data), path)


def _scan_mcap(path: Path) -> Iterator[tuple]:
    """Records of an MCAP file front to back; a cut-off last chunk yields its readable part.

    Yields ('schema', id, name, encoding, text), ('channel', id, topic, 'cdr', schema_id),
    ('message', channel_id, log_time_ns, data). Raises BagError('truncated') when the
    file ends before its footer.
    """
    data = path.read_bytes()
    if data[:8] != _MAGIC:
        raise BagError('not_a_bag', 'no MCAP magic', path)
    buf = _Buf(data)
    buf.pos = 8
    while buf.pos < len(data):
        start = buf.pos
        try:
            op, n = buf.u('B'), buf.u('Q')
        except _Buf.Short:
            break
        if op == 0x02:
            return
        if buf.pos + n > len(data):
            if op == 0x06:
                yield from _partial_chunk(data[buf.pos:], path)
            raise BagError('truncated', f'file ends inside a record at byte {start} of {len(data)}', path)
        body = _Buf(data[buf.pos:buf.pos + n])
        buf.pos += n
        try:
            yield from _record(op, body, n, path)
        except _Buf.Short:
            raise BagError('corrupt', f'record 0x{op:02x} at byte {start} shorter than its fields',
                           path) from None
    raise BagError('truncated', f'file ends after {len(data)} bytes without an MCAP footer', path)


def _partial_chunk(body: bytes, path) -> Iterator[tuple]:
    """Whole records from the decodable prefix of a chunk cut off by truncation."""
    try:
        b = _Buf(body)
        _st, _et, usize, _crc = b.u('Q'), b.u('Q'), b.u('Q'), b.u('I')
        kind, _clen = b.string(), b.u('Q')
        data = _decompress(kind, body[b.pos:], usize, partial=True)
    except Exception:
        return
    inner = _Buf(data)
    while True:
        try:
            op, n = inner.u('B'), inner.u('Q')
            rec = _Buf(inner.take(n))
            recs = list(_record(op, rec, n, path))
        except (_Buf.Short, BagError):
            return
        yield from recs


# ----------------------------------------------------------------------------- writing


def _qos_latched():
    from rosbags.interfaces import (Qos, QosDurability, QosHistory, QosLiveliness,
                                    QosReliability, QosTime)
    zero = QosTime(0, 0)
    return [Qos(QosHistory.KEEP_LAST, 1, QosReliability.RELIABLE, QosDurability.TRANSIENT_LOCAL,
                zero, zero, QosLiveliness.AUTOMATIC, zero, False)]


#: Topics recorded with TRANSIENT_LOCAL (latched) QoS by :class:`BagWriter` by default.
LATCHED = ('/tf_static',)


class BagWriter:
    """Write a rosbag2 MCAP bag (zstd-compressed chunks) with rosbags.

    >>> with BagWriter('out_bag') as w:
    ...     w.write('/topic', msg, t)   # msg built with w.types; t in seconds

    Connections are added on first write (type from the message); latched topics
    (``latched`` or names ending in ``markers``) get TRANSIENT_LOCAL QoS. ``chunk_bytes``
    bounds the uncompressed chunk size, so that a truncated bag loses little.
    """

    def __init__(self, path, *, store=None, compress: bool = True, chunk_bytes: int = 256 * 1024,
                 latched: Iterable[str] = LATCHED):
        from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin, Writer
        from msg_adapters.types import RosbagsTypes
        self.path = Path(path)
        if self.path.exists():
            raise BagError('exists', 'output bag exists already, not overwriting', self.path)
        self.store = store or typestore()
        self.types = RosbagsTypes(self.store)
        self.latched = set(latched)
        self.chunk_bytes = int(chunk_bytes)
        self._w = Writer(self.path, version=9, storage_plugin=StoragePlugin.MCAP)
        if compress:
            self._w.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
        self._w.open()
        self._conns = {}

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def connection(self, topic: str, msgtype: str):
        if topic not in self._conns:
            qos = _qos_latched() if (topic in self.latched or topic.endswith('markers')) else ()
            self._conns[topic] = self._w.add_connection(topic, msgtype, typestore=self.store,
                                                        offered_qos_profiles=qos)
        return self._conns[topic]

    def write(self, topic: str, msg, t: float, msgtype: str | None = None) -> None:
        """Serialise and write ``msg`` at bag time ``t`` [s]."""
        msgtype = msgtype or msg.__msgtype__
        self.write_raw(topic, msgtype, self.store.serialize_cdr(msg, msgtype), t)

    def write_raw(self, topic: str, msgtype: str, data: bytes, t: float) -> None:
        """Write CDR bytes (e.g. from ``rclpy.serialization.serialize_message``)."""
        conn = self.connection(topic, msgtype)
        self._w.write(conn, int(round(t * 1e9)), data)
        storage = getattr(self._w, 'storage', None)
        chunk = getattr(storage, 'chunk', None)
        if chunk is not None and chunk.bio.tell() > self.chunk_bytes and hasattr(storage, 'close_chunk'):
            storage.close_chunk()

    def close(self) -> None:
        if self._w is not None:
            self._w.close()
            self._w = None


# ----------------------------------------------------------------------------- scenario bags


def scenario_mount(scenario) -> tuple[float, float, float]:
    """Radar mount (x, y, yaw) in base_link: from sensor_xy vs the ego pose, else the config."""
    ego = scenario.ego
    for mode in ('raw', 'tracked', 'heading'):
        try:
            d = scenario.detections(mode)
        except Exception:
            continue
        ok = np.isfinite(d.sensor_xy).all(axis=1)
        if not ok.any():
            continue
        i = np.clip(np.searchsorted(ego.t, d.t[ok] - 1e-9), 0, len(ego.t) - 1)
        off = d.sensor_xy[ok] - ego.xy[i]
        c, s = np.cos(ego.yaw[i]), np.sin(ego.yaw[i])
        local = np.stack([c * off[:, 0] + s * off[:, 1], -s * off[:, 0] + c * off[:, 1]], axis=1)
        mx, my = np.round(np.median(local, axis=0), 9) + 0.0
        return float(mx), float(my), 0.0
    return float(getattr(scenario.config, 'sensor_mount', 0.0)), 0.0, 0.0


_mount_of = scenario_mount   # old private name, used by soak


def _tf_static(types, t: float, parent: str, child: str, mount) -> object:
    from msg_adapters._common import quat_from_yaw
    from msg_adapters.types import make_header
    g = types.get
    qx, qy, qz, qw = (float(v) for v in quat_from_yaw(mount[2]))
    tr = g('geometry_msgs/msg/Transform')(
        translation=g('geometry_msgs/msg/Vector3')(x=mount[0], y=mount[1], z=0.0),
        rotation=g('geometry_msgs/msg/Quaternion')(x=qx, y=qy, z=qz, w=qw))
    ts = g('geometry_msgs/msg/TransformStamped')(header=make_header(types, parent, t),
                                                 child_frame_id=child, transform=tr)
    return g('tf2_msgs/msg/TFMessage')(transforms=[ts])


def _yaw_rate(t, yaw):
    if len(t) < 2:
        return np.zeros(len(t))
    return np.gradient(np.unwrap(yaw), t)


@dataclass
class ScenarioBagInfo:
    """What :func:`write_scenario_bag` wrote: topics with message counts, the radar mount,
    bag time of scenario t = 0, and the size in bytes."""

    path: Path
    counts: dict = field(default_factory=dict)
    mount: tuple = (0.0, 0.0, 0.0)
    t0: float = BAG_T0
    size: int = 0


def scenario_messages(scenario, types, sensors=('tracked', 'raw', 'heading'), autoware: bool = True,
                      t0: float = BAG_T0, mount=None) -> Iterator[tuple[float, str, object]]:
    """``(t, topic, msg)`` of a simulated scenario in time order, messages built with ``types``.

    What :func:`write_scenario_bag` records (see there), also usable without a bag (soak,
    DDS tests with ``RclpyTypes``; there ``/tf_static`` is left out when ``tf2_msgs`` is not
    importable). ``mount`` defaults to :func:`scenario_mount`.
    """
    from msg_adapters.odometry import odometry_msg
    from msg_adapters.pointcloud2 import radar_cloud_msg
    from msg_adapters.pose_array import pose_array_msg
    from msg_adapters.tracked_objects import autoware_tracked_objects_msg, tracked_object_array_msg
    from msg_adapters.types import make_header

    ego = scenario.ego
    fx, base, radar = SCENARIO_FRAMES['fixed'], SCENARIO_FRAMES['base'], SCENARIO_FRAMES['radar']
    mount = scenario_mount(scenario) if mount is None else mount
    frames = {s: scenario.frames(s) for s in sensors}
    rate = _yaw_rate(ego.t, ego.yaw)
    try:
        yield t0 + float(ego.t[0]), SCENARIO_TOPICS['tf_static'], _tf_static(
            types, t0 + float(ego.t[0]), base, radar, mount)
    except ImportError:   # rclpy namespace without tf2_msgs (no wheel): no /tf_static
        pass
    for i, te in enumerate(ego.t):
        t = t0 + float(te)
        yield t, SCENARIO_TOPICS['odometry'], odometry_msg(
            types, t, ego.xy[i, 0], ego.xy[i, 1], ego.yaw[i], vx=ego.speed[i], yaw_rate=rate[i],
            frame_id=fx, child_frame_id=base)
        for s, it in frames.items():
            stamp, d = next(it)
            ts = t0 + stamp
            if s == 'raw':
                yield ts, SCENARIO_TOPICS['radar'], radar_cloud_msg(
                    types, make_header(types, radar, ts),
                    _to_sensor(d.xy, (ego.xy[i, 0], ego.xy[i, 1], ego.yaw[i]), mount), d.doppler, d.rcs)
            elif s == 'tracked':
                args = (make_header(types, fx, ts), d.track_id, d.xy, d.heading, d.speed, d.label)
                yield ts, SCENARIO_TOPICS['objects'], tracked_object_array_msg(types, *args)
                if autoware:
                    yield ts, SCENARIO_TOPICS['autoware'], autoware_tracked_objects_msg(types, *args)
            elif s == 'heading':
                yield ts, SCENARIO_TOPICS['detections'], pose_array_msg(
                    types, make_header(types, fx, ts), d.xy, d.heading)


def write_scenario_bag(scenario, path, sensors=('tracked', 'raw', 'heading'), autoware: bool = True,
                       t0: float = BAG_T0) -> ScenarioBagInfo:
    """Write a simulated scenario as a rosbag2 MCAP bag on the node's input topics.

    Topics (:data:`SCENARIO_TOPICS`), bag time = header stamp = ``t0`` + scenario time:

    * ``/localization/odometry`` nav_msgs/Odometry ``map`` -> ``base_link`` every ego cycle,
      twist in base_link (vx = speed, yaw rate);
    * ``/tf_static`` tf2_msgs/TFMessage ``base_link`` -> ``radar`` (the mount, once, latched);
    * ``/perception/radar/points`` ('raw') PointCloud2 in ``radar``: x, y, z, doppler, rcs
      float32 in the sensor frame (the simulator's fixed-frame points mapped through the
      ego pose and the mount, which is recovered from ``sensor_xy``);
    * ``/perception/objects`` ('tracked') our TrackedObjectArray in ``map``;
    * ``/perception/autoware/objects`` ('tracked', ``autoware=True``) Autoware
      TrackedObjects in ``map`` (schema embedded in the bag);
    * ``/perception/detections`` ('heading') geometry_msgs/PoseArray in ``map``.

    Every sensor topic gets a message per cycle (empty ones too). Deterministic.
    """
    mount = scenario_mount(scenario)
    info = ScenarioBagInfo(Path(path), mount=mount, t0=t0)
    with BagWriter(path) as w:
        for t, topic, msg in scenario_messages(scenario, w.types, sensors, autoware, t0, mount):
            w.write(topic, msg, t)
            info.counts[topic] = info.counts.get(topic, 0) + 1
    info.size = sum(f.stat().st_size for f in Path(path).iterdir())
    return info


def _to_sensor(xy, ego_pose, mount) -> np.ndarray:
    """Fixed-frame points (N, 2) -> the frame of a sensor mounted on the ego."""
    sx, sy, syaw = _compose(ego_pose, mount)
    c, s = math.cos(syaw), math.sin(syaw)
    dx, dy = xy[:, 0] - sx, xy[:, 1] - sy
    return np.stack([c * dx + s * dy, -s * dx + c * dy], axis=1)


def _compose(pose, mount):
    x, y, yaw = pose
    c, s = math.cos(yaw), math.sin(yaw)
    return x + c * mount[0] - s * mount[1], y + s * mount[0] + c * mount[1], yaw + mount[2]

