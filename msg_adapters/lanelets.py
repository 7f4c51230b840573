"""``intersection_estimator_msgs/msg/LaneletArray`` <-> list of :class:`model.Lanelet`."""

from __future__ import annotations

import numpy as np

from intersection_estimator.model import Lanelet

from .errors import guarded

__all__ = ['KINDS', 'lanelets_msg', 'read_lanelets']

#: Lanelet kind -> Lanelet.KIND_* constant.
KINDS = {'entering': 0, 'leaving': 1, 'connector': 2}


def _points(types, pl):
    return types.points(pl)


def lanelets_msg(types, header, lanelets, samples: int = 0):
    """LaneletArray of ``lanelets`` (polylines in the header frame, z = 0)."""
    Ll = types.get('intersection_estimator_msgs/msg/Lanelet')
    items = [Ll(id=str(ll.id), kind=KINDS[ll.kind], arm=int(ll.arm), arm_to=int(ll.arm_to),
                lane_index=int(ll.lane_index), left=_points(types, ll.left),
                right=_points(types, ll.right), center_line=_points(types, ll.center),
                successors=[str(s) for s in ll.successors], confidence=float(ll.confidence))
             for ll in lanelets]
    return types.get('intersection_estimator_msgs/msg/LaneletArray')(
        header=header, lanelets=items, samples=int(samples))


def _xy(points) -> np.ndarray:
    return np.array([(p.x, p.y) for p in points], dtype=np.float64).reshape(-1, 2)


@guarded
def read_lanelets(msg) -> list[Lanelet]:
    """LaneletArray -> lanelets (unknown kinds read as 'connector')."""
    names = {v: k for k, v in KINDS.items()}
    return [Lanelet(id=str(ll.id), kind=names.get(int(ll.kind), 'connector'), arm=int(ll.arm),
                    left=_xy(ll.left), right=_xy(ll.right), center=_xy(ll.center_line),
                    successors=[str(s) for s in ll.successors], arm_to=int(ll.arm_to),
                    lane_index=int(ll.lane_index), confidence=float(ll.confidence))
            for ll in msg.lanelets]
