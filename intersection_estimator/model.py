"""Intersection model exchanged between the estimator steps (paper §II-B, §III-B).

Conventions (used by simulator, estimator, evaluator, exports and the node):

* Fixed frame, metres, radians (REP 103). ``Arm.angle`` is the heading of the arm
  from the center outward, normalised to ``[-pi, pi)``.
* ``u = (cos a, sin a)`` points outward along the arm, ``n = (-sin a, cos a)`` is its
  left normal (looking outward). With right-hand traffic the *entering* lanes lie on
  the ``+n`` side and the *leaving* lanes on the ``-n`` side; left-hand traffic flips
  the sign (``traffic_side = -1``).
* Lane ``k`` (0 = next to the median) of either direction has its center line at the
  lateral offset ``side * (gap / 2 + (k + 0.5) * lane_width)``, with ``side = +1`` for
  entering and ``-1`` for leaving lanes (times ``traffic_side``).
* In the topology step (paper §II-B) every lane is a straight ray starting at the
  center ``c``; the lane-course step (paper §III) turns them into lanelets.
  ``Arm.offset`` (beyond the paper, 0 by default) moves an arm's axis sideways along ``n``
  (arms of real junctions do not meet in one point): its rays start at ``c + offset n``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import math

import numpy as np

ENTERING = 1
LEAVING = -1

__all__ = [
    'topology_key',
    'ENTERING', 'LEAVING', 'Arm', 'Intersection', 'Lanelet',
    'wrap_angle', 'lane_offset', 'unit_vectors', 'direction_class',
]


def topology_key(t: 'Intersection', center_m: float, angle_deg: float, gap_m: float | None = None,
                 width_m: float | None = None) -> tuple:
    """A hashable summary of ``t`` at the given resolutions (center [m], arm angles [deg],
    optionally gaps and lane widths [m]; lane counts and the traffic side exactly): two
    topologies with equal keys are the same to whoever keys on them (the lane estimator's
    warm start; the pipeline's "re-initialise the lane course")."""
    def q(v, step):
        return round(float(v) / step)
    arms = tuple((q(math.degrees(a.angle), angle_deg),)
                 + ((q(a.gap, gap_m),) if gap_m else ()) + (a.lanes_in, a.lanes_out)
                 + ((q(a.lane_width, width_m),) if width_m else ()) for a in t.arms)
    return (q(t.center[0], center_m), q(t.center[1], center_m), t.traffic_side, arms)


def wrap_angle(a):
    """Wrap an angle (scalar or array) to ``[-pi, pi)``."""
    return (np.asarray(a) + math.pi) % (2.0 * math.pi) - math.pi


def unit_vectors(vx, vy):
    """``(ux, uy, ok)``: the directions of the vectors ``(vx, vy)``; (0, 0) and ``ok``
    False where a vector is shorter than 1e-9."""
    n = np.hypot(vx, vy)
    ok = n > 1e-9
    with np.errstate(invalid='ignore', divide='ignore'):
        return np.where(ok, vx / n, 0.0), np.where(ok, vy / n, 0.0), ok


def direction_class(x, y, hx, hy, center):
    """``ENTERING`` where the heading ``(hx, hy)`` at ``(x, y)`` points towards ``center``
    (an entering vehicle), else ``LEAVING`` (as floats)."""
    return np.where(hx * (center[0] - x) + hy * (center[1] - y) > 0,
                    float(ENTERING), float(LEAVING))


def lane_offset(gap: float, lane_width: float, k, direction: int, traffic_side: int = 1):
    """Signed lateral offset of lane ``k`` of ``direction`` from the arm axis (model docstring)."""
    side = (1.0 if direction == ENTERING else -1.0) * traffic_side
    return side * (0.5 * gap + (np.asarray(k) + 0.5) * lane_width)


@dataclass
class Arm:
    """One arm ``a = (alpha, g_a, L_a)`` of the topology model (paper §II-B)."""

    angle: float
    gap: float = 0.0
    lanes_in: int = 1
    lanes_out: int = 1
    lane_width: float = 3.5
    confidence: float = 1.0
    support: float = 0.0      # vehicle passages that the arm explains (beyond the paper)
    offset: float = 0.0       # axis offset along ``normal`` [m] (beyond the paper)
    bend: float = 0.0         # the axis turns by this [rad, left +] ... (beyond the paper)
    bend_at: float = 0.0      # ... this far out along it [m] (topology/arm_bend.py)

    @property
    def direction(self) -> np.ndarray:
        return np.array([math.cos(self.angle), math.sin(self.angle)])

    @property
    def normal(self) -> np.ndarray:
        return np.array([-math.sin(self.angle), math.cos(self.angle)])

    def half_width(self) -> float:
        """Distance from the line through the center at ``angle`` to the arm's outermost
        border on the wider side (the axis offset included)."""
        return 0.5 * self.gap + max(self.lanes_in, self.lanes_out) * self.lane_width + abs(self.offset)

    def lane_offsets(self, direction: int, traffic_side: int = 1) -> np.ndarray:
        """Lateral offsets of the lanes of ``direction`` from the line through the center
        at ``angle``: :func:`lane_offset` from the arm axis, plus the axis offset."""
        n = self.lanes_in if direction == ENTERING else self.lanes_out
        return self.offset + lane_offset(self.gap, self.lane_width, np.arange(n), direction,
                                         traffic_side)


@dataclass
class Intersection:
    """Intersection ``I = (c, A)`` (paper §II-B): center and arms sorted by angle."""

    center: np.ndarray
    arms: list[Arm] = field(default_factory=list)
    traffic_side: int = 1

    def __post_init__(self):
        self.center = np.asarray(self.center, dtype=float).reshape(2)
        self.arms = sorted(self.arms, key=lambda a: a.angle)

    @property
    def n_lanes(self) -> int:
        return sum(a.lanes_in + a.lanes_out for a in self.arms)

    def to_json(self) -> dict:
        """The ``center``/``arms`` part of ``estimate.json`` (DESIGN.md §4)."""
        return {
            'center': [float(self.center[0]), float(self.center[1])],
            'arms': [
                {'angle_deg': math.degrees(float(wrap_angle(a.angle))), 'gap_m': float(a.gap),
                 'lanes_in': int(a.lanes_in), 'lanes_out': int(a.lanes_out),
                 'lane_width_m': float(a.lane_width), 'confidence': float(a.confidence),
                 'support': float(a.support), 'offset_m': float(a.offset),
                 'bend_deg': math.degrees(float(a.bend)), 'bend_at_m': float(a.bend_at)}
                for a in self.arms
            ],
        }

    @classmethod
    def from_json(cls, d: dict) -> 'Intersection':
        arms = [Arm(angle=math.radians(a['angle_deg']), gap=a.get('gap_m', 0.0),
                    lanes_in=int(a['lanes_in']), lanes_out=int(a['lanes_out']),
                    lane_width=a.get('lane_width_m', 3.5), confidence=a.get('confidence', 1.0),
                    support=float(a.get('support', 0.0)), offset=float(a.get('offset_m', 0.0)),
                    bend=math.radians(float(a.get('bend_deg', 0.0))),
                    bend_at=float(a.get('bend_at_m', 0.0)))
                for a in d['arms']]
        return cls(center=np.asarray(d['center'], float), arms=arms,
                   traffic_side=int(d.get('traffic_side', 1)))


@dataclass
class Lanelet:
    """A lane course as lanelet (paper §III-B): two borders and a center line.

    ``kind`` is ``'entering'``, ``'leaving'`` or ``'connector'``. ``arm`` is the arm
    index (for connectors: the arm it comes from) and ``arm_to`` the arm a connector
    leads to (``-1`` otherwise). Polylines run in driving direction; ``left``/``right``
    are seen in driving direction. Consecutive lanelets share end points.
    """

    id: str
    kind: str
    arm: int
    left: np.ndarray
    right: np.ndarray
    center: np.ndarray
    successors: list[str] = field(default_factory=list)
    arm_to: int = -1
    lane_index: int = 0
    confidence: float = 1.0
    support: int = 0          # trajectories assigned to it (tracked input; 0 without tracks)

    def to_json(self) -> dict:
        def pl(a):
            return [[round(float(x), 4), round(float(y), 4)] for x, y in np.asarray(a)]
        return {'id': self.id, 'kind': self.kind, 'arm': int(self.arm), 'arm_to': int(self.arm_to),
                'lane_index': int(self.lane_index),
                'center_line': pl(self.center), 'left': pl(self.left), 'right': pl(self.right),
                'successors': list(self.successors), 'confidence': float(self.confidence),
                'support': int(self.support)}

    @classmethod
    def from_json(cls, d: dict) -> 'Lanelet':
        return cls(id=str(d['id']), kind=d['kind'], arm=int(d.get('arm', -1)),
                   left=np.asarray(d['left'], float).reshape(-1, 2),
                   right=np.asarray(d['right'], float).reshape(-1, 2),
                   center=np.asarray(d['center_line'], float).reshape(-1, 2),
                   successors=[str(s) for s in d.get('successors', [])],
                   arm_to=int(d.get('arm_to', -1)), lane_index=int(d.get('lane_index', 0)),
                   confidence=float(d.get('confidence', 1.0)),
                   support=int(d.get('support', 0)))
