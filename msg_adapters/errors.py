"""The one exception adapters raise: :class:`AdapterError` with a stable reason key.

The node rate-limits its warnings and counts drops per ``reason``; keep the keys short
and stable. Keys used by the adapters:

``malformed``        a field is missing or has the wrong type / shape
``truncated``        ``data`` is shorter than the layout says (PointCloud2)
``bad_layout``       inconsistent ``point_step`` / ``row_step`` / sizes
``missing_field``    a required PointCloud2 field (x, y) is absent
``unknown_datatype`` a PointField datatype outside INT8..FLOAT64
``field_overflow``   a field reaches beyond ``point_step``
``too_large``        more points than the configured ``max_points``
``unknown_type``     a message of no supported family
``unknown_frame``    a frame that is neither fixed, ego nor a configured mount
``no_ego_pose``      no ego pose for the stamp (empty buffer or outside it)
``non_finite``       a non-finite stamp or ego pose
``frame_mismatch``   odometry in another fixed frame than configured
"""

from __future__ import annotations

import functools

__all__ = ['AdapterError', 'guarded']


class AdapterError(ValueError):
    """A message that cannot be converted; ``reason`` is a stable key for rate limiting."""

    def __init__(self, reason: str, message: str = ''):
        super().__init__(f'{reason}: {message}' if message else reason)
        self.reason = reason
        self.message = message or reason


def guarded(func):
    """Turn the accidental exceptions of a malformed message into ``AdapterError('malformed')``.

    Readers touch attributes of arbitrary objects; a missing attribute, a string where a
    number belongs or a ragged array must not escape a subscription callback as anything
    but an :class:`AdapterError`.
    """
    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        try:
            return func(*args, **kwargs)
        except AdapterError:
            raise
        except (AttributeError, TypeError, ValueError, IndexError, KeyError,
                OverflowError, UnicodeError) as exc:
            raise AdapterError('malformed', f'{func.__name__}: {type(exc).__name__}: {exc}') from exc
    return wrapper
