"""Reading rosbag2 bags (MCAP, sqlite3) as one time-ordered stream, and their input topics.

Each bag is read with the rosbags reader, or -- when its index is damaged -- by scanning
MCAP records (:mod:`.mcap_scan`), and decoded with the schemas *it* embeds: several bags
never share a topic's types or messages (a bag without a topic yields nothing for it).
The same bag given twice (same file, or a copy with the same topics, counts and time
span) is read once and said so in :attr:`BagSet.notes`.
"""

from __future__ import annotations

from dataclasses import dataclass
import heapq
from pathlib import Path
import struct
from typing import Iterator

from ..roles import INPUT_ROLES, ODOMETRY, ROLE_TYPES, role_of_type
from .errors import BagError
from .mcap_scan import collect, has_mcap_magic, scan_mcap
from .typestore import bag_typestore

__all__ = ['TopicInfo', 'BagMessage', 'BagSet', 'open_bags', 'detect_topics']

_CLOUD = ROLE_TYPES['radar_topics'][0]


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
        self.typestore = bag_typestore(
            (c.msgtype, c.msgdef.format.name.lower(), c.msgdef.data) for c in reader.connections)
        self.connections = [(c.topic, c.msgtype, c.msgcount) for c in reader.connections]

    def _open_fallback(self, exc):
        """The rosbags reader refused the bag: scan MCAP records if there are any."""
        files = _mcap_files(self.path) if (self.path.is_dir() or self.path.suffix == '.mcap') else []
        if not files or not all(has_mcap_magic(f) for f in files):
            what = 'not a rosbag2 bag (no metadata.yaml, .mcap or .db3)' if not files else 'no MCAP magic'
            raise BagError('not_a_bag', f'{what}: {exc}', self.path) from exc
        self._scan_files = files
        schemas, channels, counts, problem, times = {}, {}, {}, None, []
        for f in files:
            try:
                for rec in scan_mcap(f):
                    collect(rec, schemas, channels, counts)
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
        self.typestore = bag_typestore(
            (schemas[s][0], schemas[s][1], schemas[s][2]) for _, _, s in channels.values() if s in schemas)
        self.connections = [(t, schemas.get(s, ('',))[0], counts.get(cid, 0))
                            for cid, (t, _, s) in channels.items()]

    @property
    def signature(self) -> tuple:
        """What the bag holds (topics, types, counts, time span): equal for copies of a bag."""
        return tuple(sorted(self.connections)), self.span

    def raw(self, topics: set | None) -> Iterator[tuple[int, str, str, bytes]]:
        """(t_ns, topic, msgtype, cdr bytes) in bag order; stops at the first damage.
        Only the bag's own topics among ``topics``: none of them, no message."""
        if topics is not None and not any(t in topics for t, _, _ in self.connections):
            return
        if self._reader is not None:
            yield from self._raw_reader(topics)
        else:
            yield from self._raw_scan(topics)

    def _raw_reader(self, topics):
        # never connections=[]: rosbags reads *every* connection then
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
                for rec in scan_mcap(f):
                    if rec[0] != 'message':
                        collect(rec, schemas, channels, {})
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


def _unique(paths: list[Path], notes: list[str]) -> list[Path]:
    """``paths`` without repeats of one file or directory (noted)."""
    seen, out = {}, []
    for p in paths:
        key = p.resolve() if p.exists() else p
        if key in seen:
            notes.append(f'{p}: given twice (as {seen[key]}); read once')
            continue
        seen[key] = p
        out.append(p)
    return out


class BagSet:
    """Several bags read as one time-ordered stream (see :func:`open_bags`)."""

    def __init__(self, paths, *, strict: bool = False):
        paths = [Path(paths)] if isinstance(paths, (str, Path)) else [Path(p) for p in paths]
        self.notes: list[str] = []
        paths = _unique([q for p in paths for q in _expand(p)], self.notes)
        if not paths:
            raise BagError('missing', 'no bag given')
        self.strict = strict
        self.bags: list[_Bag] = []
        try:
            for p in paths:
                self._add(_Bag(p))
        except BagError:
            self.close()
            raise

    def _add(self, bag: _Bag) -> None:
        same = next((b for b in self.bags if bag.connections and b.signature == bag.signature), None)
        if same is None:
            self.bags.append(bag)
            return
        self.notes.append(f'{bag.path}: the same topics, message counts and time span as {same.path} '
                          '(a copy?); read once')
        bag.close()

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

    def _tagged(self, topics) -> Iterator[tuple[int, int, str, str, bytes]]:
        """(t_ns, bag index, topic, msgtype, CDR bytes), merged by time over all bags
        (ties in the order the bags were given)."""
        sel = None if topics is None else set(topics)
        streams = [((t, i, topic, mt, data) for t, topic, mt, data in b.raw(sel))
                   for i, b in enumerate(self.bags)]
        yield from streams[0] if len(streams) == 1 else heapq.merge(*streams, key=lambda r: r[0])
        self._check()

    def raw_messages(self, topics=None) -> Iterator[tuple[int, str, str, bytes]]:
        """(t_ns, topic, msgtype, CDR bytes), merged by time over all bags."""
        for t, _, topic, msgtype, data in self._tagged(topics):
            yield t, topic, msgtype, data

    def messages(self, topics=None) -> Iterator[BagMessage]:
        """Deserialised :class:`BagMessage` s (each with its own bag's types), merged by time;
        undecodable ones are skipped and counted in :attr:`undecodable`."""
        self.undecodable = 0
        for t, i, topic, msgtype, data in self._tagged(topics):
            try:
                msg = self.bags[i].typestore.deserialize_cdr(data, msgtype)
            except Exception:
                self.undecodable += 1
                continue
            yield BagMessage(topic, msgtype, t, msg)

    undecodable = 0

    def first_message(self, topic: str):
        """The first deserialised message of ``topic`` (None if there is none)."""
        for b in self.bags:
            for _, _, msgtype, data in b.raw({topic}):
                try:
                    return b.typestore.deserialize_cdr(data, msgtype)
                except Exception:
                    return None
        return None

    def detect_topics(self) -> dict[str, list[str]]:
        """:func:`detect_topics` over this set, peeking into PointCloud2 topics."""
        clouds = [t.topic for t in self.topics if t.msgtype == _CLOUD]
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


def cloud_fields(msg) -> list[str]:
    """Field names of a PointCloud2 message (empty for None)."""
    return [str(f.name) for f in getattr(msg, 'fields', None) or []]


def _is_radar_cloud(topic: str, msg) -> bool:
    """A PointCloud2 topic is radar when its first message has a Doppler field, or --
    without a message -- when its name says 'radar'."""
    from msg_adapters.pointcloud2 import DOPPLER_NAMES
    if msg is None:
        return 'radar' in topic.lower()
    return bool(set(cloud_fields(msg)) & set(DOPPLER_NAMES))


def detect_topics(connections, first_messages=None) -> dict[str, list[str]]:
    """Input topics per input role (:data:`~intersection_estimator.roles.ROLE_TYPES`), found by
    message type: ``{'radar_topics': [...], 'object_topics': [...], ..., 'odometry_topic': [...]}``,
    empty roles omitted, topics sorted (odometry: localisation output first).

    connections: :class:`TopicInfo` s or anything with ``topic`` and ``msgtype``.
    PointCloud2 topics count as radar when their first message (``first_messages[topic]``)
    has a Doppler field, or -- without a message -- when the topic name says 'radar'.
    Raises ``BagError('no_doppler')`` when the only candidates are PointCloud2 topics
    without a Doppler field, ``BagError('no_usable_topic')`` when there is no input topic.
    """
    first_messages = first_messages or {}
    roles: dict[str, list[str]] = {}
    no_doppler = []
    for c in sorted(connections, key=lambda c: c.topic):
        role = role_of_type(c.msgtype)
        if role == 'radar_topics' and not _is_radar_cloud(c.topic, first_messages.get(c.topic)):
            no_doppler.append(c.topic)
            continue
        if role is not None:
            roles.setdefault(role, []).append(c.topic)
    if ODOMETRY in roles:  # prefer localisation output over wheel odometry
        roles[ODOMETRY].sort(key=lambda t: ('localization' not in t and 'kinematic' not in t, t))
    if not any(r in roles for r in INPUT_ROLES):
        if no_doppler:
            from msg_adapters.pointcloud2 import DOPPLER_NAMES
            have = '; '.join(f'{t} [fields {", ".join(cloud_fields(first_messages.get(t))) or "?"}]'
                             for t in no_doppler)
            raise BagError('no_doppler', f'PointCloud2 topic without a Doppler field (none of '
                           f'{", ".join(DOPPLER_NAMES)}): {have}; name the field with the doppler_field '
                           'parameter (--params) if it has another name')
        have = ', '.join(f'{c.topic} [{c.msgtype}]' for c in connections) or 'no topics'
        raise BagError('no_usable_topic', f'no radar, object or detection topic among: {have}')
    return roles
