"""Run SUMO on a case and read its floating-car data (issue 15.1).

``sumo -n NET -r ROUTES --fcd-output fcd.xml`` at ``step_s`` with the case's seed
(deterministic: same seed and inputs -> byte-identical fcd), then
:func:`read_fcd` keeps the recorded window ``[warmup, warmup + duration]`` and returns
one :class:`FcdTrack` per vehicle / person: times rebased to the window, position,
yaw (SUMO's angle is clockwise from north, degrees), speed, the lane (vehicles) per
sample, the vehicle type.
"""

from __future__ import annotations

from dataclasses import dataclass
import math
from pathlib import Path
import xml.etree.ElementTree as ET

import numpy as np

from .sumo_net import run_tool, sumo_binary

__all__ = ['FcdTrack', 'run_sumo', 'read_fcd']


@dataclass
class FcdTrack:
    id: str
    kind: str                 # vehicle type id ('car', 'truck', 'bike', 'egotype') or 'person'
    cycle: np.ndarray         # (M,) int, window start = 0
    xy: np.ndarray
    yaw: np.ndarray
    speed: np.ndarray
    lane: np.ndarray          # (M,) str, '' for persons


def run_sumo(net, routes, folder, *, seed: int, end: float, step: float) -> Path:
    fcd = Path(folder) / 'fcd.xml'
    run_tool([sumo_binary('sumo'), '-n', str(net), '-r', str(routes), '--begin', '0',
              '--end', f'{end:.1f}', '--step-length', f'{step}', '--seed', str(int(seed)),
              '--fcd-output', str(fcd), '--no-step-log', 'true', '--no-warnings', 'true',
              '--ignore-route-errors', 'true', '--time-to-teleport', '-1',
              '--collision.action', 'none', '--duration-log.disable', 'true'], 'sumo')
    return fcd


def read_fcd(path, warmup: float, duration: float, step: float) -> list[FcdTrack]:
    """Tracks in the window (module doc), sorted by id."""
    rows: dict = {}
    for _, el in ET.iterparse(str(path), events=('end',)):
        if el.tag != 'timestep':
            continue
        t = float(el.get('time'))
        if warmup - 1e-6 <= t <= warmup + duration + 1e-6:
            cyc = int(round((t - warmup) / step))
            for obj in el:
                kind = obj.get('type', 'person') if obj.tag == 'vehicle' else 'person'
                rows.setdefault(obj.get('id'), (kind, []))[1].append(
                    (cyc, float(obj.get('x')), float(obj.get('y')), float(obj.get('angle')),
                     float(obj.get('speed')), obj.get('lane', '')))
        el.clear()
    out = []
    for vid in sorted(rows):
        kind, r = rows[vid]
        ang = np.array([x[3] for x in r])
        out.append(FcdTrack(id=vid, kind=kind, cycle=np.array([x[0] for x in r], int),
                            xy=np.array([[x[1], x[2]] for x in r]),
                            yaw=np.radians(90.0 - ang), speed=np.array([x[4] for x in r]),
                            lane=np.array([x[5] for x in r], dtype=object).astype(str)))
    return out


def yaw_wrap(a):
    return (np.asarray(a) + math.pi) % (2 * math.pi) - math.pi
