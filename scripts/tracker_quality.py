#!/usr/bin/env python3
"""The radar tracker's own quality against the simulators' truth (docs/real_junctions.md,
"Radar through a tracker"; not the estimate scored with its tracks).

    .venv/bin/python scripts/tracker_quality.py --family sumo --n 20 [--set gate_across_m=2.0]

Per case the raw radar rows go through the batch tracker (``pipeline.radar_tracked``, the
clutter filter included) and every reported track row is compared with the true vehicle
positions at its stamp (the simulators give both at the same stamps):

* ``coverage``: share of the rows of moving true vehicles (1 m/s or faster) that the radar
  saw (a radar row within 3 m at that stamp) with a track row within 3 m;
* ``tracks/vehicle``: distinct tracks with at least ``PAIR_ROWS`` rows nearest to one
  vehicle, per such vehicle (a vehicle's track broken into pieces);
* ``vehicles/track``: distinct vehicles a track has ``PAIR_ROWS`` rows nearest to, per such
  track (a track that followed two vehicles: swapped, or took a neighbour's rows);
* ``off 1.5 m``: share of track rows farther than 1.5 m from every true vehicle -- a track
  that took the rows of two vehicles side by side sits between them (lanes 3-3.5 m apart);
* ``error``: median distance of a track row to its nearest true vehicle.

Sums over the cases, printed once; ``--set`` takes ``TrackerConfig`` fields.
"""

from __future__ import annotations

import argparse
from collections import Counter
from dataclasses import fields
from pathlib import Path
import sys

import numpy as np
from scipy.spatial import cKDTree

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from intersection_estimator.bench import BenchOptions, make_case  # noqa: E402
from intersection_estimator.pipeline import in_mode, radar_tracked  # noqa: E402
from intersection_estimator.topology import TopologyConfig  # noqa: E402
from intersection_estimator.tracking import TrackerConfig, is_radar_track, radar_rows_of  # noqa: E402

COVER_M = 3.0
OFF_M = 1.5
MOVING = 1.0
PAIR_ROWS = 10


def truth_rows(sc):
    """(stamps rounded to ms, xy, vehicle index, moving) of every true vehicle row."""
    t, xy, veh, mov = [], [], [], []
    for k, tr in enumerate(sc.tracks):
        t.append(np.round(np.asarray(tr.t, float) * 1000).astype(np.int64))
        xy.append(np.asarray(tr.xy, float))
        veh.append(np.full(len(tr.t), k))
        mov.append(np.asarray(tr.speed, float) >= MOVING)
    return np.concatenate(t), np.concatenate(xy), np.concatenate(veh), np.concatenate(mov)


def _seen(raw, tt, txy) -> np.ndarray:
    """Mask of true rows with a radar row within ``COVER_M`` at their stamp."""
    radar = raw.subset(radar_rows_of(raw))
    rt = np.round(radar.t * 1000).astype(np.int64)
    seen = np.zeros(len(tt), bool)
    for stamp in np.intersect1d(np.unique(tt), np.unique(rt)):
        ti = np.flatnonzero(tt == stamp)
        seen[ti] = cKDTree(radar.xy[rt == stamp]).query(txy[ti])[0] <= COVER_M
    return seen


def case_quality(sc, cfg: TrackerConfig) -> dict:
    """Counts of one case (module docstring)."""
    raw = in_mode(sc.detections('raw'), 'raw')
    dets, _ = radar_tracked(raw, 'raw', cfg, TopologyConfig())
    d = dets.subset(is_radar_track(dets.track_id))
    tt, txy, tveh, tmov = truth_rows(sc)
    tmov &= _seen(raw, tt, txy)
    dt = np.round(d.t * 1000).astype(np.int64)
    out = {'truth_moving': int(tmov.sum()), 'covered': 0, 'rows': len(d), 'off': 0, 'err': []}
    pairs = Counter()
    for stamp in np.unique(np.concatenate([dt, tt[tmov]])):
        ti, di = np.flatnonzero(tt == stamp), np.flatnonzero(dt == stamp)
        if not len(ti):
            out['off'] += len(di)
            continue
        if len(di):
            dist, j = cKDTree(txy[ti]).query(d.xy[di])
            out['off'] += int((dist > OFF_M).sum())
            out['err'] += dist.tolist()
            pairs.update(zip(tveh[ti][j].tolist(), d.track_id[di].tolist()))
            near = cKDTree(d.xy[di]).query(txy[ti])[0] <= COVER_M
        else:
            near = np.zeros(len(ti), bool)
        out['covered'] += int((near & tmov[ti]).sum())
    kept = [p for p, n in pairs.items() if n >= PAIR_ROWS]
    out['vehicles'] = len({v for v, _ in kept})
    out['tracks'] = len({t for _, t in kept})
    out['pairs'] = len(kept)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--family', choices=('sumo', 'table1'), default='sumo')
    ap.add_argument('--n', type=int, default=20)
    ap.add_argument('--seed', type=int, default=0)
    ap.add_argument('--set', action='append', default=[], metavar='FIELD=VALUE')
    args = ap.parse_args(argv)
    kinds = {f.name: f.type for f in fields(TrackerConfig)}
    kw = {}
    for item in args.set:
        key, _, v = item.partition('=')
        if key not in kinds:
            raise SystemExit(f'tracker_quality: unknown TrackerConfig field {key!r}')
        kw[key] = v.lower() in ('1', 'true') if kinds[key] in (bool, 'bool') else float(v)
    cfg = TrackerConfig(**kw).validate()
    opts = BenchOptions(family=args.family, n=args.n, seed=args.seed, mode='raw', lane_samples=0)
    tot = {'truth_moving': 0, 'covered': 0, 'rows': 0, 'off': 0, 'vehicles': 0, 'tracks': 0, 'pairs': 0, 'err': []}
    for i in range(args.n):
        q = case_quality(make_case(opts, i)[0], cfg)
        for k in tot:
            tot[k] += q[k]
    print(f"{args.family} seeds {args.seed}..{args.seed + args.n - 1} {kw or 'defaults'}: "
          f"coverage {tot['covered'] / max(tot['truth_moving'], 1):.3f}  "
          f"tracks/vehicle {tot['pairs'] / max(tot['vehicles'], 1):.2f}  "
          f"vehicles/track {tot['pairs'] / max(tot['tracks'], 1):.2f}  "
          f"off {OFF_M} m {tot['off'] / max(tot['rows'], 1):.3f}  "
          f"error median {np.median(tot['err']) if tot['err'] else float('nan'):.2f} m  "
          f"track rows {tot['rows']}")
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
