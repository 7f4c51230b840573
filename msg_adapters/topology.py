"""``intersection_estimator_msgs/msg/Topology`` <-> :class:`model.Intersection` (DESIGN.md §4)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from intersection_estimator.model import Arm, Intersection

from ._common import header_of
from .errors import guarded

__all__ = ['STATES', 'topology_msg', 'read_topology', 'TopologyInfo']

#: Estimator state name -> Topology.state constant.
STATES = {'NO_DATA': 0, 'CONVERGING': 1, 'CONVERGED': 2}


def _state(state) -> int:
    if isinstance(state, str):
        return STATES[state.upper()]
    return int(state)


def topology_msg(types, header, intersection: Intersection | None, samples: int = 0,
                 log_posterior: float | None = None, n_obs: int = 0, state='NO_DATA'):
    """Topology message; ``intersection=None`` gives an empty estimate (center 0, no arms).

    state: 'NO_DATA' | 'CONVERGING' | 'CONVERGED' or the constant; log_posterior None -> NaN.
    """
    g = types.get
    ArmMsg = g('intersection_estimator_msgs/msg/Arm')
    arms, center = [], (0.0, 0.0)
    if intersection is not None:
        center = (float(intersection.center[0]), float(intersection.center[1]))
        arms = [ArmMsg(angle=float(a.angle), gap=float(a.gap), lanes_in=int(a.lanes_in),
                       lanes_out=int(a.lanes_out),
                       lane_widths_in=np.full(int(a.lanes_in), float(a.lane_width)),
                       lane_widths_out=np.full(int(a.lanes_out), float(a.lane_width)),
                       confidence=float(a.confidence), offset=float(a.offset))
                for a in intersection.arms]
    lp = math.nan if log_posterior is None else float(log_posterior)
    return g('intersection_estimator_msgs/msg/Topology')(
        header=header, center=g('geometry_msgs/msg/Point')(x=center[0], y=center[1], z=0.0),
        arms=arms, samples=int(samples), log_posterior=lp, observations=int(n_obs),
        state=_state(state))


@dataclass
class TopologyInfo:
    """A decoded Topology message (``intersection`` is None without arms)."""

    frame_id: str
    stamp: float
    intersection: Intersection | None
    samples: int
    log_posterior: float
    observations: int
    state: str


@guarded
def read_topology(msg) -> TopologyInfo:
    """Topology message -> :class:`TopologyInfo`; lane width = mean of the lane widths."""
    frame_id, stamp = header_of(msg)
    arms = []
    for a in msg.arms:
        widths = np.concatenate([np.asarray(a.lane_widths_in, float), np.asarray(a.lane_widths_out, float)])
        arms.append(Arm(angle=float(a.angle), gap=float(a.gap), lanes_in=int(a.lanes_in),
                        lanes_out=int(a.lanes_out),
                        lane_width=float(widths.mean()) if len(widths) else 3.5,
                        confidence=float(a.confidence),
                        offset=float(getattr(a, 'offset', 0.0))))   # absent in older recordings
    inter = Intersection(center=[msg.center.x, msg.center.y], arms=arms) if arms else None
    names = {v: k for k, v in STATES.items()}
    return TopologyInfo(frame_id, stamp, inter, int(msg.samples), float(msg.log_posterior),
                        int(msg.observations), names.get(int(msg.state), str(int(msg.state))))
