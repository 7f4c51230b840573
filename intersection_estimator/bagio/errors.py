"""The one exception of :mod:`intersection_estimator.bagio`."""

from __future__ import annotations

__all__ = ['BagError']

#: Stable ``BagError.reason`` keys.
REASONS = ('missing', 'not_a_bag', 'corrupt', 'truncated', 'no_usable_topic', 'no_doppler', 'exists',
           'duplicate')


class BagError(Exception):
    """A bag that cannot be used; ``reason`` is a stable key, ``str()`` one line."""

    def __init__(self, reason: str, message: str, path=None):
        self.reason, self.message, self.path = reason, ' '.join(str(message).split()), path
        where = f'{path}: ' if path is not None else ''
        super().__init__(f'{reason}: {where}{self.message}')
