"""Writing rosbag2 MCAP bags (zstd chunks) with rosbags."""

from __future__ import annotations

from pathlib import Path
from typing import Iterable

from .errors import BagError
from .typestore import typestore

__all__ = ['BagWriter', 'LATCHED']

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
