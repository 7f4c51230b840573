"""Lane-course step (paper §III): lanelet graph, initialisation, MCMC, refinement."""

from .config import LaneConfig
from .estimator import LaneCourseEstimator, lanelets_from_topology

__all__ = ['LaneConfig', 'LaneCourseEstimator', 'lanelets_from_topology']
