"""Lanelet2 OSM export of the lane course (DESIGN.md §6).

* Every :class:`model.Lanelet` becomes a relation ``type=lanelet, subtype=road`` with
  its left and right border as linestrings (``location=urban, one_way=yes``, our id in
  ``ie:id``, connectors with Autoware's ``turn_direction`` straight/left/right).
* Border points with the same coordinates (the lane-course graph shares them by
  construction: consecutive lanelets' end points, neighbours' border points) become
  one node, so routing sees consecutive lanelets as connected. A border that is the
  same node sequence as another lanelet's border (or its reverse) is the same way.
* Line types: borders of connectors (inside the intersection) are ``virtual``; a
  border shared by two lanes of the same direction is ``line_thin``/``dashed``; other
  borders ``line_thin``/``solid``.
* Coordinates are metric in the local fixed frame; they are written with
  ``lanelet2.projection.LocalCartesianProjector(Origin(*origin_latlon))`` -- load
  with the same projector and origin to get the metric coordinates back. Points also
  carry ``local_x``/``local_y`` tags (Autoware convention). Ids are positive and
  unique (points, ways, relations from one counter starting at 1).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ['write_osm', 'projector', 'turn_direction', 'load_osm']

_QUANT = 1e-4  # coordinates equal to this resolution are the same node [m]
STRAIGHT_DEG = 30.0


def projector(origin_latlon=(49.0, 8.4)):
    """The projector the map is written with (local Cartesian around the origin)."""
    from lanelet2.io import Origin
    from lanelet2.projection import LocalCartesianProjector
    return LocalCartesianProjector(Origin(float(origin_latlon[0]), float(origin_latlon[1])))


def turn_direction(center: np.ndarray) -> str:
    """'straight' / 'left' / 'right' from the heading change along a center line."""
    c = np.asarray(center, float)
    if len(c) < 2:
        return 'straight'
    d0, d1 = c[1] - c[0], c[-1] - c[-2]
    turn = math.degrees(math.atan2(d0[0] * d1[1] - d0[1] * d1[0], d0 @ d1))
    if abs(turn) < STRAIGHT_DEG:
        return 'straight'
    return 'left' if turn > 0 else 'right'


def _key(p) -> tuple:
    return (int(round(float(p[0]) / _QUANT)), int(round(float(p[1]) / _QUANT)))


def write_osm(path, lanelets, origin_latlon=(49.0, 8.4)):
    """Write ``lanelets`` (list of :class:`model.Lanelet`) as a Lanelet2 OSM map; returns ``path``."""
    import lanelet2
    from lanelet2.core import AttributeMap, LaneletMap, LineString3d, Point3d
    from lanelet2.core import Lanelet as LL

    ids = iter(range(1, 1 << 62))
    nodes: dict = {}
    ways: dict = {}

    def node(p):
        k = _key(p)
        if k not in nodes:
            x, y = float(p[0]), float(p[1])
            nodes[k] = Point3d(next(ids), x, y, 0.0,
                               AttributeMap({'local_x': f'{x:.4f}', 'local_y': f'{y:.4f}'}))
        return nodes[k]

    # who uses which border (by node sequence): decides sharing and line type
    users: dict = {}
    for l in lanelets:
        for b in (l.left, l.right):
            seq = tuple(_key(p) for p in b)
            users.setdefault(min(seq, seq[::-1]), []).append(l)

    def way(b, owner):
        seq = tuple(_key(p) for p in b)
        canon = min(seq, seq[::-1])
        if canon not in ways:
            us = users[canon]
            if any(u.kind == 'connector' for u in us):
                attrs = {'type': 'virtual'}
            elif len(us) > 1 and len({u.kind for u in us}) == 1:
                attrs = {'type': 'line_thin', 'subtype': 'dashed'}
            else:
                attrs = {'type': 'line_thin', 'subtype': 'solid'}
            pts = [node(p) for p in (b if seq == canon else b[::-1])]
            ways[canon] = LineString3d(next(ids), pts, AttributeMap(attrs))
        ls = ways[canon]
        return ls if seq == canon else ls.invert()

    lmap = LaneletMap()
    for l in lanelets:
        attrs = {'type': 'lanelet', 'subtype': 'road', 'location': 'urban', 'one_way': 'yes',
                 'ie:id': str(l.id), 'ie:kind': l.kind}
        if l.kind == 'connector':
            attrs['turn_direction'] = turn_direction(l.center)
        lmap.add(LL(next(ids), way(l.left, l), way(l.right, l), AttributeMap(attrs)))
    lanelet2.io.write(str(path), lmap, projector(origin_latlon))
    return path


def load_osm(path, origin_latlon=(49.0, 8.4)):
    """Load a map written by :func:`write_osm` back into metric coordinates."""
    import lanelet2
    return lanelet2.io.load(str(path), projector(origin_latlon))
