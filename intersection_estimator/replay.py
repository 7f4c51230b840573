"""``intersection-estimator replay`` and ``demo``: the node's pipeline over recorded bags.

Offline and deterministic by default: messages are fed in bag order through the same
:class:`~.ingest.Ingest` and :class:`~.pipeline.OnlineEstimator` as the node, ticks fall
at the node's period in *bag time*, and each tick spends a sample budget (so the result
does not depend on machine speed, and ``estimate.json`` is byte-identical for the same bag
and seed: its ``stats.elapsed_s`` is 0, the wall time is in the printed summary;
``--budget-mode wall`` spends the node's wall budget instead). Writes ``estimate.json``,
``lanelets.osm``, ``estimate.png`` and
``output.mcap`` (the node's ``~/topology``, ``~/lanelets``, ``~/markers``).
``--live`` instead publishes the bag over DDS at bag rate for a running node.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
import json
from pathlib import Path
import shutil
import sys
import time

from . import params as P
from .bagio import BagError, BagWriter, open_bags, typestore
from .ingest import ROLE_TYPES, Ingest, tick
from .pipeline import OnlineEstimator

__all__ = ['ReplaySummary', 'replay', 'register']

NODE = 'intersection_estimator'
OUTPUT_TOPICS = {'topology': ('/intersection_estimator/topology', 'intersection_estimator_msgs/msg/Topology'),
                 'lanelets': ('/intersection_estimator/lanelets', 'intersection_estimator_msgs/msg/LaneletArray'),
                 'markers': ('/intersection_estimator/markers', 'visualization_msgs/msg/MarkerArray')}


@dataclass
class ReplaySummary:
    """What a replay did (printed by the CLI, returned to callers and tests)."""

    messages: int
    ticks: int
    result: object
    files: dict
    dropped: dict
    wall_s: float
    truncated: str = ''

    def lines(self) -> list[str]:
        r = self.result
        out = [f'replayed {self.messages} messages, {self.ticks} ticks in {self.wall_s:.2f} s']
        if self.truncated:
            out.append(f'WARNING: bag truncated ({self.truncated}); estimate uses what could be read')
        if r is None or r.intersection is None:
            out.append('no intersection estimated (no usable observations)')
        else:
            I = r.intersection
            out.append(f'center ({I.center[0]:.2f}, {I.center[1]:.2f}) m, {len(I.arms)} arms, '
                       f'state {r.state}, {r.topology_samples} topology + {r.lane_samples} lane samples')
            for i, a in enumerate(I.arms):
                out.append(f'  arm {i}: {a.angle * 57.29577951308232:7.1f} deg, gap {a.gap:.1f} m, '
                           f'lanes in/out {a.lanes_in}/{a.lanes_out}, width {a.lane_width:.2f} m')
            kinds = {k: sum(1 for l in r.lanelets if l.kind == k) for k in ('entering', 'leaving', 'connector')}
            out.append('lanelets: ' + ', '.join(f'{v} {k}' for k, v in kinds.items()))
        if self.dropped:
            out.append('dropped: ' + ', '.join(f'{k} {v}' for k, v in sorted(self.dropped.items())))
        out += [f'wrote {p}' for p in self.files.values()]
        return out


def _values(params_file: str | None, seed: int | None, overrides: dict) -> dict:
    values = P.load_yaml(params_file) if params_file else P.defaults()
    if seed is not None:
        values['seed'] = seed
    values.update(overrides)
    errors = P.check_all(values)
    if errors:
        raise ValueError('; '.join(errors))
    return values


#: bagio's detected role -> the node's parameter (input role)
_BAG_ROLES = {'radar_clouds': 'radar_topics', 'radar_scans': 'radar_scan_topics',
              'pose_arrays': 'detection_topics', 'tracked_objects': 'object_topics',
              'detected_objects': 'object_topics',
              'odometry': 'odometry_topic'}


def _roles(reader, values: dict, configured: bool) -> dict[str, str]:
    """topic -> input role: the topics a params file names, else found by message type.

    Found by type, one tracked-objects topic is used (the same tracks published in two
    message families would count twice) and one odometry topic.
    """
    present = {t.topic for t in reader.topics}
    if configured:
        wanted = {t: role for role, ts in P.topics(values).items() for t in ts}
        if values['odometry_topic']:
            wanted[values['odometry_topic']] = 'odometry_topic'
        return {t: r for t, r in wanted.items() if t in present}
    found = reader.detect_topics()
    for single in ('tracked_objects', 'odometry'):
        if single in found:
            found[single] = found[single][:1]
    return {t: _BAG_ROLES[role] for role, topics in found.items() for t in topics}


def replay(bags: list[str], out: str | Path, *, params_file: str | None = None, seed: int | None = None,
           budget_mode: str = 'samples', progress: bool = True, write_outputs: bool = True) -> ReplaySummary:
    """Run the pipeline over ``bags``; raises :class:`BagError` with a one-line reason."""
    from msg_adapters.types import RosbagsTypes
    t_start = time.perf_counter()
    values = _values(params_file, seed, {})
    out = Path(out)
    writer = None
    n_msgs = n_ticks = 0
    with open_bags(bags) as reader:
        roles = _roles(reader, values, params_file is not None)
        if not roles or set(roles.values()) == {'odometry_topic'}:
            raise BagError('no_usable_topic', 'none of the configured input topics is in the bag')
        types = RosbagsTypes(typestore())
        ingest = Ingest(values, types)
        estimator = OnlineEstimator(P.pipeline_config(values), seed=values['seed'])
        if write_outputs:
            out.mkdir(parents=True, exist_ok=True)
            shutil.rmtree(out / '.output_bag', ignore_errors=True)
            writer = BagWriter(out / '.output_bag')
        period_ns = int(round(values['timer_period'] * 1e9))
        next_tick = None
        total = sum(t.count for t in reader.topics if t.topic in roles)
        for m in _progress(reader.messages(topics=sorted(roles)), progress, total):
            n_msgs += 1
            ingest.handle(roles[m.topic], m.msg, estimator)
            next_tick = m.t_ns + period_ns if next_tick is None else next_tick
            while m.t_ns >= next_tick:
                n_ticks += _tick(ingest, estimator, budget_mode, writer, values, next_tick)
                next_tick += period_ns
        if next_tick is not None:
            n_ticks += _tick(ingest, estimator, budget_mode, writer, values, next_tick)
        damage = [str(p) for p in reader.problems]
        if n_msgs < total:          # corrupt bytes inside a readable chunk: skipped, but not silently
            damage.append(f'{total - n_msgs} of {total} indexed messages could not be read')
        truncated = '; '.join(damage)
    if writer is not None:
        writer.close()
        _single_mcap(out / '.output_bag', out / 'output.mcap')
    result = estimator.result if n_ticks else None
    files = _write_files(out, result, estimator, values, budget_mode == 'samples') if write_outputs else {}
    if writer is not None:
        files['output'] = str(out / 'output.mcap')
    return ReplaySummary(n_msgs, n_ticks, result, files, dict(ingest.dropped),
                         time.perf_counter() - t_start, truncated or '')


def _tick(ingest, estimator, budget_mode, writer, values, t_ns) -> int:
    result = tick(ingest, estimator, wall_budget=budget_mode == 'wall')
    if result is None or writer is None:
        return int(result is not None)
    from msg_adapters.lanelets import lanelets_msg
    from msg_adapters.markers import markers_msg
    from msg_adapters.topology import topology_msg
    from msg_adapters.types import make_header
    types, t = writer.types, t_ns * 1e-9
    header = make_header(types, values['fixed_frame'], t)
    topo = topology_msg(types, header, result.intersection, result.topology_samples,
                        result.log_posterior, result.observations, result.state)
    writer.write(OUTPUT_TOPICS['topology'][0], topo, t)
    if result.intersection is not None and result.lanes_updated:
        writer.write(OUTPUT_TOPICS['lanelets'][0], lanelets_msg(types, header, result.lanelets,
                                                                result.lane_samples), t)
        markers, writer.marker_keys = markers_msg(types, header, result.intersection, result.lanelets,
                                                  getattr(writer, 'marker_keys', set()))
        writer.write(OUTPUT_TOPICS['markers'][0], markers, t)
    return 1


def _single_mcap(bag_dir: Path, target: Path) -> None:
    """Move the rosbag2 writer's one .mcap file to ``target`` (Foxglove, ros2 bag and rosbags
    all open a bare .mcap) and drop the bag directory."""
    target.unlink(missing_ok=True)
    (mcap,) = bag_dir.glob('*.mcap')
    mcap.rename(target)
    shutil.rmtree(bag_dir)


def _write_files(out: Path, result, estimator, values, deterministic: bool = True) -> dict:
    from .estimate_io import write_estimate
    files = {}
    I = None if result is None else result.intersection
    lanelets = [] if result is None else result.lanelets
    stats = {} if result is None else result.stats()
    if deterministic and stats:
        # same bag + seed -> byte-identical estimate.json: no wall time in it (the summary has it)
        stats['elapsed_s'] = 0.0
    files['estimate'] = str(write_estimate(out / 'estimate.json', I, lanelets, stats))
    if I is not None:
        from .export.osm import write_osm
        from .export.plot import plot_estimate
        files['osm'] = str(write_osm(out / 'lanelets.osm', lanelets))
        files['plot'] = str(plot_estimate(out / 'estimate.png', I, lanelets, dets=estimator.window()))
    return files


def _progress(it, enabled: bool, total: int):
    if not enabled:
        return it
    from tqdm import tqdm
    return tqdm(it, total=total, unit='msg', desc='replay', file=sys.stderr,
                mininterval=0.5, leave=False)


# -- command line -------------------------------------------------------------------------------
def register(sub) -> None:
    p = sub.add_parser('replay', help='run the estimator over rosbag2 bags (MCAP, sqlite3)',
                       description=__doc__)
    p.add_argument('bags', nargs='+', help='rosbag2 bag directories or .mcap / .db3 files')
    p.add_argument('--out', default='replay_out', help='output directory (default: replay_out)')
    p.add_argument('--params', help='parameter YAML (default: built-in defaults, topics found by type)')
    p.add_argument('--seed', type=int, help='seed (overrides the params file)')
    p.add_argument('--budget-mode', choices=('samples', 'wall'), default='samples',
                   help='samples: deterministic sample budget per tick (default); wall: the node\'s time budget')
    p.add_argument('--live', action='store_true', help='publish the bag over DDS at bag rate instead')
    p.add_argument('--rate', type=float, default=1.0, help='--live playback rate (default 1.0)')
    p.add_argument('--json', action='store_true', help='print the summary as JSON')
    p.add_argument('--quiet', action='store_true', help='no progress bar')
    p.set_defaults(func=_main)
    d = sub.add_parser('demo', help='replay the bundled sample bag into demo_out/ and summarise')
    d.add_argument('--out', default='demo_out')
    d.add_argument('--bag', default=None, help='bag to use (default: the bundled tracked-objects bag)')
    d.set_defaults(func=_demo)


def _main(args) -> int:
    try:
        if args.live:
            from .live import play
            return play(args.bags, rate=args.rate)
        summary = replay(args.bags, args.out, params_file=args.params, seed=args.seed,
                         budget_mode=args.budget_mode, progress=not args.quiet)
    except (BagError, ValueError, OSError) as exc:
        print(f'replay: {_one_line(exc)}', file=sys.stderr)
        return 1
    except Exception as exc:  # noqa: BLE001 - whatever a damaged bag provokes: one line, not a traceback
        print(f'replay: failed: {type(exc).__name__}: {_one_line(exc)}', file=sys.stderr)
        return 1
    if summary.truncated:
        print(f'replay: bag damaged ({_one_line(summary.truncated)}); wrote the estimate from the '
              f'{summary.messages} messages that could be read', file=sys.stderr)
    if args.json:
        print(json.dumps({'messages': summary.messages, 'ticks': summary.ticks, 'files': summary.files,
                          'dropped': summary.dropped, 'wall_s': summary.wall_s,
                          'truncated': summary.truncated}, indent=1))
    else:
        print('\n'.join(summary.lines()))
    return 2 if summary.truncated else 0


def _one_line(text) -> str:
    return ' '.join(str(text).split())


def bundled_bag(name: str = 'tracked') -> Path:
    """A sample bag shipped with the package (source tree or installed share/)."""
    here = Path(__file__).resolve().parents[1] / 'bags' / name
    if here.exists():
        return here
    return Path(sys.prefix) / 'share' / NODE / 'bags' / name


def _demo(args) -> int:
    bag = Path(args.bag) if args.bag else bundled_bag()
    print(f'demo: replaying {bag} (deterministic, sample budget per tick)')
    try:
        summary = replay([str(bag)], args.out, progress=True)
    except (BagError, ValueError, OSError) as exc:
        print(f'demo: {exc}', file=sys.stderr)
        return 1
    print('\n'.join(summary.lines()))
    gt = bag.parent / f'{bag.name}.gt.json'
    if gt.exists() and 'estimate' in summary.files:
        from .evaluate import evaluate_files
        m = evaluate_files(summary.files['estimate'], str(gt))
        keys = ('arm_correct', 'topology_correct', 'center_error_m', 'lane_error_cm', 'lane_recall',
                'connectivity_recall')
        fmt = (lambda v: f'{v:.3g}' if isinstance(v, float) else str(v))
        print('against ground truth: ' + ', '.join(f'{k} {fmt(m.get(k))}' for k in keys))
    return 2 if summary.truncated else 0
