"""Lanelet graph of the lane-course step (paper §III-B) as flat arrays.

Every lanelet ``l`` has ``n_l`` *stations* (equidistant cross sections, driving
direction). Station ``g`` (global index) has a left and a right *slot*
(``2g`` and ``2g + 1``); each slot references a border *point* ``ref[slot]``.
Sharing is by reference:

* consecutive lanelets (entering -> connector -> leaving) and neighbouring lanes of
  one arm share their end points for good (one point, several slots);
* interior border points of neighbouring lanelets form split/merge *pairs*: merged,
  both slots reference one point; split, each references its own ``home`` point.

The center point of a station is ``(P[ref[2g]] + P[ref[2g+1]]) / 2`` (the paper's
``m`` between opposing border points). The exported center line doubles that
discretisation by adding the midpoint between consecutive center points (§III-A).
Each point moves along its lateral axis ``axis[p]`` only, which keeps the stations
equidistant and makes every sampled quantity one-dimensional (as in Meyer 2020).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..model import Lanelet

__all__ = ['LaneletSpec', 'LaneGraph', 'build_graph', 'doubled_center']


@dataclass
class LaneletSpec:
    """Geometry and sharing keys of one lanelet before it enters the graph.

    ``left_keys``/``right_keys``: per station a hashable key of a point shared for
    good, or ``None`` for a point of its own (only end stations may carry keys).
    """

    id: str
    kind: str
    arm: int
    left: np.ndarray
    right: np.ndarray
    left_keys: list
    right_keys: list
    arm_to: int = -1
    lane_index: int = 0
    lane_to: int = -1
    predecessor: int = -1          # spec index (connectors: the entering lanelet)
    successor: int = -1            # spec index (connectors: the leaving lanelet)
    successors: list = field(default_factory=list)  # spec indices
    evidence: int = 0


class LaneGraph:
    """Flat-array state of the lanelet model (see module docstring)."""

    __slots__ = ('specs', 'P', 'axis', 'ref', 'home', 'users', 'nusers', 'st_ll', 'st_off',
                 'st_n', 'st_normal', 'prev_st', 'next_st', 'pair_a', 'pair_b', 'pair_merged',
                 'kind_code')

    def n_stations(self) -> int:
        return len(self.st_ll)

    def station_range(self, lane: int) -> range:
        return range(self.st_off[lane], self.st_off[lane] + self.st_n[lane])

    def borders(self, lane: int) -> tuple[np.ndarray, np.ndarray]:
        g = np.arange(self.st_off[lane], self.st_off[lane] + self.st_n[lane])
        return self.P[self.ref[2 * g]].copy(), self.P[self.ref[2 * g + 1]].copy()

    def centers(self) -> np.ndarray:
        """Center point of every station, shape (n_stations, 2)."""
        return 0.5 * (self.P[self.ref[0::2]] + self.P[self.ref[1::2]])

    def n_shared(self) -> int:
        """s(I2): number of merged interior border pairs."""
        return int(self.pair_merged.sum())

    def copy_state(self):
        return self.P.copy(), self.ref.copy(), self.pair_merged.copy()

    def set_state(self, state) -> None:
        P, ref, merged = state
        self.P[:] = P
        self.ref[:] = ref
        self.pair_merged[:] = merged
        self.rebuild_users()

    def rebuild_users(self) -> None:
        """users[p, :nusers[p]] = the slots referencing point p."""
        order = np.argsort(self.ref, kind='stable')
        p = self.ref[order]
        counts = np.bincount(self.ref, minlength=len(self.P))
        rank = np.arange(len(p)) - (np.cumsum(counts) - counts)[p]
        self.users[:] = -1
        self.users[p, rank] = order
        self.nusers[:] = counts

    def lanelets(self) -> list[Lanelet]:
        """Export as :class:`model.Lanelet` (center line with doubled discretisation)."""
        out = []
        for i, sp in enumerate(self.specs):
            left, right = self.borders(i)
            out.append(Lanelet(id=sp.id, kind=sp.kind, arm=sp.arm, left=left, right=right,
                               center=doubled_center(0.5 * (left + right)),
                               successors=[self.specs[j].id for j in sp.successors],
                               arm_to=sp.arm_to, lane_index=sp.lane_index))
        return out


def doubled_center(c: np.ndarray) -> np.ndarray:
    """Insert the midpoint between consecutive center points (paper §III-A)."""
    c = np.asarray(c, float)
    if len(c) < 2:
        return c.copy()
    out = np.empty((2 * len(c) - 1, 2))
    out[0::2] = c
    out[1::2] = 0.5 * (c[:-1] + c[1:])
    return out


_KIND = {'entering': 0, 'leaving': 1, 'connector': 2}


def _unit_normal(left: np.ndarray, right: np.ndarray) -> np.ndarray:
    """Left normal per station from the center line's tangent (central differences)."""
    c = 0.5 * (left + right)
    t = np.gradient(c, axis=0) if len(c) > 1 else np.array([[1.0, 0.0]])
    t /= np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-12)
    return np.stack([-t[:, 1], t[:, 0]], axis=1)


def build_graph(specs: list[LaneletSpec], pairs: list[tuple], users_cap: int = 0) -> LaneGraph:
    """Build the flat graph. ``pairs``: ``((spec, station, side), (spec, station, side), merged)``."""
    g = LaneGraph()
    g.specs = specs
    n_st = np.array([len(s.left) for s in specs], np.int64)
    g.st_n = n_st
    g.st_off = np.concatenate([[0], np.cumsum(n_st)[:-1]]).astype(np.int64) if len(specs) else \
        np.zeros(0, np.int64)
    n_total = int(n_st.sum())
    g.st_ll = np.repeat(np.arange(len(specs)), n_st).astype(np.int64)
    g.kind_code = np.array([_KIND[s.kind] for s in specs], np.int64)
    # one point per slot (slot 2g = left, 2g + 1 = right of station g); slots with a
    # sharing key then reference the first point of that key (the others stay unused)
    L = np.concatenate([s.left for s in specs]).reshape(-1, 2) if specs else np.zeros((0, 2))
    R = np.concatenate([s.right for s in specs]).reshape(-1, 2) if specs else np.zeros((0, 2))
    normal = np.concatenate([_unit_normal(s.left, s.right) for s in specs]).reshape(-1, 2) \
        if specs else np.zeros((0, 2))
    pts = np.empty((2 * n_total, 2))
    pts[0::2], pts[1::2] = L, R
    axes = np.repeat(normal, 2, axis=0)
    ref = np.arange(2 * n_total, dtype=np.int64)
    keyed: dict = {}
    for li, sp in enumerate(specs):
        o = g.st_off[li]
        for side, keys in ((0, sp.left_keys), (1, sp.right_keys)):
            for i in (0, len(keys) - 1) if len(keys) else ():
                key = keys[i]
                if key is not None:
                    slot = 2 * (o + i) + side
                    ref[slot] = keyed.setdefault(key, slot)
    g.P = np.array(pts, float).reshape(-1, 2)
    g.axis = np.array(axes, float).reshape(-1, 2)
    g.home = ref.copy()
    g.ref = ref
    g.st_normal = normal
    # angle neighbours: connectors continue the predecessor / successor lanelet
    prev_st = np.full(n_total, -1, np.int64)
    next_st = np.full(n_total, -1, np.int64)
    for li, sp in enumerate(specs):
        o, n = g.st_off[li], n_st[li]
        prev_st[o + 1:o + n] = np.arange(o, o + n - 1)
        next_st[o:o + n - 1] = np.arange(o + 1, o + n)
        if sp.kind == 'connector':
            if sp.predecessor >= 0 and n_st[sp.predecessor] >= 2:
                p = sp.predecessor
                prev_st[o] = g.st_off[p] + n_st[p] - 2
            if sp.successor >= 0 and n_st[sp.successor] >= 2:
                prev_dummy = sp.successor
                next_st[o + n - 1] = g.st_off[prev_dummy] + 1
    g.prev_st, g.next_st = prev_st, next_st
    A = np.array([a for a, _, _ in pairs], np.int64).reshape(-1, 3)
    B = np.array([b for _, b, _ in pairs], np.int64).reshape(-1, 3)
    g.pair_a = 2 * (g.st_off[A[:, 0]] + A[:, 1]) + A[:, 2]
    g.pair_b = 2 * (g.st_off[B[:, 0]] + B[:, 1]) + B[:, 2]
    g.pair_merged = np.array([bool(m) for _, _, m in pairs], np.bool_)
    g.ref[g.pair_b[g.pair_merged]] = g.ref[g.pair_a[g.pair_merged]]
    counts = np.bincount(g.home, minlength=len(g.P)) if len(g.home) else np.zeros(len(g.P), int)
    cap = max(int(counts.max(initial=0)) + 2, users_cap, 4)
    g.users = np.full((len(g.P), cap), -1, np.int64)
    g.nusers = np.zeros(len(g.P), np.int64)
    g.rebuild_users()
    return g
