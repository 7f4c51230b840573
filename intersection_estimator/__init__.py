"""Map-free lane-level intersection estimation (Meyer, Walter, Lauer, Stiller, ITSC 2019).

The core (everything here except :mod:`intersection_estimator.node`) is ROS-free.
"""

from . import _numba_cache

__version__ = '0.1.0'

_numba_cache.configure()      # before any kernel module is imported (numba cache safety)
