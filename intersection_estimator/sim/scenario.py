"""Random ground-truth intersections (paper §IV, Table I) with lanelets and connectors.

Geometry follows :mod:`intersection_estimator.model`: arm angle = heading outward, lane
``k`` of either direction at ``lane_offset(gap, w, k, direction, traffic_side)``.
Every arm's lanes start at a stop line ``stop[a]`` metres from the center, far enough
that neighbouring arms do not overlap, and run ``arm_length`` metres outward.
Connectors are cubic Bezier curves, tangent-continuous with the lanes they join and
sharing their end points exactly (Lanelet2 routing, DESIGN.md §6).
"""

from __future__ import annotations

import math

import numpy as np

from ..model import ENTERING, LEAVING, Arm, Intersection, Lanelet, lane_offset, wrap_angle
from .config import SimConfig

__all__ = ['random_intersection', 'stop_distances', 'connector_pairs', 'build_lanelets',
           'lane_id', 'connector_id']

def lane_id(arm: int, direction: int, k: int) -> str:
    return f'a{arm}_{"in" if direction == ENTERING else "out"}{k}'


def connector_id(arm_from: int, k_in: int, arm_to: int, k_out: int) -> str:
    return f'c_a{arm_from}i{k_in}_a{arm_to}o{k_out}'


def _arm_angles(rng: np.random.Generator, n: int, min_deg: float) -> np.ndarray:
    """``n`` sorted angles with >= ``min_deg`` between neighbours (incl. wrap-around)."""
    slack = 2.0 * math.pi - n * math.radians(min_deg)
    if slack < 0:
        raise ValueError(f'{n} arms cannot be {min_deg} deg apart')
    gaps = math.radians(min_deg) + slack * rng.dirichlet(np.ones(n))
    angles = wrap_angle(rng.uniform(-math.pi, math.pi) + np.cumsum(gaps))
    return np.sort(angles)


def random_intersection(rng: np.random.Generator, cfg: SimConfig) -> Intersection:
    """Draw center and arms from the Table I ranges."""
    n = int(rng.integers(cfg.arms[0], cfg.arms[1] + 1))
    angles = _arm_angles(rng, n, cfg.min_arm_angle_deg)
    lanes = rng.integers(cfg.lanes[0], cfg.lanes[1] + 1, size=(n, 2))
    gaps = rng.uniform(0.0, cfg.gap_max, size=n)
    widths = rng.uniform(*cfg.lane_width, size=n)
    center = rng.uniform(-cfg.center_range, cfg.center_range, size=2)
    arms = [Arm(angle=float(a), gap=float(g), lanes_in=int(li), lanes_out=int(lo),
                lane_width=float(w))
            for a, g, (li, lo), w in zip(angles, gaps, lanes, widths)]
    return Intersection(center=center, arms=arms, traffic_side=cfg.traffic_side)


def _corner_distance(hw_i: float, hw_j: float, theta: float, radius: float) -> float:
    """Distance along arm i to clear neighbour j (angle theta) with a kerb of ``radius``.

    The borders of i and j meet ``(hw_j + hw_i cos theta) / sin theta`` out along i; a
    kerb arc of ``radius`` through the turn ``pi - theta`` needs ``radius tan((pi - theta)/2)``
    more.
    """
    if theta >= math.radians(160.0):
        return 0.0
    corner = (hw_j + hw_i * math.cos(theta)) / math.sin(theta)
    return max(0.0, corner + radius * math.tan(0.5 * (math.pi - theta)))


def stop_distances(rng: np.random.Generator, inter: Intersection, cfg: SimConfig) -> np.ndarray:
    """Stop-line distance per arm: clear of both neighbours' rounded corners + random margin."""
    arms = inter.arms
    n = len(arms)
    hw = np.array([a.half_width() for a in arms])
    ang = np.array([a.angle for a in arms])
    out = np.empty(n)
    for i in range(n):
        nxt, prv = (i + 1) % n, (i - 1) % n
        th_n = float((ang[nxt] - ang[i]) % (2 * math.pi))
        th_p = float((ang[i] - ang[prv]) % (2 * math.pi))
        out[i] = max(_corner_distance(hw[i], hw[nxt], th_n, cfg.kerb_radius),
                     _corner_distance(hw[i], hw[prv], th_p, cfg.kerb_radius), hw[i])
    return out + rng.uniform(*cfg.stop_margin, size=n)


def _turn(inter: Intersection, a: int, b: int) -> float:
    """Signed heading change entering at arm a and leaving at arm b (>0 = left)."""
    arms = inter.arms
    return float(wrap_angle(arms[b].angle - (arms[a].angle + math.pi)))


def _overlap(i: int, n: int, j: int, m: int) -> bool:
    """Do the unit-interval cells [i/n, (i+1)/n] and [j/m, (j+1)/m] overlap (open)?"""
    return i * m < (j + 1) * n and j * n < (i + 1) * m


def connector_pairs(inter: Intersection) -> list[tuple[int, int, int, int]]:
    """Which entering lane connects to which leaving lane: ``(a, k_in, b, k_out)``.

    Rules (no U-turns, no crossing connectors from one arm): destination arms are
    ordered from the sharpest turn towards the kerb side (right in right-hand traffic)
    to the sharpest turn across traffic; entering lanes from the kerb lane to the median
    lane. Lane r takes the destinations whose share of [0, 1] overlaps its own share, so
    kerb turns come from kerb lanes, turns across traffic from median lanes, straight
    from the middle (all lanes with one lane). Within a destination arm the same rule
    maps the source lanes onto its leaving lanes (kerb to kerb). Every entering lane
    has a connector and every leaving lane is reached.
    """
    ts = inter.traffic_side
    arms = inter.arms
    n = len(arms)
    pairs = []
    for a in range(n):
        dests = sorted((b for b in range(n) if b != a), key=lambda b: ts * _turn(inter, a, b))
        n_in = arms[a].lanes_in
        kerb_in = list(range(n_in - 1, -1, -1))  # lane index, kerb lane first
        for j, b in enumerate(dests):
            src = [kerb_in[r] for r in range(n_in) if _overlap(r, n_in, j, len(dests))]
            n_out = arms[b].lanes_out
            kerb_out = list(range(n_out - 1, -1, -1))
            for s, k_in in enumerate(src):
                for q, k_out in enumerate(kerb_out):
                    if _overlap(s, len(src), q, n_out):
                        pairs.append((a, k_in, b, k_out))
    return pairs


def _borders(center: np.ndarray, tangent: np.ndarray, half_width: np.ndarray):
    """Left/right borders at ``+-half_width`` along the left normal of ``tangent``."""
    t = tangent / np.linalg.norm(tangent, axis=1, keepdims=True)
    left_n = np.stack([-t[:, 1], t[:, 0]], axis=1)
    hw = np.asarray(half_width, float).reshape(-1, 1)
    return center + hw * left_n, center - hw * left_n


def _arm_lanelet(inter, a, direction, k, stop, length, spacing) -> Lanelet:
    arm = inter.arms[a]
    u, nrm = arm.direction, arm.normal
    off = float(lane_offset(arm.gap, arm.lane_width, k, direction, inter.traffic_side))
    m = max(2, int(math.ceil(length / spacing)) + 1)
    s = np.linspace(stop, stop + length, m)
    if direction == ENTERING:
        s = s[::-1]
    center = inter.center + s[:, None] * u + off * nrm
    tangent = np.broadcast_to(-u if direction == ENTERING else u, center.shape)
    left, right = _borders(center, tangent, np.full(m, 0.5 * arm.lane_width))
    kind = 'entering' if direction == ENTERING else 'leaving'
    return Lanelet(id=lane_id(a, direction, k), kind=kind, arm=a, left=left, right=right,
                   center=center, lane_index=k)


#: Tightest turn radius of a connector center line [m] (passenger cars turn >= ~5 m at
#: the kerb); the circular-arc handles below keep to it except for sharp turns between arms
#: whose lane ends are far from symmetric, which get asymmetric handles.
MIN_TURN_RADIUS = 4.0


def _max_curvature(p0, p1, p2, p3, n=200) -> float:
    """Largest curvature of a cubic Bezier (analytic, on ``n`` parameter values)."""
    t = np.linspace(0.0, 1.0, n)[:, None]
    v = 3 * (1 - t) ** 2 * (p1 - p0) + 6 * (1 - t) * t * (p2 - p1) + 3 * t ** 2 * (p3 - p2)
    a = 6 * (1 - t) * (p2 - 2 * p1 + p0) + 6 * t * (p3 - 2 * p2 + p1)
    cross = np.abs(v[:, 0] * a[:, 1] - v[:, 1] * a[:, 0])
    return float((cross / np.maximum(np.linalg.norm(v, axis=1), 1e-9) ** 3).max())


def _handles(p0, d0, p3, d3, shape: str = 'arc'):
    """Control points p1, p2 of a connector, its handles by ``SimConfig.turn_shape``
    (:data:`TURN_HANDLES`: :func:`_arc_handles`, :func:`_corner_handles`); if that turns
    tighter than MIN_TURN_RADIUS, the pair of handle lengths (0.1-1 chord each) with the
    gentlest turn."""
    chord = float(np.linalg.norm(p3 - p0))
    if shape not in TURN_HANDLES:
        raise ValueError(f'turn_shape {shape!r} is not one of {sorted(TURN_HANDLES)}')
    h0, h3 = TURN_HANDLES[shape](p0, d0, p3, d3, chord)
    p1, p2 = p0 + h0 * d0, p3 - h3 * d3
    if _max_curvature(p0, p1, p2, p3) * MIN_TURN_RADIUS <= 1.0:
        return p1, p2
    grid = np.linspace(0.1, 1.0, 10) * chord
    _, h0, h3 = min((_max_curvature(p0, p0 + a * d0, p3 - b * d3, p3), a, b) for a in grid for b in grid)
    return p0 + h0 * d0, p3 - h3 * d3


def _arc_handles(p0, d0, p3, d3, chord: float) -> tuple[float, float]:
    """Handle lengths of a circular arc through the turn angle: chord/3 straight, ~0.39
    chord at 90 deg, at most chord/2."""
    phi = math.acos(float(np.clip(np.dot(d0, d3), -1.0, 1.0)))
    ratio = 2.0 / 3.0 * math.tan(phi / 4) / math.sin(phi / 2) if phi > 1e-6 else 1.0 / 3.0
    h = chord * min(ratio, 0.5)
    return h, h


def _corner_handles(p0, d0, p3, d3, chord: float) -> tuple[float, float]:
    """Handle lengths of the quadratic Bezier through the corner where the entering lane's
    line (``p0`` along ``d0``) meets the leaving lane's (back from ``p3`` along ``d3``),
    raised to a cubic (2/3 of the way to the corner; SUMO draws its internal lanes this
    way): a family of its own, asymmetric where the lane ends are, apart from the circular
    arcs the estimator's connectors start from. Lines that meet behind an end or not at
    all (straight on): chord/3 each; at most one chord each (a near U-turn)."""
    A = np.column_stack([d0, d3])
    if abs(float(np.linalg.det(A))) > 1e-6:
        a, b = np.linalg.solve(A, p3 - p0)
        if a > 0 and b > 0:
            return min(2.0 / 3.0 * a, chord), min(2.0 / 3.0 * b, chord)
    return chord / 3.0, chord / 3.0


#: ``SimConfig.turn_shape`` -> handle lengths of a connector (:func:`_handles`)
TURN_HANDLES = {'arc': _arc_handles, 'corner': _corner_handles}


def _bezier(p0, d0, p3, d3, spacing, shape: str = 'arc'):
    """Cubic Bezier from p0 (heading d0) to p3 (heading d3): points, tangents, params."""
    p1, p2 = _handles(p0, d0, p3, d3, shape)
    fine = np.linspace(0.0, 1.0, 400)[:, None]
    pts = ((1 - fine) ** 3 * p0 + 3 * (1 - fine) ** 2 * fine * p1
           + 3 * (1 - fine) * fine ** 2 * p2 + fine ** 3 * p3)
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))])
    m = max(3, int(math.ceil(arc[-1] / spacing)) + 1)
    t = np.interp(np.linspace(0.0, arc[-1], m), arc, fine[:, 0])[:, None]
    pts = (1 - t) ** 3 * p0 + 3 * (1 - t) ** 2 * t * p1 + 3 * (1 - t) * t ** 2 * p2 + t ** 3 * p3
    tan = 3 * (1 - t) ** 2 * (p1 - p0) + 6 * (1 - t) * t * (p2 - p1) + 3 * t ** 2 * (p3 - p2)
    return pts, tan, t[:, 0]


def _connector(inter, a, k_in, b, k_out, lin: Lanelet, lout: Lanelet, spacing,
               shape: str = 'arc') -> Lanelet:
    d0 = -inter.arms[a].direction
    d3 = inter.arms[b].direction
    center, tan, t = _bezier(lin.center[-1], d0, lout.center[0], d3, spacing, shape)
    w = (1 - t) * inter.arms[a].lane_width + t * inter.arms[b].lane_width
    left, right = _borders(center, tan, 0.5 * w)
    # share the end points exactly with the lanes it joins (Lanelet2 routing)
    center[0], left[0], right[0] = lin.center[-1], lin.left[-1], lin.right[-1]
    center[-1], left[-1], right[-1] = lout.center[0], lout.left[0], lout.right[0]
    return Lanelet(id=connector_id(a, k_in, b, k_out), kind='connector', arm=a, arm_to=b,
                   left=left, right=right, center=center, lane_index=k_in,
                   successors=[lout.id])


def build_lanelets(rng: np.random.Generator, inter: Intersection, cfg: SimConfig,
                   stop: np.ndarray) -> list[Lanelet]:
    """Entering, leaving and connector lanelets; successors entering -> connector -> leaving."""
    lanes: dict[str, Lanelet] = {}
    for a, arm in enumerate(inter.arms):
        length = float(rng.uniform(*cfg.arm_length))
        for direction, n in ((ENTERING, arm.lanes_in), (LEAVING, arm.lanes_out)):
            for k in range(n):
                ll = _arm_lanelet(inter, a, direction, k, float(stop[a]), length, cfg.point_spacing)
                lanes[ll.id] = ll
    connectors = []
    for a, k_in, b, k_out in connector_pairs(inter):
        lin, lout = lanes[lane_id(a, ENTERING, k_in)], lanes[lane_id(b, LEAVING, k_out)]
        con = _connector(inter, a, k_in, b, k_out, lin, lout, cfg.point_spacing, cfg.turn_shape)
        lin.successors.append(con.id)
        connectors.append(con)
    return list(lanes.values()) + connectors
