"""Reading a damaged MCAP file record by record, without its summary/index.

When the rosbags reader refuses a file (recording killed, copy cut short, corrupt index),
:func:`scan_mcap` walks the records front to back and yields schemas, channels and
messages as far as they can be read; a cut-off last chunk gives its decodable prefix.
Raises :class:`~.errors.BagError` ('truncated' / 'corrupt') where the damage starts.
"""

from __future__ import annotations

from pathlib import Path
import struct
from typing import Iterator

from .errors import BagError

__all__ = ['scan_mcap', 'has_mcap_magic', 'collect']

_MAGIC = b'\x89MCAP0\r\n'


def has_mcap_magic(path: Path) -> bool:
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


def scan_mcap(path: Path) -> Iterator[tuple]:
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


def collect(rec, schemas, channels, counts):
    kind = rec[0]
    if kind == 'schema':
        schemas[rec[1]] = rec[2:]
    elif kind == 'channel':
        channels[rec[1]] = rec[2:]
    elif kind == 'message':
        counts[rec[1]] = counts.get(rec[1], 0) + 1
