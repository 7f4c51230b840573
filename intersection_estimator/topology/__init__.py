"""Topology of the intersection (paper §II), one module per concept, compiled code beside
its maths (like :mod:`..lanes`):

* :mod:`.config` -- :class:`TopologyConfig` (every parameter, range, unit), the derived
  :class:`PreprocessConfig`, :class:`Tables`
* :mod:`.state` -- packed state / kernel-parameter layouts (named slots), :class:`Chain`
* :mod:`.moves` -- Algorithm 1: every move and :func:`propose`
* :mod:`.prior` -- P(I) (§II-C1); :mod:`.likelihood` -- P(Z|I) (§II-C2), ObservationSet
* :mod:`.mcmc` -- annealing schedule, the compiled chain loop, :class:`Posterior`
* :mod:`.preprocess`, :mod:`.voxels` -- detections -> observations (§II-A)
* :mod:`.init` -- data-driven initial state (center, arms, lanes)
* beyond the paper, each a function with explicit inputs: :mod:`.refit` (arm grid refit),
  :mod:`.descent` (greedy descent at the end of the schedule), :mod:`.support` (arms
  without support left out of the report)
* :mod:`.estimator` -- :class:`TopologyEstimator`, orchestration only
"""

from .config import PreprocessConfig, TopologyConfig
from .estimator import TopologyEstimator

__all__ = ['TopologyConfig', 'TopologyEstimator', 'PreprocessConfig']
