"""Lane-course step (paper §III): lanelet graph, initialisation, MCMC, refinement.

>>> est = LaneCourseEstimator(LaneConfig(), seed)
>>> est.initialise(topology, dets)        # trajectories = rows with track_id >= 0
>>> est.run(n_samples=20000)              # or run(time_budget_s=...)
>>> est.lanelets                          # entering, leaving, connector model.Lanelet

Modules (one concern each, paper names):

* ``model``      lanelet graph as flat arrays; border points shared by reference
                 (consecutive lanelets' end points for good, neighbours' interior
                 points as split/merge pairs); center = midpoint of opposing border
                 points, exported with the doubled discretisation.
* ``init``       trajectories split at the point closest to the center, parts
                 assigned to the closest lane of their direction (mean of the points
                 beyond the stop line), arms and lane positions re-fitted to the
                 traffic, stop-line distance from the kerb geometry, lanelets and
                 connectors (only where a trajectory connects two lanes).
* ``stops``      path model of the turning traffic: stop lines fitted to it, one-sided
                 trajectories completed by it.
* ``moves``, ``prior``, ``likelihood``, ``mcmc``
                 the paper's sampler: center/border point moves, split (Delta b ~
                 U[0, 0.6 m]) and merge; prior s(I2)^tau prod N(delta_l); likelihood
                 sum_l 1(t, l) prod_p N(d_perp); compiled, incremental, annealed,
                 deterministic per seed.
* ``refine``     penalised least squares over the lateral point offsets (the
                 Meyer 2020 B-spline refinement done as a discrete smoothing spline).

Decisions beyond the paper (see the module docstrings): lanes end at a stop line
derived from the neighbouring arms (kerb radius) and fitted to the turning traffic;
connectors start as circular-arc-like cubic Bezier curves tangent to their lanes
(``connector_arc=0`` gives the paper's straight lanelets); the smoothness prior is
centred on each lanelet's own turn. Measured on the simulator (``docs`` of the
report, 100-200 cases): the structured initialisation is what reaches < 10 cm; the
MCMC keeps it (best state) and the least-squares refinement made it worse on this
data (refine=0 by default, kept configurable).
"""

from .config import LaneConfig
from .estimator import LaneCourseEstimator, lanelets_from_topology

__all__ = ['LaneConfig', 'LaneCourseEstimator', 'lanelets_from_topology']
