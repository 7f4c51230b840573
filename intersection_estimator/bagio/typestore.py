"""Message types for reading and writing bags: rosbags' Jazzy store + our messages + the
schemas of packages without a wheel (``msg_adapters/schemas``: Autoware, radar_msgs,
derived_object_msgs); per bag, the schemas it embeds win (:func:`bag_typestore`)."""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path
import sys
from typing import Iterable

from .errors import BagError

__all__ = ['typestore', 'schema_dirs', 'bag_typestore']

_MSGS_PKG = 'intersection_estimator_msgs'


def _msg_dirs() -> list[tuple[str, Path]]:
    """(package, msg dir) of our messages: installed share dir first, else the source tree."""
    cands = []
    try:
        from ament_index_python.packages import get_package_share_directory
        cands.append(Path(get_package_share_directory(_MSGS_PKG)) / 'msg')
    except Exception:  # not on AMENT_PREFIX_PATH: fine, try the others
        pass
    cands.append(Path(sys.prefix) / 'share' / _MSGS_PKG / 'msg')
    cands.append(Path(__file__).resolve().parents[2] / 'msgs' / _MSGS_PKG / 'msg')
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


def bag_typestore(schemas: Iterable[tuple[str, str, str]]):
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
