"""Run SUMO on a case and read its floating-car data (issue 15.1).

``sumo -n NET -r ROUTES --fcd-output fcd.xml`` at ``step_s`` with the case's seed
(deterministic: same seed and inputs -> byte-identical fcd), then
:func:`read_fcd` keeps the recorded window ``[warmup, warmup + duration]`` and returns
one :class:`FcdTrack` per vehicle / person: times rebased to the window, position,
yaw (SUMO's angle is clockwise from north, degrees), speed, the lane (vehicles) per
sample, the vehicle type.

SUMO's position of a vehicle is the middle of its *front bumper*; a perception stack
reports an object's box center. So each vehicle's position is taken half its type's
length (``sumo_demand.VTYPE_LENGTH``) back along the path its front bumper drove
(:func:`box_center`): a driver keeps the car's body, not its bumper, on the lane, so the
center follows the lane shape as SUMO's point vehicle does, half a car length behind the
front; its lane is the one the front was on there (SUMO's angle, the direction from back to
front bumper, is already the heading at the center). Without it every position was 2.5 m (a
truck 5 m) ahead of the vehicle's center and every queue's first vehicle stood exactly on
the stop line. Persons keep their position.
"""

from __future__ import annotations

from dataclasses import dataclass
import math
from pathlib import Path
import re

import numpy as np

from .sumo_demand import VTYPE_LENGTH
from .sumo_net import run_tool, sumo_binary

__all__ = ['FcdTrack', 'run_sumo', 'read_fcd', 'box_center', 'CENTER_BACK']

#: Metres behind the front bumper where each vehicle type's box center is (half its length).
CENTER_BACK = {kind: 0.5 * length for kind, length in VTYPE_LENGTH.items()}


@dataclass
class FcdTrack:
    id: str
    kind: str                 # vehicle type id ('car', 'truck', 'bike', 'egotype') or 'person'
    cycle: np.ndarray         # (M,) int, window start = 0
    xy: np.ndarray
    yaw: np.ndarray
    speed: np.ndarray
    lane: np.ndarray          # (M,) str, '' for persons


def run_sumo(net, routes, folder, *, seed: int, end: float, step: float, record_from: float = 0.0
             ) -> Path:
    """Run SUMO to ``end`` s; floating-car data from ``record_from`` s on."""
    fcd = Path(folder) / 'fcd.xml'
    run_tool([sumo_binary('sumo'), '-n', str(net), '-r', str(routes), '--begin', '0',
              '--end', f'{end:.1f}', '--step-length', f'{step}', '--seed', str(int(seed)),
              '--fcd-output', str(fcd), '--device.fcd.begin', f'{record_from:.1f}',
              '--fcd-output.attributes', 'x,y,angle,speed,lane,type',
              '--pedestrian.model', 'nonInteracting',
              '--no-step-log', 'true', '--no-warnings', 'true',
              '--ignore-route-errors', 'true', '--time-to-teleport', '-1',
              '--collision.action', 'none', '--duration-log.disable', 'true'], 'sumo')
    return fcd


_STEP = re.compile(rb'<timestep time="([^"]+)"')
_OBJ = re.compile(rb'<(vehicle|person) ([^>]*?)/?>')
_ATTR = re.compile(rb'(\w+)="([^"]*)"')


def read_fcd(path, warmup: float, duration: float, step: float,
             back: dict | None = None) -> list[FcdTrack]:
    """Tracks in the window (module doc), sorted by id. A line scanner over SUMO's
    one-element-per-line fcd file (several times faster than an XML tree walk).
    ``back``: metres behind the front bumper a type's position is taken (default: half
    its length, the box center; the ego's origin is its rear axle instead)."""
    back = CENTER_BACK if back is None else back
    rows: dict = {}
    cyc, inside = 0, False
    with open(path, 'rb') as fh:
        for line in fh:
            m = _STEP.search(line)
            if m:
                t = float(m.group(1))
                inside = warmup - 1e-6 <= t <= warmup + duration + 1e-6
                cyc = int(round((t - warmup) / step))
                continue
            m = _OBJ.search(line) if inside else None
            if m is None:
                continue
            a = dict(_ATTR.findall(m.group(2)))
            kind = a.get(b'type', b'person').decode() if m.group(1) == b'vehicle' else 'person'
            rows.setdefault(a[b'id'].decode(), (kind, []))[1].append(
                (cyc, float(a[b'x']), float(a[b'y']), float(a[b'angle']), float(a[b'speed']),
                 a.get(b'lane', b'').decode()))
    out = []
    for vid in sorted(rows):
        kind, r = rows[vid]
        yaw = np.radians(90.0 - np.array([x[3] for x in r]))
        xy = np.array([[x[1], x[2]] for x in r]).reshape(-1, 2)
        xy, at = box_center(xy, yaw, back.get(kind, 0.0))
        out.append(FcdTrack(id=vid, kind=kind, cycle=np.array([x[0] for x in r], int),
                            xy=xy, yaw=yaw, speed=np.array([x[4] for x in r]),
                            lane=np.array([x[5] for x in r], dtype=object).astype(str)[at]))
    return out


def box_center(front: np.ndarray, yaw: np.ndarray, back: float) -> tuple[np.ndarray, np.ndarray]:
    """((M, 2) positions, (M,) rows): the positions ``back`` metres behind the front
    bumper's positions ``front`` along the path it drove (before the first row: straight
    back along the first heading), and per row the row whose front position the center is
    passing -- its SUMO lane is the center's lane (0 before the first)."""
    rows = np.arange(len(front))
    if back <= 0.0 or len(front) == 0:
        return front, rows
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(front, axis=0), axis=1))])
    at = s - back
    out = np.empty_like(front)
    on = at >= 0.0
    for k in range(2):
        out[on, k] = np.interp(at[on], s, front[:, k])
    heading = np.array([math.cos(yaw[0]), math.sin(yaw[0])])
    out[~on] = front[0] + at[~on, None] * heading
    return out, np.clip(np.searchsorted(s, at, side='right') - 1, 0, len(front) - 1)


def yaw_wrap(a):
    return (np.asarray(a) + math.pi) % (2 * math.pi) - math.pi
