"""``intersection-estimator fleet``: which intersections of a map changed, from many drives.

    intersection-estimator fleet BAG_OR_DIR... --map MAP.osm --out DIR
        [--engine local|ray] [--address ADDR] [--workers N]

Each bag is replayed (deterministic, seed from the bag's identity), its estimates matched
to the map's intersections and compared; the drives of one intersection are fused. Writes
``DIR/changes.json`` and ``DIR/changes_<id>.png`` per changed intersection, prints the
summary table. A bag that cannot be read is reported and the others go on. Exit status:
0, 2 when some bag failed or was damaged, 1 when nothing could run (bad map/option).
"""

from __future__ import annotations

import argparse
from pathlib import Path
import sys

__all__ = ['register', 'run_fleet']


def run_fleet(bags, map_path, out, *, engine='local', workers=1, address=None, params_file=None,
              origin=(49.0, 8.4), projector='local', cfg=None, progress=True) -> dict:
    """The whole job; returns the ``changes.json`` document (also written to ``out``)."""
    from .changes import ChangeConfig
    from .engine import expand_bags, run
    from .fuse import fuse
    from .prior_map import load_prior_map
    from .report import changes_doc, plot_changes, write_changes
    cfg = cfg or ChangeConfig()
    cfg.validate()
    mapped = load_prior_map(map_path, origin=origin, projector=projector)
    results = run(expand_bags(bags), mapped, engine=engine, workers=workers, address=address,
                  params_file=params_file, cfg=cfg, progress=progress)
    fused = fuse([(r.identity, v) for r in results for v in r.views], cfg)
    doc = changes_doc(fused, results, mapped, Path(map_path).name, cfg)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    write_changes(out / 'changes.json', doc)
    by_id = {m.id: m for m in mapped}
    for inter in doc['intersections']:
        if inter['changes']:
            ests = [e for r in results for e in r.estimates if e[0] == inter['id']]
            plot_changes(out / f"changes_{inter['id']}.png", by_id[inter['id']], inter, ests)
    return doc


def _cmd(args) -> int:
    from .changes import ChangeConfig
    from .prior_map import PriorMapError
    from .report import summary_lines
    try:
        cfg = ChangeConfig(moved_m=args.moved_m, min_confidence=args.min_confidence,
                           corroborate=int(not args.no_corroborate), turn_absence=int(not args.any_lane_absence),
                           share_from_traffic=int(not args.even_lane_choice),
                           empty_calibration=int(not args.no_empty_calibration))
        doc = run_fleet(args.bags, args.map, args.out, engine=args.engine, workers=args.workers,
                        address=args.address, params_file=args.params, origin=tuple(args.origin),
                        projector=args.projector, cfg=cfg, progress=not args.quiet)
    except (PriorMapError, ValueError, OSError, ImportError) as exc:
        print(f"fleet: {' '.join(str(exc).split())}", file=sys.stderr)
        return 1
    print('\n'.join(summary_lines(doc)))
    print(f"wrote {Path(args.out) / 'changes.json'}")
    return 2 if any(b['status'] != 'ok' for b in doc['bags']) else 0


def register(subparsers) -> argparse.ArgumentParser:
    """Add the ``fleet`` subcommand."""
    p = subparsers.add_parser('fleet', help='map-change detection over many bags (local or Ray)',
                              description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('bags', nargs='+', metavar='BAG_OR_DIR', help='bags, or directories of bags')
    p.add_argument('--map', required=True, help='prior Lanelet2 OSM map')
    p.add_argument('--out', required=True, help='output directory (changes.json, PNGs)')
    p.add_argument('--engine', choices=('local', 'ray'), default='local')
    p.add_argument('--address', default=None, help='Ray cluster address (default: start Ray locally)')
    p.add_argument('--workers', type=int, default=1, help='parallel bags (local processes / Ray CPUs)')
    p.add_argument('--params', default=None, help='parameter YAML for the replay (seed: from each bag)')
    p.add_argument('--origin', type=float, nargs=2, default=(49.0, 8.4), metavar=('LAT', 'LON'),
                   help="the map projector's origin (default: the export's 49.0 8.4)")
    p.add_argument('--projector', choices=('local', 'utm'), default='local')
    p.add_argument('--moved-m', type=float, default=0.75, help='lane moved beyond this offset [m]')
    p.add_argument('--min-confidence', type=float, default=0.5, help='fused confidence to report')
    p.add_argument('--no-corroborate', action='store_true',
                   help="keep claims the drive's map-matched vehicles contradict (the estimate alone)")
    p.add_argument('--any-lane-absence', action='store_true',
                   help='a missing lane: every vehicle of its direction counts, not only those of its turns')
    p.add_argument('--even-lane-choice', action='store_true',
                   help="a missing lane: the lanes of a turn carry exactly equal shares of it (not read from "
                        "the drive's lane choices on the other arms)")
    p.add_argument('--no-empty-calibration', action='store_true',
                   help="a missing lane: its evidence is not weighed by how often the drive's other mapped "
                        'lanes stood empty against the lane-choice model')
    p.add_argument('--quiet', action='store_true', help='no progress bar')
    p.set_defaults(func=_cmd)
    return p
