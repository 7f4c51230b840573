"""``intersection-estimator replay`` and ``demo``: the node's pipeline over recorded bags.

Offline and deterministic by default: messages are fed in bag order through the same
:class:`~.ingest.Ingest` and :class:`~.pipeline.OnlineEstimator` as the node, ticks fall
at the node's period in *bag time*, and each tick spends a sample budget (so the result
does not depend on machine speed, and ``estimate.json`` is byte-identical for the same bag
and seed: its ``stats.elapsed_s`` is 0, the wall time is in the printed summary;
``--budget-mode wall`` spends the node's wall budget instead). A converged estimate with no
new data does not sample (a gap in bag time costs nothing): such idle ticks in a row are
written to ``output.mcap`` once.

Outputs, in ``--out`` (written to a temporary folder beside it and moved into place at the
end, so a failed run leaves the previous results as they were):

* ``estimate.json``, ``lanelets.osm``, ``estimate.png``: the *last* intersection estimated;
  without any, ``estimate.json`` of state NO_DATA (``center`` null, no arms) whose
  ``stats`` hold the input counts (``received``, ``dropped`` per reason) and ``why``;
* ``intersections/NN/`` (00, 01, ...): the same three files for every intersection of the
  drive, in order (the pipeline starts on the next one when the ego has passed one, or when
  the time base jumps, e.g. two recordings in one replay);
* ``output.mcap``: the node's ``~/topology``, ``~/lanelets``, ``~/markers``.

Exit codes: 0 an intersection was estimated; 1 unusable input or bad arguments (one line on
stderr, nothing written); 2 a bag was damaged, the estimate uses what could be read; 3 no
intersection could be estimated (NO_DATA estimate written, the reason printed).
``--live`` instead publishes the bag over DDS at bag rate (and ``/clock``) for a running node.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import json
from pathlib import Path
import shutil
import sys
import tempfile
import time

from . import params as P
from .bagio import BagError, BagWriter, open_bags, typestore
from .ingest import TF_TOPICS, TF_TYPE, Ingest, tick
from .pipeline import OnlineEstimator
from .replay_report import (EXIT_DAMAGED, EXIT_NO_INTERSECTION, EXIT_OK, EXIT_UNUSABLE, Intersection,
                            ReplaySummary, WarningLog, why_no_intersection)
from .roles import ODOMETRY, TRACK_TYPES

__all__ = ['ReplaySummary', 'replay', 'register', 'EXIT_OK', 'EXIT_UNUSABLE', 'EXIT_DAMAGED',
           'EXIT_NO_INTERSECTION']

NODE = 'intersection_estimator'
OUTPUT_TOPICS = {'topology': ('/intersection_estimator/topology', 'intersection_estimator_msgs/msg/Topology'),
                 'lanelets': ('/intersection_estimator/lanelets', 'intersection_estimator_msgs/msg/LaneletArray'),
                 'markers': ('/intersection_estimator/markers', 'visualization_msgs/msg/MarkerArray')}
#: What a replay writes into ``--out`` (and replaces there, nothing else).
OUTPUT_NAMES = ('estimate.json', 'lanelets.osm', 'estimate.png', 'output.mcap', 'intersections')


def _values(params_file: str | None, seed: int | None, overrides: dict) -> dict:
    values = P.load_yaml(params_file) if params_file else P.defaults()
    if seed is not None:
        values['seed'] = seed
    values.update(overrides)
    errors = P.check_all(values)
    if errors:
        raise ValueError('; '.join(errors))
    return values


def _roles(reader, values: dict, configured: bool, wlog: WarningLog) -> dict[str, str]:
    """topic -> input role: the topics a params file names, else found by message type.

    Found by type, one topic carrying tracks is used (the same tracks published in two
    message families would count twice) and one odometry topic; the others are noted.
    """
    present = {t.topic: t.msgtype for t in reader.topics}
    if configured:
        wanted = {t: role for role, ts in P.topics(values).items() for t in ts}
        if values[ODOMETRY]:
            wanted[values[ODOMETRY]] = ODOMETRY
        missing = sorted(t for t in wanted if t not in present)
        roles = {t: r for t, r in wanted.items() if t in present}
        have = ', '.join(f'{t} [{m}]' for t, m in sorted(present.items())) or 'no topics'
        if set(roles.values()) <= {ODOMETRY}:
            raise BagError('no_usable_topic', f'none of the configured input topics '
                           f'({", ".join(t for t in missing if wanted[t] != ODOMETRY)}) is in the bag; '
                           f'it has: {have}')
        if missing:
            wlog.info(f'configured topic(s) not in the bag(s): {", ".join(missing)}')
        return roles
    found = reader.detect_topics()
    roles = {t: role for role, ts in found.items() for t in ts}
    for group in (sorted(t for t in roles if present[t] in TRACK_TYPES), found.get(ODOMETRY, [])):
        for t in group[1:]:
            del roles[t]
        if len(group) > 1:
            wlog.info(f'using {group[0]}; also found by type, not used: {", ".join(group[1:])}')
    if ODOMETRY not in roles.values():
        wlog.note('no odometry (nav_msgs/Odometry) in the bag(s): observations in a sensor frame '
                     'need the ego pose')
    return roles


class _Recorder(OnlineEstimator):
    """The node's estimator, keeping the estimate of every intersection it finished (the
    result before each reset: ego passed, time base moved)."""

    def __init__(self, config, seed, clock, ego):
        self.finished: list[Intersection] = []
        self.ending, self.clock, self.ego = 'time_base_reset', clock, ego
        super().__init__(config, seed)

    def reset(self) -> None:
        r = getattr(self, 'result', None)
        if r is not None and r.intersection is not None:
            self.finished.append(Intersection(r, self.window(), self.ending, self.clock(), self.ego()))
        self.ending = 'time_base_reset'
        super().reset()


@dataclass
class _Run:
    """State of one replay while it reads the bags."""

    ingest: Ingest
    estimator: _Recorder
    writer: BagWriter | None
    values: dict
    wall_budget: bool
    log: WarningLog
    messages: int = 0
    ticks: int = 0
    idle_ticks: int = 0
    detections: int = 0
    marker_keys: set = field(default_factory=set)


def replay(bags: list[str], out: str | Path, *, params_file: str | None = None, seed: int | None = None,
           budget_mode: str = 'samples', progress: bool = True, write_outputs: bool = True,
           log=None, origin: tuple[float, float] | None = None) -> ReplaySummary:
    """Run the pipeline over ``bags``; raises :class:`BagError` with a one-line reason.

    ``origin``: (latitude, longitude) of the fixed frame's origin for ``lanelets.osm``
    (default: the ``geo_origin`` parameter).

    ``log``: called with each warning line (the ingest warnings the node would log, at most
    one per reason per 5 s of bag time; notes on the input) -- default: kept in the summary only.
    """
    t_start = time.perf_counter()
    values = _values(params_file, seed, {} if origin is None else {'geo_origin': [float(v) for v in origin]})
    out, wlog = Path(out), WarningLog(log)
    with open_bags(bags) as reader:
        for note in reader.notes:
            wlog.note(note)
        roles = _roles(reader, values, params_file is not None, wlog)
        if not roles or set(roles.values()) == {ODOMETRY}:
            raise BagError('no_usable_topic', 'none of the configured input topics is in the bag')
        tmp = _temp_dir(out) if write_outputs else None
        try:
            run = _start(values, tmp, budget_mode == 'wall', wlog)
            total = sum(t.count for t in reader.topics if t.topic in roles)
            _feed(run, reader, roles, _tf_topics(reader), progress, total)
            damage = [str(p) for p in reader.problems]
            if run.messages < total:   # corrupt bytes inside a readable chunk: skipped, not silently
                damage.append(f'{total - run.messages} of {total} indexed messages could not be read')
            summary = _finish(run, tmp, budget_mode == 'samples', '; '.join(damage))
            if tmp is not None:
                summary.files = _move_into_place(tmp, out, summary.files)
        finally:
            if tmp is not None:
                shutil.rmtree(tmp, ignore_errors=True)
    summary.wall_s = time.perf_counter() - t_start
    return summary


def _start(values, tmp, wall_budget: bool, wlog) -> _Run:
    from msg_adapters.types import RosbagsTypes
    ingest = Ingest(values, RosbagsTypes(typestore()))
    estimator = _Recorder(P.pipeline_config(values), values['seed'], lambda: ingest.latest_stamp,
                          lambda: _ego(ingest))
    writer = BagWriter(tmp / '.output_bag') if tmp is not None else None
    return _Run(ingest, estimator, writer, values, wall_budget, wlog)


def _ego(ingest: Ingest) -> tuple | None:
    """The latest ego pose (x, y, yaw) in the fixed frame, None before odometry."""
    p = ingest.ego.latest
    return None if p is None else (float(p.x), float(p.y), float(p.yaw))


def _tf_topics(reader) -> dict[str, bool]:
    """The bag's /tf and /tf_static topics (tf2_msgs/TFMessage) -> static?: sensor mounts and
    map -> odom for Ingest, as the node subscribes to them."""
    return {t.topic: TF_TOPICS[t.topic] for t in reader.topics
            if t.topic in TF_TOPICS and t.msgtype == TF_TYPE}


def _feed(run: _Run, reader, roles: dict, tf: dict, progress: bool, total: int) -> None:
    """Every message through Ingest (``tf`` topics to its TF buffer), ticks at the node's
    period in bag time."""
    period_ns = int(round(run.values['timer_period'] * 1e9))
    next_tick = None
    total += sum(t.count for t in reader.topics if t.topic in tf)
    for m in _progress(reader.messages(topics=sorted(set(roles) | set(tf))), progress, total):
        if m.topic in tf:
            run.ingest.handle_tf(m.msg, tf[m.topic])
            run.log.emit(run.ingest.pop_warnings(), m.t)
            continue
        run.messages += 1
        run.detections += run.ingest.handle(roles[m.topic], m.msg, run.estimator)
        run.log.emit(run.ingest.pop_warnings(), m.t)
        next_tick = m.t_ns + period_ns if next_tick is None else next_tick
        while m.t_ns >= next_tick:
            _tick(run, next_tick)
            next_tick += period_ns
            if m.t_ns >= next_tick and run.estimator.idle:
                # no message since this tick and nothing to sample: the ticks up to this message
                # would repeat it exactly -- one stands for them (a gap in bag time costs nothing)
                skip = (m.t_ns - next_tick) // period_ns
                run.idle_ticks += skip
                next_tick += skip * period_ns
    if next_tick is not None:
        _tick(run, next_tick)
    run.ingest.flush_pending()
    run.log.emit(run.ingest.pop_warnings(), None)


def _tick(run: _Run, t_ns: int) -> None:
    def passed(text):
        run.estimator.ending = 'ego_passed'
        run.log.note(f'{text} (bag time {t_ns * 1e-9:.3f} s)')
    result = tick(run.ingest, run.estimator, wall_budget=run.wall_budget, log=passed)
    if result is None:
        return
    run.ticks += 1
    if run.writer is not None:
        _publish(run, result, t_ns * 1e-9)


def _publish(run: _Run, result, t: float) -> None:
    """The node's output messages of one tick into output.mcap."""
    from msg_adapters.lanelets import lanelets_msg
    from msg_adapters.markers import markers_msg
    from msg_adapters.topology import topology_msg
    from msg_adapters.types import make_header
    writer = run.writer
    types = writer.types
    header = make_header(types, run.values['fixed_frame'], t)
    topo = topology_msg(types, header, result.intersection, result.topology_samples,
                        result.log_posterior, result.observations, result.state)
    writer.write(OUTPUT_TOPICS['topology'][0], topo, t)
    if result.intersection is not None and result.lanes_updated:
        writer.write(OUTPUT_TOPICS['lanelets'][0], lanelets_msg(types, header, result.lanelets,
                                                                result.lane_samples), t)
        markers, run.marker_keys = markers_msg(types, header, result.intersection, result.lanelets,
                                               run.marker_keys)
        writer.write(OUTPUT_TOPICS['markers'][0], markers, t)


def _finish(run: _Run, tmp, deterministic: bool, truncated: str) -> ReplaySummary:
    """The intersections of the drive, the summary and (with ``tmp``) the files."""
    est = run.estimator
    last = est.result if run.ticks else None
    done = list(est.finished)
    if last is not None and last.intersection is not None:
        done.append(Intersection(last, est.window(), 'end_of_input', run.ingest.latest_stamp,
                                 _ego(run.ingest)))
    ing = run.ingest
    why = '' if done else why_no_intersection(ing.received, ing.dropped, run.detections, run.messages)
    summary = ReplaySummary(run.messages, run.ticks, done[-1].result if done else last, {}, dict(ing.dropped),
                            0.0, truncated, intersections=done, received=dict(ing.received), notes=run.log.lines, infos=run.log.infos,
                            idle_ticks=run.idle_ticks, why=why)
    if run.writer is not None:
        run.writer.close()
        _single_mcap(tmp / '.output_bag', tmp / 'output.mcap')
    if tmp is not None:
        summary.files = _write_files(tmp, summary, run.values, deterministic)
        summary.files['output'] = str(tmp / 'output.mcap')
    return summary


def _single_mcap(bag_dir: Path, target: Path) -> None:
    """Move the rosbag2 writer's one .mcap file to ``target`` (Foxglove, ros2 bag and rosbags
    all open a bare .mcap) and drop the bag directory."""
    target.unlink(missing_ok=True)
    (mcap,) = bag_dir.glob('*.mcap')
    mcap.rename(target)
    shutil.rmtree(bag_dir)


def _write_files(out: Path, summary: ReplaySummary, values, deterministic: bool) -> dict:
    """estimate.json (+ osm, png) per intersection into ``intersections/NN``, the last one
    (or the NO_DATA estimate) also at the top."""
    counts = {'received': summary.received, 'dropped': summary.dropped,
              'intersections': len(summary.intersections)}
    if not summary.intersections:
        from .estimate_io import write_estimate
        stats = dict(summary.result.stats() if summary.result is not None else {}, **counts,
                     why=summary.why, state='NO_DATA')
        if deterministic:
            stats['elapsed_s'] = 0.0
        return {'estimate': str(write_estimate(out / 'estimate.json', None, [], stats))}
    files = {}
    for k, item in enumerate(summary.intersections):
        files = _write_one(out / 'intersections' / f'{k:02d}', item, dict(counts, index=k), deterministic,
                           tuple(values['geo_origin']), values['fixed_frame'])
    for key, path in list(files.items()):
        files[key] = str(shutil.copy2(path, out / Path(path).name))
    return files


def _write_one(folder: Path, item: Intersection, counts: dict, deterministic: bool, origin: tuple,
               frame: str) -> dict:
    from .estimate_io import write_estimate
    from .export.osm import write_osm
    from .export.plot import plot_estimate
    folder.mkdir(parents=True, exist_ok=True)
    r = item.result
    stats = dict(r.stats(), **counts, ended=item.ended, t_end=item.t_end)
    if deterministic:
        # same bag + seed -> byte-identical estimate.json: no wall time in it (the summary has it)
        stats['elapsed_s'] = 0.0
    return {'estimate': str(write_estimate(folder / 'estimate.json', r.intersection, r.lanelets, stats)),
            'osm': str(write_osm(folder / 'lanelets.osm', r.lanelets, origin_latlon=origin)),
            'plot': str(plot_estimate(folder / 'estimate.png', r.intersection, r.lanelets, dets=item.window,
                                      title=f'intersection {counts["index"]:02d} ({item.ended})',
                                      ego=item.ego, frame=frame, stamp=item.t_end, result=r))}


def _temp_dir(out: Path) -> Path:
    """A fresh folder beside ``out`` (same file system: the final move is a rename)."""
    out.parent.mkdir(parents=True, exist_ok=True)
    return Path(tempfile.mkdtemp(prefix=f'.{out.name}.', suffix='.tmp', dir=out.parent))


def _move_into_place(tmp: Path, out: Path, files: dict) -> dict:
    """Replace the replay outputs in ``out`` (old ones included, also those this run did not
    write: no stale png beside a new estimate) by the new ones; other files stay."""
    out.mkdir(parents=True, exist_ok=True)
    for name in OUTPUT_NAMES:
        old = out / name
        if old.is_dir() and not old.is_symlink():
            shutil.rmtree(old)
        elif old.exists() or old.is_symlink():
            old.unlink()
    for item in sorted(tmp.iterdir()):
        item.rename(out / item.name)
    return {k: str(out / Path(v).relative_to(tmp)) for k, v in files.items()}


def _progress(it, enabled: bool, total: int):
    if not enabled:
        return it
    from tqdm import tqdm
    return tqdm(it, total=total, unit='msg', desc='replay', file=sys.stderr,
                mininterval=0.5, leave=False)


# -- command line -------------------------------------------------------------------------------
_EPILOG = ('exit codes: 0 intersection estimated; 1 unusable input or arguments (nothing written); '
           '2 bag damaged, estimate from what could be read; 3 no intersection estimated '
           '(estimate.json of state NO_DATA written, the reason printed)')


def register(sub) -> None:
    p = sub.add_parser('replay', help='run the estimator over rosbag2 bags (MCAP, sqlite3)',
                       description=__doc__, epilog=_EPILOG, formatter_class=_raw())
    p.usage_exit = EXIT_UNUSABLE   # bad arguments: 1 as documented (2 means a damaged bag)
    p.add_argument('bags', nargs='+', help='rosbag2 bag directories or .mcap / .db3 files')
    p.add_argument('--out', default='replay_out', help='output directory (default: replay_out)')
    p.add_argument('--params', help='parameter YAML (default: built-in defaults, topics found by type)')
    p.add_argument('--seed', type=int, help='seed (overrides the params file)')
    p.add_argument('--origin', type=_origin, metavar='LAT,LON',
                   help="geo origin of the fixed frame for lanelets.osm (default: the geo_origin parameter, "
                        "49.0,8.4)")
    p.add_argument('--budget-mode', choices=('samples', 'wall'), default='samples',
                   help='samples: deterministic sample budget per tick (default); wall: the node\'s time budget')
    p.add_argument('--live', action='store_true', help='publish the bag over DDS at bag rate (and /clock) instead')
    p.add_argument('--rate', type=float, default=1.0, help='--live playback rate (default 1.0)')
    p.add_argument('--wait', type=float, default=10.0,
                   help='--live: seconds to wait for subscribers before playing (default 10)')
    p.add_argument('--json', action='store_true', help='print the summary as JSON')
    p.add_argument('--quiet', action='store_true', help='no progress bar')
    p.set_defaults(func=_main)
    d = sub.add_parser('demo', help='replay the bundled sample bag into demo_out/ and summarise',
                       description='Replay the bundled sample bag (deterministic) and score the estimate '
                                   'against its ground truth.', epilog=_EPILOG)
    d.add_argument('--out', default='demo_out', help='output directory (default: demo_out)')
    d.add_argument('--bag', default=None, help='bag to use (default: the bundled tracked-objects bag)')
    d.set_defaults(func=_demo)


def _origin(text: str) -> tuple[float, float]:
    import argparse
    from .export.osm import parse_origin
    try:
        return parse_origin(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _raw():
    import argparse
    return argparse.RawDescriptionHelpFormatter


def _stderr(line: str) -> None:
    print(f'replay: {line}', file=sys.stderr)


def _main(args) -> int:
    try:
        if args.live:
            from .live import play
            return play(args.bags, rate=args.rate, wait_s=args.wait)
        summary = replay(args.bags, args.out, params_file=args.params, seed=args.seed,
                         budget_mode=args.budget_mode, progress=not args.quiet, log=_stderr,
                         origin=args.origin)
    except (BagError, ValueError, OSError) as exc:
        _stderr(_one_line(exc))
        return EXIT_UNUSABLE
    except Exception as exc:  # noqa: BLE001 - whatever a damaged bag provokes: one line, not a traceback
        _stderr(f'failed: {type(exc).__name__}: {_one_line(exc)}')
        return EXIT_UNUSABLE
    if summary.truncated:
        _stderr(f'bag damaged ({_one_line(summary.truncated)}); wrote the estimate from the '
                f'{summary.messages} messages that could be read')
    if summary.why:
        _stderr(f'no intersection estimated: {summary.why}')
    print(json.dumps(summary.to_json(), indent=1) if args.json else '\n'.join(summary.lines()))
    return summary.exit_code


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
        summary = replay([str(bag)], args.out, progress=True, log=_stderr)
    except (BagError, ValueError, OSError) as exc:
        print(f'demo: {_one_line(exc)}', file=sys.stderr)
        return EXIT_UNUSABLE
    print('\n'.join(summary.lines()))
    gt = bag.parent / f'{bag.name}.gt.json'
    if gt.exists() and summary.intersections:
        from .evaluate import evaluate_files
        m = evaluate_files(summary.files['estimate'], str(gt))
        keys = ('arm_correct', 'topology_correct', 'center_error_m', 'lane_error_cm', 'lane_recall',
                'connectivity_recall')
        fmt = (lambda v: f'{v:.3g}' if isinstance(v, float) else str(v))
        print('against ground truth: ' + ', '.join(f'{k} {fmt(m.get(k))}' for k in keys))
    return summary.exit_code
