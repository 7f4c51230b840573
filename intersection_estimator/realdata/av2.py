"""Argoverse 2 motion-forecasting scenarios -> detections, bag and ground truth (issue 15.2).

One AV2 scenario folder holds ``scenario_<id>.parquet`` (tracks at 10 Hz in the city
frame: ``track_id, object_type, timestep, position_x/y, heading, velocity_x/y``) and
``log_map_archive_<id>.json`` (the local lane graph). :func:`load_av2` turns it into a
:class:`~intersection_estimator.sim.Scenario` (so the bag writer, ``evaluate`` and
``bench`` take it as they take a simulated one):

* ground truth: lane segments (``VEHICLE`` / ``BUS`` lanes) become
  :class:`~intersection_estimator.scenarios.lanegraph.Segment` (``is_intersection`` =
  connector); the intersection segments are grouped into junctions (linked or within
  ``JOIN_M`` of each other) and the junction the traffic uses most becomes the case's
  intersection (:func:`~intersection_estimator.scenarios.lanegraph.gt_from_lane_graph`);
* traffic per lane and the traffic-following line (:mod:`~intersection_estimator.scenarios.floor`)
  from the tracks map-matched to the segments;
* ``'tracked'``: the AV2 tracks themselves (real positions, headings, speeds; no noise
  added), seen from the AV (ego = track ``AV``, not itself a detection); object types
  map to Autoware labels (:data:`LABELS`), static objects (parked cars) stay in.
  ``'raw'`` / ``'heading'`` are *synthetic*: the project's sensor models
  (:mod:`intersection_estimator.sim.sensors`) driven by the real moving road users.

Licence: Argoverse 2 is CC BY-NC-SA 4.0 (non-commercial); the data are read from
outside the repository and never copied into it.
"""

from __future__ import annotations

import json
from pathlib import Path
import zlib

import numpy as np

from ..components import components
from ..observations import Detections
from ..scenarios.floor import drove, label_points, match_segments, traffic_counts, traffic_lines
from ..scenarios.lanegraph import Segment, gt_from_lane_graph
from ..scenarios.base import FamilyScenario
from ..sim import SimConfig
from ..sim.traffic import EgoTrajectory, Track

__all__ = ['Av2Error', 'load_av2', 'av2_segments', 'find_scenarios', 'LABELS',
           'register', 'convert']

#: AV2 object_type -> Autoware ObjectClassification label
LABELS = {'vehicle': 1, 'bus': 3, 'motorcyclist': 5, 'cyclist': 6, 'riderless_bicycle': 6,
          'pedestrian': 7}
MOVING = ('vehicle', 'bus', 'motorcyclist', 'cyclist')
LANE_USERS = ('vehicle', 'bus', 'motorcyclist')   # traffic + floor: who drives a lane's centre
JOIN_M = 3.0            # intersection segments this close belong to one junction
RATE_HZ = 10.0


class Av2Error(ValueError):
    """The folder is not a readable AV2 scenario (one-line message)."""


def _files(folder: Path):
    folder = Path(folder)
    if not folder.is_dir():
        raise Av2Error(f'av2: {folder} is not a folder')
    pq = sorted(folder.glob('scenario_*.parquet'))
    mp = sorted(folder.glob('log_map_archive_*.json'))
    if not pq or not mp:
        raise Av2Error(f'av2: {folder} has no scenario_*.parquet + log_map_archive_*.json')
    return pq[0], mp[0]


def _xy(pts) -> np.ndarray:
    return np.array([[p['x'], p['y']] for p in pts], float)


def _width(seg: dict) -> float:
    left, right = _xy(seg['left_lane_boundary']), _xy(seg['right_lane_boundary'])
    d = np.linalg.norm(left[:, None] - right[None], axis=2).min(1)
    return float(np.clip(np.median(d), 2.0, 6.0))


def av2_segments(log_map: dict) -> dict:
    """Vehicle / bus lane segments of an AV2 map as lane-graph segments."""
    out = {}
    for s in log_map['lane_segments'].values():
        if s.get('lane_type', 'VEHICLE') not in ('VEHICLE', 'BUS'):
            continue
        out[str(s['id'])] = Segment(id=str(s['id']), center=_xy(s['centerline']),
                                    width=_width(s),
                                    preds=[str(x) for x in s.get('predecessors', [])],
                                    succs=[str(x) for x in s.get('successors', [])],
                                    connector=bool(s['is_intersection']))
    for s in out.values():   # keep only links to segments we kept
        s.preds = [x for x in s.preds if x in out]
        s.succs = [x for x in s.succs if x in out]
    return out


def _junctions(segs: dict) -> list[set]:
    """Connector segments grouped: linked to each other or within JOIN_M."""
    ids = sorted(k for k, s in segs.items() if s.connector)
    pairs = []
    for a_i, a in enumerate(ids):
        for b in ids[a_i + 1:]:
            linked = b in segs[a].succs or b in segs[a].preds
            d = np.linalg.norm(segs[a].center[:, None] - segs[b].center[None], axis=2).min()
            if linked or d <= JOIN_M:
                pairs.append((a, b))
    return [set(g) for g in components(ids, pairs)]


def _read(folder):
    import pandas as pd
    pq, mp = _files(folder)
    try:
        df = pd.read_parquet(pq)
        log_map = json.loads(mp.read_text())
    except (OSError, ValueError) as e:
        raise Av2Error(f'av2: cannot read {folder}: {e}') from None
    need = {'track_id', 'object_type', 'timestep', 'position_x', 'position_y', 'heading',
            'velocity_x', 'velocity_y'}
    if not need <= set(df.columns):
        raise Av2Error(f'av2: {pq.name} lacks columns {sorted(need - set(df.columns))}')
    if 'lane_segments' not in log_map:
        raise Av2Error(f'av2: {mp.name} has no lane_segments')
    return df.sort_values(['track_id', 'timestep'], kind='stable'), log_map


def _tracks(df):
    """-> ego EgoTrajectory, per-row arrays of the other road users, vehicle Tracks."""
    t = df['timestep'].to_numpy(int)
    tid = df['track_id'].astype(str).to_numpy()
    ego_rows = tid == 'AV'
    if not ego_rows.any():
        raise Av2Error('av2: no AV track (the ego vehicle)')
    n_cyc = int(t.max()) + 1
    xy = df[['position_x', 'position_y']].to_numpy(float)
    vel = df[['velocity_x', 'velocity_y']].to_numpy(float)
    hd = df['heading'].to_numpy(float)
    e = np.flatnonzero(ego_rows)
    grid = np.arange(n_cyc)
    ego_xy = np.stack([np.interp(grid, t[e], xy[e, 0]), np.interp(grid, t[e], xy[e, 1])], 1)
    ego = EgoTrajectory(t=grid / RATE_HZ, xy=ego_xy,
                        yaw=np.interp(grid, t[e], np.unwrap(hd[e])),
                        speed=np.interp(grid, t[e], np.linalg.norm(vel[e], axis=1)),
                        arm=-1, lane_index=-1)
    rows = dict(t=t[~ego_rows], tid=tid[~ego_rows], xy=xy[~ego_rows], heading=hd[~ego_rows],
                speed=np.linalg.norm(vel[~ego_rows], axis=1),
                type=df['object_type'].astype(str).to_numpy()[~ego_rows])
    tracks = []
    for i, k in enumerate(sorted(set(rows['tid']))):
        sel = np.flatnonzero(rows['tid'] == k)
        if rows['type'][sel[0]] in MOVING and len(sel) >= 2:
            tracks.append(Track(id=i, t=rows['t'][sel] / RATE_HZ, xy=rows['xy'][sel],
                                yaw=rows['heading'][sel], speed=rows['speed'][sel], route=()))
    return ego, rows, tracks, n_cyc


def _tracked_stream(rows, ego, n_cyc):
    ids = {k: i for i, k in enumerate(sorted(set(rows['tid'])))}
    cyc = rows['t']
    order = np.argsort(cyc, kind='stable')
    dets = Detections.make(rows['xy'], cyc / RATE_HZ, heading=rows['heading'],
                           speed=rows['speed'], sensor_xy=ego.xy[cyc],
                           track_id=np.array([ids[k] for k in rows['tid']]),
                           label=np.array([LABELS.get(x, 0) for x in rows['type']]))
    return dets.subset(order), cyc[order]


def _pick(segs, groups, xy, heading):
    """The junction whose connectors the traffic's points map-match to most."""
    conn = {k: s for k, s in segs.items() if s.connector}
    m = match_segments(xy, heading, conn)
    score = [sum(int((m == s).sum()) for s in g) for g in groups]
    return groups[int(np.argmax([(sc, len(g)) for sc, g in zip(score, groups)], axis=0)[0])]


def load_av2(folder, *, arm_length: float = 60.0) -> FamilyScenario:
    """One AV2 scenario folder -> :class:`FamilyScenario` (module doc)."""
    df, log_map = _read(folder)
    segs = av2_segments(log_map)
    groups = _junctions(segs)
    if not groups:
        raise Av2Error(f'av2: {folder}: the map has no intersection lane segment')
    ego, rows, tracks, n_cyc = _tracks(df)
    moving = np.isin(rows['type'], MOVING)
    box = _pick(segs, groups, rows['xy'][moving], rows['heading'][moving])
    try:
        gt = gt_from_lane_graph(segs, box, arm_length=arm_length)
    except ValueError as e:
        raise Av2Error(f'av2: {folder}: {e}') from None
    seg_of = match_segments(rows['xy'], rows['heading'], segs)
    users = np.isin(rows['type'], LANE_USERS)
    labels = drove(np.where(users, label_points(seg_of, rows['tid'], gt), ''), rows['tid'],
                   rows['xy'], rows['t'])
    counts = traffic_counts(gt.lanelets, labels, rows['tid'])
    lines = traffic_lines(gt.lanelets, rows['xy'], labels)
    sid = Path(folder).name
    cfg = SimConfig(sensor_mount=0.0)
    sc = FamilyScenario(seed=zlib.crc32(sid.encode()) & 0x7FFFFFFF, config=cfg,
                      gt=gt.intersection, gt_lanelets=gt.lanelets, traffic=counts,
                      tracks=tracks, ego=ego, duration=float(ego.t[-1]), stop=gt.stop,
                      sensor_range=cfg.sensor_range)
    sc.real['tracked'] = _tracked_stream(rows, ego, n_cyc)
    sc.extra_gt = {lid: {'traffic_line': line} for lid, line in lines.items()}
    sc.info = {'source': 'argoverse2', 'scenario_id': sid,
               'city': str(df['city'].iloc[0]) if 'city' in df else None,
               'licence': 'Argoverse 2, CC BY-NC-SA 4.0 (non-commercial)',
               'tracked': 'real AV2 tracks', 'raw_heading': 'synthetic sensor models on the '
               'real road users', 'junction_segments': sorted(box)}
    return sc


def find_scenarios(root) -> list[Path]:
    """AV2 scenario folders under ``root`` (sorted)."""
    return sorted(p.parent for p in Path(root).rglob('scenario_*.parquet'))


def convert(folder, out, sensors=('tracked',)) -> dict:
    """Write ``out/gt.json`` and ``out/bag`` (the node's input topics) of one scenario."""
    from .. import bagio
    from ..estimate_io import dumps
    from ..scenarios import gt_doc
    sc = load_av2(folder)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    (out / 'gt.json').write_text(dumps(gt_doc(sc)))
    import shutil
    shutil.rmtree(out / 'bag', ignore_errors=True)
    info = bagio.write_scenario_bag(sc, out / 'bag', sensors=tuple(sensors))
    return {'gt': out / 'gt.json', 'bag': out / 'bag', 'counts': info.counts, 'scenario': sc}


def _cmd(args) -> int:
    import sys
    folders = find_scenarios(args.scenario) if args.all else [Path(args.scenario)]
    if not folders:
        print(f'av2: no scenario_*.parquet under {args.scenario}', file=sys.stderr)
        return 1
    for f in folders:
        out = Path(args.out) / f.name if args.all else Path(args.out)
        try:
            res = convert(f, out, args.mode)
        except Av2Error as e:
            print(str(e), file=sys.stderr)
            return 1
        sc = res['scenario']
        print(f"{f.name}: {len(sc.gt.arms)} arms, {len(sc.gt_lanelets)} lanes "
              f"({sum(v > 0 for v in sc.traffic.values())} with traffic) -> {res['gt']}, {res['bag']}")
    return 0


def register(subparsers):
    """Add the ``av2`` subcommand."""
    p = subparsers.add_parser('av2', help='convert an Argoverse 2 scenario to a bag + gt.json',
                              description=__doc__.split('\n\n')[0])
    p.add_argument('scenario', help='AV2 scenario folder (scenario_*.parquet + log_map_archive_*.json)'
                   ' or, with --all, a folder holding several')
    p.add_argument('--out', required=True, help='output folder (gt.json, bag/)')
    p.add_argument('--all', action='store_true', help='convert every scenario under SCENARIO '
                   'into OUT/<scenario id>/')
    p.add_argument('--mode', nargs='+', choices=('tracked', 'raw', 'heading'), default=['tracked'],
                   help="streams to record ('tracked' = the real tracks; raw / heading: "
                   'synthetic sensor models on them)')
    p.set_defaults(func=_cmd)
    return p
