"""Benchmark after the paper's Table I / §IV (issue 4, DESIGN.md §5) on three families.

``--family`` (issue 15): ``table1`` -- our simulator (paper Table I; ``--empty-lanes P``
leaves each lane without traffic with probability P, measured separately); ``sumo`` --
SUMO traffic on generated and inD junctions (:mod:`intersection_estimator.scenarios.sumo`);
``sumo_road`` -- the same junctions with through traffic on the main road only (the data
show a road: ``road_no_intersection_rate``);
``av2`` -- the Argoverse 2 scenarios in ``../shared/realdata/av2`` (case ``i`` = the
``i``-th, ``--n`` at most their number).

Case ``i`` makes scenario ``seed + i`` in-process (no bag IO), runs the estimator
(``intersection_estimator.pipeline.estimate``) on its detections of ``--mode``, scores
it with :func:`intersection_estimator.evaluate.evaluate` and pools the cases with
:func:`~intersection_estimator.evaluate.aggregate`. ``--oracle`` scores the ground
truth itself (sanity row: must be perfect). Timings are the estimator's own
``timing_ms`` measured inside the worker per case; with ``--jobs > 1`` the workers
share the machine's cores, so use ``--jobs 1`` for headline timings.

JSON (stable interface for CI): ``{"config", "summary", "cases": [{"seed", "true",
"estimate", "metrics", "timing_ms"}]}``; ``true`` / ``estimate`` hold the topology part
of estimate.json (center, arms) and the lane count -- lane polylines are left out to
keep the file small (regenerate them with ``simulate --seed``).
"""

from __future__ import annotations

import argparse
from dataclasses import asdict, dataclass, replace
import multiprocessing as mp
import os
from pathlib import Path
import platform
import sys
import time
import traceback

from .estimate_io import dumps, estimate_to_dict
from .evaluate import aggregate, evaluate
from .sim import MODES, SimConfig, simulate_scenario
from .sim.scenario import TURN_HANDLES
from .tracking import TrackerConfig

__all__ = ['BenchOptions', 'run_bench', 'run_case', 'format_table', 'PAPER', 'register',
           'merge_results', 'make_case', 'FAMILIES',
           'package_version', 'machine_info']

#: Paper figures (§IV, i7-8750H, C++) per mode; 'raw' also stands for 'heading'.
PAPER = {
    'arm_accuracy': {'tracked': 1.0, 'raw': 0.999},
    'topology_accuracy': {'tracked': 0.9228, 'raw': 0.8490},
    'center_error_m_mean': {'tracked': 1.99, 'raw': 2.15},     # read off Fig. 4 at 5000
    'angle_error_deg_mean': {'tracked': 0.34, 'raw': 0.97},
    'lane_error_cm_mean': {'tracked': 14.0, 'raw': 14.0},
    'topology_ms_median': {'tracked': 35.72, 'raw': 55.38},    # paper: mean
    'lanes_ms_median': {'tracked': 104.05, 'raw': 104.05},     # paper: mean
    'total_ms_median': {'tracked': 140.05, 'raw': 140.05},     # paper: mean
}


@dataclass(frozen=True)
class BenchOptions:
    n: int = 1000
    mode: str = 'tracked'
    samples: int = 5000
    lane_samples: int = 20000
    seed: int = 0
    jobs: int = 1
    oracle: bool = False
    warmup: bool = True     # one small untimed estimator run per process first
    profile: bool = False   # per case: where the time went (EstimateResult.phases_ms)
    cost_model: bool = False   # per case: the sampler's work vs its limit (topology.cost_model)
    family: str = 'table1'
    empty_lanes: float = 0.0   # table1: share of lanes left without traffic
    track_noise_corr: float = 0.0   # tracked: AR(1) track error per cycle (sim/sensors.py)
    position_noise: float = 1.0     # simulated families: sigma of every detection's position [m]
    turn_shape: str = 'arc'         # table1: connector family of the simulator (SimConfig)
    radar_tracking: bool = True   # raw: radar rows through the tracker (False: the paper's model)

    def sim_config(self) -> SimConfig:
        """The sensor and traffic settings the simulated families run with."""
        return SimConfig(empty_lane_prob=self.empty_lanes, track_noise_corr=self.track_noise_corr,
                         position_noise=self.position_noise, turn_shape=self.turn_shape)


FAMILIES = ('table1', 'sumo', 'sumo_road', 'av2')
TURN_SHAPES = tuple(TURN_HANDLES)
_SCENARIO_FIELDS = ('seed', 'config', 'gt', 'gt_lanelets', 'traffic', 'tracks', 'ego', 'duration',
                    'stop', 'sensor_range', 'sensors')


def make_case(opts: BenchOptions, i: int):
    """(scenario, gt dict) of case ``i`` of the family."""
    from .scenarios import gt_doc
    if opts.family == 'table1':
        from .scenarios.base import FamilyScenario
        from .scenarios.floor import scene_traffic_lines
        sc = simulate_scenario(opts.seed + i, opts.sim_config())
        sc = FamilyScenario(**{f: getattr(sc, f) for f in _SCENARIO_FIELDS})
        sc.extra_gt = scene_traffic_lines(sc)         # the floor of the case
    elif opts.family in ('sumo', 'sumo_road'):
        from .scenarios.sumo import sumo_scenario
        from .scenarios.sumo_config import SumoConfig
        sc = sumo_scenario(opts.seed + i, SumoConfig(road_only=opts.family == 'sumo_road'),
                           opts.sim_config())
    elif opts.family == 'av2':
        from .realdata.av2 import find_scenarios, load_av2
        from .scenarios.sumo_net import realdata_dir
        found = find_scenarios(realdata_dir() / 'av2')
        if i >= len(found):
            raise ValueError(f'av2: case {i} but only {len(found)} scenarios')
        sc = load_av2(found[i])
    else:
        raise ValueError(f'family {opts.family!r} not in {FAMILIES}')
    return sc, gt_doc(sc, arrays=True)


def package_version() -> str:
    """The package's ``__version__`` (installed or source checkout)."""
    from . import __version__
    return __version__


def machine_info() -> dict:
    return {'platform': platform.platform(), 'machine': platform.machine(),
            'processor': platform.processor(), 'python': platform.python_version(),
            'cpu_count': os.cpu_count()}


def _load_estimator():
    from .pipeline import estimate
    return estimate


def _topology_part(doc: dict) -> dict:
    return {'center': doc['center'], 'arms': doc['arms'], 'n_lanes': len(doc.get('lanes', []))}


def _run_estimator(estimator, sc, opts: BenchOptions):
    """-> (estimate.json dict, timing_ms, profile) of the estimator on the scenario's detections."""
    dets = sc.detections(opts.mode)
    t0 = time.perf_counter()
    extra = {} if opts.radar_tracking else {'tracker_config': TrackerConfig(enabled=False)}
    res = estimator(dets, mode=opts.mode, topology_samples=opts.samples,
                    lane_samples=opts.lane_samples, seed=sc.seed, **extra)
    wall = 1e3 * (time.perf_counter() - t0)
    timing = {k: float(v) for k, v in dict(getattr(res, 'timing_ms', None) or {}).items()}
    timing.setdefault('total', wall)
    timing['wall'] = wall
    if res.intersection is None:
        raise ValueError('estimator returned no intersection')
    stats = {'topology_samples': opts.samples, 'lane_samples': opts.lane_samples,
             'elapsed_s': timing['total'] / 1e3}
    profile = {'phases_ms': dict(getattr(res, 'phases_ms', None) or {}),
               'counters': dict(getattr(res, 'counters', None) or {})}
    return estimate_to_dict(res.intersection, list(res.lanelets or []), stats, arrays=True), timing, profile


_WARM: set = set()


def _warm_up(estimator, opts: BenchOptions) -> None:
    """Run the estimator once per process on a small budget before timing anything, so
    one-off costs (imports, JIT compilation) do not land in the first case's timing."""
    key = (getattr(estimator, '__module__', ''), getattr(estimator, '__qualname__', ''), opts.mode)
    if opts.warmup and key not in _WARM:
        _WARM.add(key)
        small = BenchOptions(mode=opts.mode, samples=min(opts.samples, 200),
                             lane_samples=min(opts.lane_samples, 200),
                             radar_tracking=opts.radar_tracking)
        try:
            _run_estimator(estimator, simulate_scenario(opts.seed, SimConfig()), small)
        except Exception:  # noqa: BLE001 - the real case will report it
            pass


def run_case(i: int, opts: BenchOptions, estimator=None) -> dict:
    """Simulate, estimate (or oracle), evaluate case ``i``; never raises for estimator
    errors, and a case the family cannot make (a SUMO tool failing) is a failed case."""
    seed = opts.seed + i
    t0 = time.perf_counter()
    try:
        sc, gt = make_case(opts, i)
    except Exception as e:  # noqa: BLE001 - one bad case must not stop a benchmark
        from .evaluate import failed_case
        metrics = failed_case(f'case not made: {type(e).__name__}: {e}')
        return {'seed': seed, 'true': None, 'estimate': None, 'metrics': metrics,
                'timing_ms': {'simulate': 1e3 * (time.perf_counter() - t0)}}
    sim_ms = 1e3 * (time.perf_counter() - t0)
    tb = profile = None
    if opts.oracle:
        est, timing = gt, {}
    else:
        try:
            estimator = estimator or _load_estimator()
            _warm_up(estimator, opts)
            est, timing, profile = _run_estimator(estimator, sc, opts)
        except Exception as e:  # noqa: BLE001 - one bad case must not stop a benchmark
            est, timing = {'error': f'{type(e).__name__}: {e}'}, {}
            tb = traceback.format_exc(limit=3)
        from . import speed_index as SI   # lazy: importing numba costs seconds (--help must not)
        ref = SI.after_case(timing.get('wall', 0.0))   # the speed index, in this process, now
        if ref is not None:
            timing['reference'] = ref
    # lane step skipped: score the topology only, but against the truth's lane traffic
    # (which lanes and arms were used), as a full run does
    metrics = evaluate(est, gt, score_lanes=opts.lane_samples > 0)
    if 'error' in est:
        metrics['reason'] = f'estimator raised {est["error"]}'
        metrics['traceback'] = tb
    timing['simulate'] = sim_ms
    case = {'seed': seed, 'true': _topology_part(gt),
            'estimate': _topology_part(est) if 'center' in est else None,
            'metrics': metrics, 'timing_ms': timing}
    if opts.profile and profile is not None:
        case['profile'] = profile
        if opts.cost_model:       # after the timed run and its index repetition: untimed
            from .topology.cost_model import case_cost
            profile['cost_model'] = case_cost(sc.detections(opts.mode), opts.mode,
                                              opts.samples, sc.seed)
    return case


def _worker(args):
    i, opts = args
    return run_case(i, opts)


def _progress(total):
    try:
        from tqdm import tqdm
        return tqdm(total=total, file=sys.stderr, unit='case', dynamic_ncols=True)
    except ImportError:  # pragma: no cover - tqdm is a dependency
        return None


def run_bench(opts: BenchOptions, estimator=None) -> dict:
    """All cases (``jobs`` spawn workers, or in-process with ``jobs == 1``) -> bench JSON dict.

    ``estimator`` (in-process only) replaces ``pipeline.estimate``; it must have that
    signature: ``estimator(dets, *, mode, topology_samples, lane_samples, seed)``.
    """
    if opts.mode not in MODES:
        raise ValueError(f'mode {opts.mode!r} not in {MODES}')
    if opts.family not in FAMILIES:
        raise ValueError(f'family {opts.family!r} not in {FAMILIES}')
    if estimator is not None and opts.jobs > 1:
        raise ValueError('a custom estimator runs in-process only (jobs=1)')
    bar = _progress(opts.n)
    cases = []
    t0 = time.perf_counter()
    from . import speed_index as SI
    meter = None if opts.oracle else SI.SpeedMeter()
    meter and meter.warm(5)
    if opts.jobs > 1:
        with mp.get_context('spawn').Pool(opts.jobs) as pool:
            for case in pool.imap(_worker, ((i, opts) for i in range(opts.n)), chunksize=2):
                cases.append(case)
                bar and bar.update()
    else:
        for i in range(opts.n):
            cases.append(run_case(i, opts, estimator))
            bar and bar.update()
    bar and bar.close()
    summary = aggregate([c['metrics'] for c in cases], [c['timing_ms'] for c in cases])
    index = _speed_index(meter, cases, summary)
    config = {**asdict(opts), 'estimator': 'oracle (ground truth)' if opts.oracle else
              getattr(estimator, '__module__', 'intersection_estimator.pipeline') + '.estimate',
              'sim_config': opts.sim_config().to_dict(),
              'family_config': _family_config(opts.family), 'package_version': package_version(),
              'machine': machine_info(), 'wall_s': time.perf_counter() - t0,
              'timing_note': ('timing_ms measured inside the worker per case (estimator only, '
                              'simulation excluded, after one untimed warm-up run per '
                              'process); ' + (
                                  f'{opts.jobs} workers shared {os.cpu_count()} cores, so '
                                  'timings are inflated: use --jobs 1 for headline timings'
                                  if opts.jobs > 1 else 'single process')),
              'speed_index': index}
    out = {'config': config, 'summary': summary, 'cases': cases}
    if opts.profile:
        out['profile'] = SI.profile_summary(cases, index and index['ref_ms'])
    if opts.profile and opts.cost_model:
        from .topology.cost_model import summarise
        out['profile']['cost_model'] = summarise([c.get('profile', {}).get('cost_model')
                                                  for c in cases])
    return out


def _speed_index(meter, cases, summary) -> dict | None:
    """The run's speed index (issue 18): reference repetitions before the cases, one after each
    case (in its worker) and after the cases; every ``*_ms_*`` figure also as ``*_ref_*``."""
    from . import speed_index as SI
    if meter is None:
        return None
    for c in cases:
        if c['timing_ms'].get('reference') is not None:
            meter.add(c['timing_ms']['reference'])
    meter.warm(5)
    index = meter.result()
    summary.update(SI.relative_summary(summary, index['ref_ms']))
    return index


def _family_config(family: str) -> dict:
    if family in ('sumo', 'sumo_road'):
        from .scenarios.sumo_config import SumoConfig
        return SumoConfig(road_only=family == 'sumo_road').to_dict()
    return {}


def merge_results(results: list[dict]) -> dict:
    """One bench result from several runs of the same family / mode (chunks of seeds):
    cases concatenated in seed order, summary re-pooled with :func:`aggregate`."""
    if not results:
        raise ValueError('nothing to merge')
    keys = {(r['config'].get('family', 'table1'), r['config']['mode']) for r in results}
    if len(keys) != 1:
        raise ValueError(f'cannot merge runs of different family / mode: {sorted(keys)}')
    cases = sorted((c for r in results for c in r['cases']), key=lambda c: c['seed'])
    seeds = [c['seed'] for c in cases]
    if len(set(seeds)) != len(seeds):
        raise ValueError('the runs share seeds')
    config = {**results[0]['config'], 'n': len(cases), 'seed': min(seeds),
              'merged_from': [[r['config']['seed'], r['config']['n']] for r in results],
              'wall_s': sum(r['config'].get('wall_s', 0.0) for r in results)}
    summary = aggregate([c['metrics'] for c in cases], [c['timing_ms'] for c in cases])
    return {'config': config, 'summary': summary, 'cases': cases}


# ---------------------------------------------------------------- table
def _fmt(v, kind):
    if v is None:
        return '-'
    return {'pct': f'{100 * v:.2f} %', 'pct0': f'{100 * v:.0f} %', 'm': f'{v:.2f}',
            'deg': f'{v:.2f}', 'cm': f'{v:.1f}', 'ms': f'{v:.1f}'}[kind]


def format_table(result: dict) -> str:
    """One plain-text table: each metric beside the paper's figure."""
    cfg, s = result['config'], result['summary']
    pm = 'tracked' if cfg['mode'] == 'tracked' else 'raw'

    def paper(key, kind):
        return _fmt(PAPER[key][pm], kind) if key in PAPER else ''

    rows = [
        ('arm accuracy', _fmt(s['arm_accuracy'], 'pct'), paper('arm_accuracy', 'pct')),
        ('arm accuracy on arms with traffic', _fmt(s.get('arm_observed_accuracy'), 'pct'), ''),
        ('lane-level topology accuracy', _fmt(s['topology_accuracy'], 'pct'),
         paper('topology_accuracy', 'pct')),
        ('topology_observed (lanes with traffic)', _fmt(s.get('topology_observed_accuracy'), 'pct'),
         ''),
        ('center error mean / median [m]',
         f"{_fmt(s['center_error_m_mean'], 'm')} / {_fmt(s['center_error_m_median'], 'm')}",
         '~' + paper('center_error_m_mean', 'm') + ' (Fig. 4)'),
        ('angle error mean [deg]', _fmt(s['angle_error_deg_mean'], 'deg'),
         paper('angle_error_deg_mean', 'deg')),
        ('lane course error mean [cm]', _fmt(s['lane_error_cm_mean'], 'cm'),
         paper('lane_error_cm_mean', 'cm')),
        ('traffic-following floor (all / matched) [cm]',
         f"{_fmt(s.get('floor_cm_mean'), 'cm')} / {_fmt(s.get('floor_cm_matched_mean'), 'cm')}", ''),
        ('  floor entering / leaving / connector [cm]',
         ' / '.join(_fmt(s.get(f'floor_cm_mean_{k}'), 'cm')
                    for k in ('entering', 'leaving', 'connector')), ''),
        ('lane error entering / leaving / connector [cm]',
         ' / '.join(_fmt(s.get(f'lane_error_cm_mean_{k}'), 'cm')
                    for k in ('entering', 'leaving', 'connector')), ''),
        ('lane recall (lanes with traffic)', _fmt(s['lane_recall'], 'pct'), ''),
        ('  entering / leaving / connector',
         ' / '.join(_fmt(s.get(f'lane_recall_{k}'), 'pct0')
                    for k in ('entering', 'leaving', 'connector')), ''),
        ('lane precision', _fmt(s['lane_precision'], 'pct'), ''),
        ('connectivity recall', _fmt(s['connectivity_recall'], 'pct'), ''),
        (f"topology time median / p95 [ms] @{cfg['samples']}", _times(s, 'topology'),
         paper('topology_ms_median', 'ms') + ' (mean @5000)'),
        (f"lane course time median / p95 [ms] @{cfg['lane_samples']}", _times(s, 'lanes'),
         paper('lanes_ms_median', 'ms') + ' (mean @20000)'),
        ('total time median / p95 [ms]', _times(s, 'total'), paper('total_ms_median', 'ms') + ' (mean)'),
        ('road cases: no intersection reported',
         f"{_fmt(s.get('road_no_intersection_rate'), 'pct')} of {s.get('road_cases', 0)}", ''),
        ('failed cases', f"{s['n_failed']} / {s['n']}", ''),
    ]
    radar = ('' if cfg['mode'] != 'raw' else
             '  radar_tracking=' + ('on' if cfg.get('radar_tracking', True) else 'off (paper model)'))
    turns = '' if cfg.get('turn_shape', 'arc') == 'arc' else f"  turn_shape={cfg['turn_shape']}"
    head = (f"bench  family={cfg.get('family', 'table1')}  mode={cfg['mode']}{radar}{turns}  n={cfg['n']}  "
            f"seed={cfg['seed']}  jobs={cfg['jobs']}  "
            f"estimator={cfg['estimator']}")
    w0 = max(len(r[0]) for r in rows)
    w1 = max(len(r[1]) for r in rows + [('', 'ours', '')])
    lines = [head, f"{'metric':{w0}s}  {'ours':>{w1}s}  paper ({pm}, i7-8750H C++)",
             '-' * (w0 + w1 + 30)]
    lines += [f'{a:{w0}s}  {b:>{w1}s}  {c}' for a, b, c in rows]
    if 'speed_index' in cfg:
        from .speed_index import format_index
        lines.append(format_index(cfg['speed_index']))
    if cfg['jobs'] > 1:
        lines.append(f"note: {cfg['timing_note']}")
    return '\n'.join(lines)


def _times(s: dict, step: str) -> str:
    """'median / p95' in ms, and in x ref when the run measured its speed index."""
    ms = f"{_fmt(s[f'{step}_ms_median'], 'ms')} / {_fmt(s[f'{step}_ms_p95'], 'ms')}"
    med, p95 = s.get(f'{step}_ref_median'), s.get(f'{step}_ref_p95')
    if med is None or p95 is None:
        return ms
    return f'{ms} (= {med:.2f} / {p95:.2f} x ref)'


def is_perfect(summary: dict) -> bool:
    """What ``--oracle`` must give: every accuracy/recall 1, every error 0."""
    ones = ('arm_accuracy', 'topology_accuracy', 'lane_recall', 'lane_precision',
            'connectivity_recall')
    zeros = ('center_error_m_mean', 'angle_error_deg_mean', 'lane_error_cm_mean')
    return (summary['n_failed'] == 0 and all(summary[k] in (None, 1.0) for k in ones)
            and all(summary[k] is None or summary[k] < 1e-2 for k in zeros))


# ---------------------------------------------------------------- CLI
def _merge_cmd(args) -> int:
    import json
    try:
        result = merge_results([json.loads(Path(f).read_text()) for f in args.merge])
    except (OSError, ValueError, KeyError) as e:
        print(f'bench --merge: {e}', file=sys.stderr)
        return 2
    print(format_table(result))
    if args.json:
        Path(args.json).write_text(dumps(result))
        print(f'wrote {args.json}')
    return 0


def _refused(args) -> str | None:
    """Why the simulation options of ``args`` are refused (the first reason, naming its
    option), or None."""
    simulated = args.family in ('table1', 'sumo', 'sumo_road')
    for bad, why in (
            (not 0.0 <= args.empty_lanes < 1.0, f'--empty-lanes {args.empty_lanes} not in [0, 1)'),
            (not 0.0 <= args.track_noise_corr < 1.0,
             f'--track-noise-corr {args.track_noise_corr} not in [0, 1)'),
            (not args.position_noise > 0.0, f'--position-noise {args.position_noise} must be > 0'),
            ((args.track_noise_corr or args.position_noise != 1.0) and not simulated,
             '--track-noise-corr / --position-noise apply to the simulated families only'),
            (args.empty_lanes and args.family != 'table1',
             '--empty-lanes applies to --family table1 only'),
            (args.turn_shape != 'arc' and args.family != 'table1',
             '--turn-shape applies to --family table1 only (SUMO draws its own turns)')):
        if bad:
            return why
    return None


def _cmd(args) -> int:
    if args.merge:
        return _merge_cmd(args)
    refused = _refused(args)
    if refused:
        print(f'bench: {refused}', file=sys.stderr)
        return 2
    opts = BenchOptions(n=args.n, mode=args.mode, samples=args.samples,
                        lane_samples=args.lane_samples, seed=args.seed, jobs=args.jobs,
                        oracle=args.oracle, warmup=not args.no_warmup,
                        profile=getattr(args, 'profile', False) or getattr(args, 'cost_model', False),
                        cost_model=getattr(args, 'cost_model', False), family=args.family,
                        empty_lanes=args.empty_lanes, radar_tracking=not args.no_radar_tracking,
                        track_noise_corr=args.track_noise_corr, position_noise=args.position_noise,
                        turn_shape=args.turn_shape)
    if not opts.oracle:
        try:
            _load_estimator()
        except ImportError as e:
            print(f'bench: estimator not available ({e}); use --oracle', file=sys.stderr)
            return 2
    if opts.family == 'av2':
        from .realdata.av2 import find_scenarios
        from .scenarios.sumo_net import realdata_dir
        have = len(find_scenarios(realdata_dir() / 'av2'))
        if have == 0:
            print(f"bench: no AV2 scenarios under {realdata_dir() / 'av2'}", file=sys.stderr)
            return 2
        opts = replace(opts, n=min(opts.n, have))
    result = run_bench(opts)
    print(format_table(result))
    if 'profile' in result:
        from .speed_index import format_profile
        print(format_profile(result['profile'], opts.mode))
        if 'cost_model' in result['profile']:
            from .topology.cost_model import format_cost
            print(format_cost(result['profile']['cost_model']))
    if args.json:
        Path(args.json).write_text(dumps(result))
        print(f'wrote {args.json}')
    if opts.oracle and not is_perfect(result['summary']):
        print('bench: the oracle is not perfect -- evaluator or simulator bug', file=sys.stderr)
        return 1
    return 0


def register(subparsers) -> argparse.ArgumentParser:
    """Add the ``bench`` subcommand."""
    p = subparsers.add_parser('bench', help='benchmark (paper Table I, SUMO, AV2)',
                              description=__doc__.split('\n\n')[0])
    from .cli import int_at_least
    p.add_argument('--n', type=int_at_least(1), default=1000, help='number of intersections')
    p.add_argument('--family', choices=FAMILIES, default='table1',
                   help='table1: our simulator; sumo: SUMO on generated + inD junctions; '
                   'sumo_road: those with main-road through traffic only; '
                   'av2: the Argoverse 2 scenarios in ../shared/realdata/av2')
    p.add_argument('--empty-lanes', type=float, default=0.0, metavar='P',
                   help='table1: leave each lane without traffic with probability P')
    p.add_argument('--track-noise-corr', type=float, default=0.0, metavar='RHO',
                   help="simulated families, tracked: each track's position error AR(1) with "
                   "this correlation per cycle (a tracker's smoothed output; 0 = white)")
    p.add_argument('--position-noise', type=float, default=1.0, metavar='SIGMA',
                   help='simulated families: sigma of every detected position [m] (1.0: the '
                   "paper's §IV model)")
    p.add_argument('--turn-shape', choices=TURN_SHAPES, default='arc',
                   help="table1: the simulator's connectors -- arc: circular-arc Beziers, the "
                   "family the estimator's connectors start from; corner: Beziers through the "
                   "corner of the lanes' lines, a family the estimator does not share")
    p.add_argument('--mode', choices=MODES, default='tracked', help='detection input')
    p.add_argument('--samples', type=int, default=5000, help='topology MCMC samples')
    p.add_argument('--lane-samples', type=int, default=20000,
                   help='lane course MCMC samples (0 = skip the lane step)')
    p.add_argument('--seed', type=int_at_least(0), default=0, help='case i uses scenario seed + i')
    p.add_argument('--jobs', type=int_at_least(1), default=1, help='worker processes (spawn)')
    p.add_argument('--json', metavar='OUT', help='write config, summary and all cases')
    p.add_argument('--oracle', action='store_true',
                   help='score the ground truth itself (sanity: must be perfect)')
    p.add_argument('--profile', action='store_true',
                   help='per case and phase: where the time goes (table, and "profile" in --json)')
    p.add_argument('--cost-model', action='store_true',
                   help='with --profile: per case the sampler\'s work per sample vs the work a '
                   'move needs, and ns per observation vs a plain compiled loop (two untimed '
                   'replays per case; "profile.cost_model" in --json)')
    p.add_argument('--merge', nargs='+', metavar='JSON',
                   help='merge bench JSON files of one family / mode (chunks of seeds) '
                   'and print their pooled table (no cases run)')
    p.add_argument('--no-radar-tracking', action='store_true',
                   help="--mode raw: the paper's raw-detection model (radar rows voxelised), "
                   'not the radar tracker (intersection_estimator.tracking)')
    p.add_argument('--no-warmup', action='store_true',
                   help='time the first case cold (imports / JIT compilation included)')
    p.set_defaults(func=_cmd)
    return p
