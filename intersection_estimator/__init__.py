"""Map-free lane-level intersection estimation (Meyer, Walter, Lauer, Stiller, ITSC 2019).

The core (everything here except :mod:`intersection_estimator.node`) is ROS-free.
"""

__version__ = '0.1.0'
