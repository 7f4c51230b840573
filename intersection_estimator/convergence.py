"""The reported estimator state, with hysteresis, so that a user can gate on it.

The topology sampler's own test (``TopologyEstimator.state``: no better sample in the last
``converge_window`` steps) is a statement about the chain, and with data arriving every
tick it flips CONVERGING <-> CONVERGED nearly every tick (35 changes in the 106 ticks of a
replay of ``bags/tracked``). What a user needs to know is whether the *estimate* has
settled. The states (``~/topology`` ``state``, ``/diagnostics``, ``estimate.json``):

``NO_DATA``
    No estimate: nothing observed yet, or everything was dropped (e.g. after the ego passed
    an intersection and the estimator started on the next one).
``CONVERGING``
    An estimate exists but is still changing: its structure (number of arms, lanes in / out
    per arm) changed, or its center or an arm angle moved more than ``center_tol_m`` /
    ``angle_tol_deg``, within the last ``enter_s`` seconds of data time -- or the sampler has
    not settled once since. Use it, if at all, as a preview.
``CONVERGED``
    The estimate has kept its structure, and its center and arm angles within the
    tolerances, for at least ``enter_s`` seconds of data time, and the sampler settled
    (its own plateau test) at least once meanwhile. It stays CONVERGED while it is refined
    within the tolerances (the lanelets' geometry and the confidences may still improve),
    and through changes that last less than ``exit_s`` (one tick's flicker); a change that
    persists ``exit_s`` returns it to CONVERGING.

Times are data time (the stamps the estimate is made of, like every output), so the state
does not depend on the tick rate or the machine's speed. The state never feeds back into
the estimate: it is computed from what the estimator reports, after the fact.
"""

from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np

from .ranges import check_table

__all__ = ['ConvergenceConfig', 'ConvergenceTracker', 'same_estimate', 'STATES']

STATES = ('NO_DATA', 'CONVERGING', 'CONVERGED')


_RANGES = {'enter_s': ('[0, 600]', 'stable this long before CONVERGED [s]'),
           'exit_s': ('[0, 600]', 'a change must last this long to leave CONVERGED [s]'),
           'center_tol_m': ('(0, 100]', 'center moves within this are refinement [m]'),
           'angle_tol_deg': ('(0, 90]', 'arm angle moves within this are refinement [deg]')}


@dataclass(frozen=True)
class ConvergenceConfig:
    """Hysteresis of the reported state (see the module docstring)."""

    enter_s: float = 2.0          # stable this long (data time) before CONVERGED [s]
    exit_s: float = 1.0           # a change must last this long to leave CONVERGED [s]
    center_tol_m: float = 2.0     # center moves within this are refinement [m]
    angle_tol_deg: float = 10.0   # arm angle moves within this are refinement [deg]

    def validate(self) -> 'ConvergenceConfig':
        """Raise ValueError naming the first parameter outside its allowed range."""
        check_table(self, _RANGES, 'convergence')
        return self


def _same_arm(x, y, tol: float) -> bool:
    return ((int(x.lanes_in), int(x.lanes_out)) == (int(y.lanes_in), int(y.lanes_out))
            and abs(math.remainder(float(x.angle) - float(y.angle), 2 * math.pi)) <= tol)


def same_estimate(a, b, cfg: ConvergenceConfig) -> bool:
    """Do intersections ``a`` and ``b`` describe the same junction up to refinement? Same
    number of arms, centers within ``center_tol_m``, and the arms pair up (in angular order,
    whichever arm comes first: an angle may cross +-pi) with the same lanes in / out and
    angles within ``angle_tol_deg``."""
    if a is None or b is None or len(a.arms) != len(b.arms):
        return False
    d = np.asarray(a.center, float) - np.asarray(b.center, float)
    if not float(np.hypot(d[0], d[1])) <= cfg.center_tol_m:
        return False
    tol, n = math.radians(cfg.angle_tol_deg), len(a.arms)
    return n == 0 or any(all(_same_arm(a.arms[i], b.arms[(i + k) % n], tol) for i in range(n))
                         for k in range(n))


class ConvergenceTracker:
    """Turns each tick's (data time, sampler state, estimate) into the reported state."""

    def __init__(self, config: ConvergenceConfig | None = None):
        self.config = (config or ConvergenceConfig()).validate()
        self.reset()

    def reset(self) -> None:
        """Back to NO_DATA (a new intersection, or the window emptied)."""
        self.state = 'NO_DATA'
        self._anchor = None          # the estimate the stability is measured against
        self._since = -math.inf      # data time the anchor was set (CONVERGING)
        self._settled = False        # sampler plateau seen since the anchor was set
        self._changed_at = None      # data time a change from the anchor began (CONVERGED)
        self.transitions = 0         # state changes since the reset

    def _set(self, state: str) -> None:
        if state != self.state:
            self.transitions += 1
            self.state = state

    def _restart(self, now: float, inter, settled: bool) -> None:
        self._anchor, self._since, self._settled, self._changed_at = inter, now, settled, None

    def update(self, now: float, sampler_state: str, intersection) -> str:
        """The state after a tick at data time ``now`` that reported ``intersection`` with the
        sampler's own ``sampler_state``; returns it (also in :attr:`state`)."""
        cfg = self.config
        if intersection is None or sampler_state == 'NO_DATA':
            self._anchor = None
            self._set('NO_DATA')
            return self.state
        settled = sampler_state == 'CONVERGED'
        if self._anchor is None:
            self._restart(now, intersection, settled)
            self._set('CONVERGING')
        same = same_estimate(intersection, self._anchor, cfg)
        if self.state == 'CONVERGED':
            if same:
                self._anchor, self._changed_at = intersection, None   # follows refinement
            elif self._changed_at is None:
                self._changed_at = now
            elif now - self._changed_at >= cfg.exit_s:
                self._restart(now, intersection, settled)
                self._set('CONVERGING')
            return self.state
        if not same:
            self._restart(now, intersection, settled)
        self._settled |= settled
        if self._settled and now - self._since >= cfg.enter_s:
            self._anchor, self._changed_at = intersection, None
            self._set('CONVERGED')
        return self.state
