"""The one way a configuration checks its values: a table ``name -> (interval, meaning)``.

``interval`` is written as in mathematics, ``'[0, 1]'``, ``'(0, inf)'``, ``'[1, 1e6]'``; a
bound may name another field of the same configuration (``'(0, t_start]'``); ``None``
means "any value". A value outside (NaN included) raises ``ValueError`` naming the field,
its value, the interval and what it means, e.g. ``LaneConfig.sigma_perp=-1 outside
[0.01, 10.0] (std of d_perp in the likelihood [m])``.
"""

from __future__ import annotations

import re

import numpy as np

__all__ = ['check_range', 'check_table', 'check_labels']

_INTERVAL = re.compile(r'^([\[(])\s*([^,]+?)\s*,\s*([^\]\)]+?)\s*([\])])$')


def _bound(cfg, text: str) -> float:
    return float(getattr(cfg, text)) if text.isidentifier() and text != 'inf' else float(text)


def check_range(cfg, name: str, interval: str | None, what: str, label: str | None = None) -> None:
    """Raise ValueError unless ``cfg.<name>`` lies in ``interval``."""
    if interval is None:
        return
    m = _INTERVAL.match(interval)
    if m is None:
        raise ValueError(f'bad interval {interval!r} for {name}')
    opn, lo, hi, cls = m.groups()
    v = getattr(cfg, name)
    lo, hi = _bound(cfg, lo), _bound(cfg, hi)
    try:
        ok = (lo < v if opn == '(' else lo <= v) and (v < hi if cls == ')' else v <= hi)
    except TypeError:
        ok = False
    if not ok:
        raise ValueError(f'{label or type(cfg).__name__}.{name}={v!r} outside {interval} ({what})')


def check_table(cfg, table: dict, label: str | None = None) -> None:
    """:func:`check_range` for every entry of ``table`` (name -> (interval, meaning))."""
    for name, (interval, what) in table.items():
        check_range(cfg, name, interval, what, label)


def check_labels(cfg, name: str, label: str | None = None) -> None:
    """Raise ValueError unless ``cfg.<name>`` is a tuple of integer classification labels
    (``bool`` is not one)."""
    v = getattr(cfg, name)
    if not (isinstance(v, tuple) and all(isinstance(x, (int, np.integer)) and not isinstance(x, bool)
                                         for x in v)):
        raise ValueError(f'{label or type(cfg).__name__}.{name}={v!r}: needs a tuple of integer labels')
