"""Lanelet2 OSM export of the lane course (DESIGN.md §6).

* Every :class:`model.Lanelet` becomes a relation ``type=lanelet, subtype=road`` with
  its left and right border as linestrings (``location=urban, one_way=yes``, our id in
  ``ie:id``, connectors with Autoware's ``turn_direction`` straight/left/right).
* Border points with the same coordinates (the lane-course graph shares them by
  construction: consecutive lanelets' end points, neighbours' border points) become
  one node, so routing sees consecutive lanelets as connected. A border that is the
  same node sequence as another lanelet's border (or its reverse) is the same way.
* Neighbouring lanes of one direction (same arm and kind) share their border *way*:
  when one lane's right border and the other's left border run point by point within
  :data:`MERGE_TOL` (an estimate may leave them a few cm apart), their points are merged
  into one node each (at the mean position), so the two lanelets reference one
  linestring and lanelet2's RoutingGraph offers a lane change between them.
* lanelet2's loader orients each lanelet's borders by their middle vertices (``geometry::
  align``: the right border's middle vertex must lie right of the left border, the left
  border's left of the right one; else it inverts a border). The inner border of a turn
  tighter than half the lane width, offset from its center line, folds back over itself, its
  middle vertex lies on the wrong side, and the loaded connector's right border ran
  backwards -- the routing graph dropped the turn (78 of 3912 SUMO connectors). A border
  whose middle vertex would mislead the loader gets a point of the right side at its middle
  index instead (:func:`_aligned`; the geometry is unchanged).
* Line types: borders of connectors (inside the intersection) are ``virtual``; a
  border shared by two lanes of the same direction is ``line_thin``/``dashed`` (lane
  change allowed); other borders -- the median, the road edge -- ``line_thin``/``solid``.
* Coordinates are metric in the local fixed frame; they are written with
  ``lanelet2.projection.LocalCartesianProjector(Origin(lat, lon))`` around the geo origin
  ``origin_latlon`` (default :data:`DEFAULT_ORIGIN`), and the origin is written into the
  file as ``<geoReference lat= lon= alt= projector="LocalCartesian"/>`` (an element OSM
  readers and lanelet2 skip): :func:`load_osm` / :func:`read_origin` take it from there,
  so the metric coordinates come back without knowing the origin. Points also carry
  ``local_x``/``local_y`` tags (Autoware convention). Ids are positive and unique
  (points, ways, relations from one counter starting at 1).
"""

from __future__ import annotations

from dataclasses import replace
import math
from pathlib import Path
import re
import xml.etree.ElementTree as ET

import numpy as np

from ..components import components

__all__ = ['write_osm', 'projector', 'turn_direction', 'load_osm', 'read_origin', 'check_origin',
           'parse_origin', 'DEFAULT_ORIGIN', 'MERGE_TOL']

_QUANT = 1e-4  # coordinates equal to this resolution are the same node [m]
STRAIGHT_DEG = 30.0
#: geo origin (lat, lon) [deg] when none is given (Karlsruhe, the paper's test area)
DEFAULT_ORIGIN = (49.0, 8.4)
#: neighbouring same-direction borders this close point by point are one linestring [m]
MERGE_TOL = 0.5


def check_origin(origin_latlon, name: str = 'origin_latlon') -> tuple[float, float]:
    """(lat, lon) as floats; ValueError naming ``name`` unless finite, |lat| <= 90, |lon| <= 180."""
    try:
        lat, lon = (float(v) for v in origin_latlon)
    except (TypeError, ValueError):
        raise ValueError(f'{name} must be two numbers (latitude, longitude) in degrees, '
                         f'got {origin_latlon!r}') from None
    if not (math.isfinite(lat) and math.isfinite(lon) and abs(lat) <= 90.0 and abs(lon) <= 180.0):
        raise ValueError(f'{name}=({lat}, {lon}) out of range: latitude in [-90, 90], '
                         f'longitude in [-180, 180] degrees')
    return lat, lon


def parse_origin(text: str, name: str = '--origin') -> tuple[float, float]:
    """'LAT,LON' (or 'LAT LON') -> (lat, lon), for a command-line option named ``name``."""
    parts = [p for p in re.split(r'[,\s]+', str(text).strip()) if p]
    if len(parts) != 2:
        raise ValueError(f'{name} must be LAT,LON in degrees (e.g. 49.0,8.4), got {text!r}')
    return check_origin(parts, name)


def projector(origin_latlon=DEFAULT_ORIGIN):
    """The projector the map is written with (local Cartesian around the origin)."""
    from lanelet2.io import Origin
    from lanelet2.projection import LocalCartesianProjector
    lat, lon = check_origin(origin_latlon)
    return LocalCartesianProjector(Origin(lat, lon))


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


class _Signed:
    """lanelet2's signed distance (left > 0) of points to ``line``, as its loader computes it
    (its own ``toArcCoordinates``; the linestring is built once)."""

    def __init__(self, line: np.ndarray):
        from lanelet2.core import LineString3d, Point3d
        from lanelet2.geometry import to2D
        self._ls = to2D(LineString3d(0, [Point3d(0, float(x), float(y), 0.0) for x, y in line]))

    def __call__(self, P: np.ndarray) -> np.ndarray:
        """Signed distances of the points ``P`` (m, 2)."""
        from lanelet2.core import BasicPoint2d
        from lanelet2.geometry import toArcCoordinates
        return np.array([toArcCoordinates(self._ls, BasicPoint2d(float(x), float(y))).distance
                         for x, y in np.atleast_2d(P)])


def _middle(line: np.ndarray) -> np.ndarray:
    return line[len(line) // 2] if len(line) > 2 else 0.5 * (line[0] + line[-1])


def _centred(line: np.ndarray, other: np.ndarray, side: float, step: float = 0.1) -> np.ndarray:
    """``line`` with a point of the ``side`` (+1 left, -1 right) of ``other`` at its middle
    index: the one nearest its half length, inserted on its segment, and the segments on the
    side with fewer vertices split at their midpoints until it sits there (unchanged when its
    middle vertex already lies there, or when no point of it does)."""
    signed = _Signed(other)
    if side * signed(_middle(line))[0] > 0:
        return line
    seg = np.hypot(*np.diff(line, axis=0).T)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    q = np.linspace(0.0, s[-1], max(3, int(s[-1] / step) + 1))[1:-1]
    cand = np.stack([np.interp(q, s, line[:, 0]), np.interp(q, s, line[:, 1])], 1)
    good = np.flatnonzero(side * signed(cand) > 0)
    if not len(good):
        return line
    k = good[np.argmin(np.abs(q[good] - 0.5 * s[-1]))]
    j = int(np.searchsorted(s, q[k], 'right'))            # the point goes before vertex j
    before, after = list(line[:j]), list(line[j:])
    while len(before) != len(after):                     # split the fewer side's longest segment
        part = before if len(before) < len(after) else after
        ends = part + [cand[k]] if part is before else [cand[k]] + part
        i = int(np.argmax(np.hypot(*np.diff(np.array(ends), axis=0).T)))
        part.insert(i + 1 if part is before else i, 0.5 * (ends[i] + ends[i + 1]))
    return np.array(before + [cand[k]] + after)


def _aligned(l):
    """``l`` with borders whose middle vertices lanelet2's loader reads the right way round
    (module doc)."""
    left, right = np.asarray(l.left, float), np.asarray(l.right, float)
    if len(left) < 2 or len(right) < 2:
        return l
    right = _centred(right, left, -1.0)
    left = _centred(left, right, +1.0)
    return replace(l, left=left, right=right)


def _key(p) -> tuple:
    return (int(round(float(p[0]) / _QUANT)), int(round(float(p[1]) / _QUANT)))


class _Nodes:
    """Point keys -> one node per group (the connected components of the merged pairs; its
    smallest key names it), position = group mean."""

    def __init__(self, lanelets, pairs=()):
        self.xy: dict = {}
        for l in lanelets:
            for b in (l.left, l.right):
                for p in np.asarray(b, float).reshape(-1, 2):
                    self.xy[_key(p)] = p
        self.root = {k: g[0] for g in components(sorted(self.xy), pairs) for k in g}

    def positions(self) -> dict:
        """group root -> mean position of its keys."""
        acc: dict = {}
        for k, p in self.xy.items():
            acc.setdefault(self.root[k], []).append(p)
        return {r: np.mean(ps, axis=0) for r, ps in acc.items()}


def _merge_pairs(lanelets) -> list[tuple]:
    """Point-key pairs that are one node: the right border of each lane with the left border
    of its same-direction neighbour when they run within :data:`MERGE_TOL` point by point."""
    groups: dict = {}
    for l in lanelets:
        if l.kind != 'connector':
            groups.setdefault((l.arm, l.kind), []).append(l)
    pairs = []
    for lanes in groups.values():
        for a in lanes:
            for b in lanes:
                A, B = np.asarray(a.right, float), np.asarray(b.left, float)
                if a is b or len(A) != len(B) or not len(A):
                    continue
                if float(np.max(np.hypot(*(A - B).T))) <= MERGE_TOL:
                    pairs += [(_key(p), _key(q)) for p, q in zip(A, B)]
    return pairs


def _line_attrs(users) -> dict:
    if any(u.kind == 'connector' for u in users):
        return {'type': 'virtual'}
    if len(users) > 1 and len({u.kind for u in users}) == 1:
        return {'type': 'line_thin', 'subtype': 'dashed'}
    return {'type': 'line_thin', 'subtype': 'solid'}


def _lanelet_map(lanelets):
    """The lanelet2 LaneletMap of ``lanelets`` (shared nodes and ways, see module docstring)."""
    from lanelet2.core import AttributeMap, LaneletMap, LineString3d, Point3d
    from lanelet2.core import Lanelet as LL

    ids = iter(range(1, 1 << 62))
    lanelets = [_aligned(l) for l in lanelets]
    nodes = _Nodes(lanelets, _merge_pairs(lanelets))
    pos = nodes.positions()
    points: dict = {}

    def seq_of(b):
        out = []
        for p in np.asarray(b, float).reshape(-1, 2):
            r = nodes.root[_key(p)]
            if not out or out[-1] != r:          # a merge never folds a border onto itself
                out.append(r)
        return tuple(out)

    def point(r):
        if r not in points:
            x, y = float(pos[r][0]), float(pos[r][1])
            points[r] = Point3d(next(ids), x, y, 0.0,
                                AttributeMap({'local_x': f'{x:.4f}', 'local_y': f'{y:.4f}'}))
        return points[r]

    users: dict = {}     # who uses which border (by node sequence): decides sharing and line type
    for l in lanelets:
        for b in (l.left, l.right):
            seq = seq_of(b)
            users.setdefault(min(seq, seq[::-1]), []).append(l)
    ways: dict = {}

    def way(b):
        seq = seq_of(b)
        canon = min(seq, seq[::-1])
        if canon not in ways:
            ways[canon] = LineString3d(next(ids), [point(r) for r in canon],
                                       AttributeMap(_line_attrs(users[canon])))
        return ways[canon] if seq == canon else ways[canon].invert()

    lmap = LaneletMap()
    for l in lanelets:
        attrs = {'type': 'lanelet', 'subtype': 'road', 'location': 'urban', 'one_way': 'yes',
                 'ie:id': str(l.id), 'ie:kind': l.kind}
        if l.kind == 'connector':
            attrs['turn_direction'] = turn_direction(l.center)
        lmap.add(LL(next(ids), way(l.left), way(l.right), AttributeMap(attrs)))
    return lmap


def write_osm(path, lanelets, origin_latlon=DEFAULT_ORIGIN):
    """Write ``lanelets`` (list of :class:`model.Lanelet`) as a Lanelet2 OSM map around the geo
    origin ``origin_latlon`` = (lat, lon) [deg], written into the file; returns ``path``."""
    import lanelet2
    lat, lon = check_origin(origin_latlon)
    lanelet2.io.write(str(path), _lanelet_map(lanelets), projector((lat, lon)))
    _write_geo_reference(Path(path), lat, lon)
    return path


def _write_geo_reference(path: Path, lat: float, lon: float) -> None:
    """Insert ``<geoReference .../>`` as the first child of ``<osm>`` (text edit: the rest of
    lanelet2's output stays byte for byte)."""
    text = path.read_text()
    m = re.search(r'<osm\b[^>]*>', text)
    if m is None:
        raise ValueError(f'{path}: lanelet2 wrote no <osm> element')
    ref = (f'\n  <geoReference lat="{lat!r}" lon="{lon!r}" alt="0.0" projector="LocalCartesian" '
           f'generator="intersection_estimator" />')
    head = m.group(0)
    if head.endswith('/>'):          # an empty map: lanelet2 writes <osm ... />
        head, ref = head[:-2].rstrip() + '>', ref + '\n</osm>'
    path.write_text(text[:m.start()] + head + ref + text[m.end():])


def read_origin(path):
    """(lat, lon) of the ``<geoReference>`` a map written by :func:`write_osm` carries, or
    None when the file has none (a map from elsewhere, or from before the origin was written)."""
    for _, el in ET.iterparse(str(path), events=('start',)):
        if el.tag == 'geoReference':
            return check_origin((el.get('lat'), el.get('lon')), f'{path}: geoReference')
        if el.tag in ('node', 'way', 'relation'):
            return None
    return None


def load_osm(path, origin_latlon=None):
    """Load a map written by :func:`write_osm` back into metric coordinates, around
    ``origin_latlon`` or else the origin written in the file (else :data:`DEFAULT_ORIGIN`)."""
    import lanelet2
    origin = origin_latlon if origin_latlon is not None else (read_origin(path) or DEFAULT_ORIGIN)
    return lanelet2.io.load(str(path), projector(origin))
