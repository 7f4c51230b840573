"""Benchmark after the paper's Table I / §IV (issue 4, DESIGN.md §5) on three families.

``--family`` (issue 15): ``table1`` -- our simulator (paper Table I; ``--empty-lanes P``
leaves each lane without traffic with probability P, measured separately); ``sumo`` --
SUMO traffic on generated and inD junctions (:mod:`intersection_estimator.scenarios.sumo`);
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

__all__ = ['BenchOptions', 'run_bench', 'run_case', 'format_table', 'PAPER', 'register',
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
    family: str = 'table1'
    empty_lanes: float = 0.0   # table1: share of lanes left without traffic


FAMILIES = ('table1', 'sumo', 'av2')


def make_case(opts: BenchOptions, i: int):
    """(scenario, gt dict) of case ``i`` of the family."""
    from .scenarios import gt_doc
    if opts.family == 'table1':
        sc = simulate_scenario(opts.seed + i, SimConfig(empty_lane_prob=opts.empty_lanes))
    elif opts.family == 'sumo':
        from .scenarios.sumo import sumo_scenario
        sc = sumo_scenario(opts.seed + i)
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
    """-> (estimate.json dict, timing_ms) of the estimator on the scenario's detections."""
    dets = sc.detections(opts.mode)
    t0 = time.perf_counter()
    res = estimator(dets, mode=opts.mode, topology_samples=opts.samples,
                    lane_samples=opts.lane_samples, seed=sc.seed)
    wall = 1e3 * (time.perf_counter() - t0)
    timing = {k: float(v) for k, v in dict(getattr(res, 'timing_ms', None) or {}).items()}
    timing.setdefault('total', wall)
    timing['wall'] = wall
    if res.intersection is None:
        raise ValueError('estimator returned no intersection')
    stats = {'topology_samples': opts.samples, 'lane_samples': opts.lane_samples,
             'elapsed_s': timing['total'] / 1e3}
    return estimate_to_dict(res.intersection, list(res.lanelets or []), stats, arrays=True), timing


_WARM: set = set()


def _warm_up(estimator, opts: BenchOptions) -> None:
    """Run the estimator once per process on a small budget before timing anything, so
    one-off costs (imports, JIT compilation) do not land in the first case's timing."""
    key = (getattr(estimator, '__module__', ''), getattr(estimator, '__qualname__', ''), opts.mode)
    if opts.warmup and key not in _WARM:
        _WARM.add(key)
        small = BenchOptions(mode=opts.mode, samples=min(opts.samples, 200),
                             lane_samples=min(opts.lane_samples, 200))
        try:
            _run_estimator(estimator, simulate_scenario(opts.seed, SimConfig()), small)
        except Exception:  # noqa: BLE001 - the real case will report it
            pass


def run_case(i: int, opts: BenchOptions, estimator=None) -> dict:
    """Simulate, estimate (or oracle), evaluate case ``i``; never raises for estimator errors."""
    seed = opts.seed + i
    t0 = time.perf_counter()
    sc, gt = make_case(opts, i)
    sim_ms = 1e3 * (time.perf_counter() - t0)
    tb = None
    if opts.oracle:
        est, timing = gt, {}
    else:
        try:
            estimator = estimator or _load_estimator()
            _warm_up(estimator, opts)
            est, timing = _run_estimator(estimator, sc, opts)
        except Exception as e:  # noqa: BLE001 - one bad case must not stop a benchmark
            est, timing = {'error': f'{type(e).__name__}: {e}'}, {}
            tb = traceback.format_exc(limit=3)
    if opts.lane_samples == 0:   # lane step skipped: score topology only
        gt = {**gt, 'lanes': []}
        if 'lanes' in est:
            est = {**est, 'lanes': []}
    metrics = evaluate(est, gt)
    if 'error' in est:
        metrics['reason'] = f'estimator raised {est["error"]}'
        metrics['traceback'] = tb
    timing['simulate'] = sim_ms
    return {'seed': seed, 'true': _topology_part(gt),
            'estimate': _topology_part(est) if 'center' in est else None,
            'metrics': metrics, 'timing_ms': timing}


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
    config = {**asdict(opts), 'estimator': 'oracle (ground truth)' if opts.oracle else
              getattr(estimator, '__module__', 'intersection_estimator.pipeline') + '.estimate',
              'sim_config': SimConfig(empty_lane_prob=opts.empty_lanes).to_dict(),
              'family_config': _family_config(opts.family), 'package_version': package_version(),
              'machine': machine_info(), 'wall_s': time.perf_counter() - t0,
              'timing_note': ('timing_ms measured inside the worker per case (estimator only, '
                              'simulation excluded, after one untimed warm-up run per '
                              'process); ' + (
                                  f'{opts.jobs} workers shared {os.cpu_count()} cores, so '
                                  'timings are inflated: use --jobs 1 for headline timings'
                                  if opts.jobs > 1 else 'single process'))}
    return {'config': config, 'summary': summary, 'cases': cases}


def _family_config(family: str) -> dict:
    if family == 'sumo':
        from .scenarios.sumo_config import SumoConfig
        return SumoConfig().to_dict()
    return {}


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
        (f"topology time median / p95 [ms] @{cfg['samples']}",
         f"{_fmt(s['topology_ms_median'], 'ms')} / {_fmt(s['topology_ms_p95'], 'ms')}",
         paper('topology_ms_median', 'ms') + ' (mean @5000)'),
        (f"lane course time median / p95 [ms] @{cfg['lane_samples']}",
         f"{_fmt(s['lanes_ms_median'], 'ms')} / {_fmt(s['lanes_ms_p95'], 'ms')}",
         paper('lanes_ms_median', 'ms') + ' (mean @20000)'),
        ('total time median / p95 [ms]',
         f"{_fmt(s['total_ms_median'], 'ms')} / {_fmt(s['total_ms_p95'], 'ms')}",
         paper('total_ms_median', 'ms') + ' (mean)'),
        ('failed cases', f"{s['n_failed']} / {s['n']}", ''),
    ]
    head = (f"bench  family={cfg.get('family', 'table1')}  mode={cfg['mode']}  n={cfg['n']}  "
            f"seed={cfg['seed']}  jobs={cfg['jobs']}  "
            f"estimator={cfg['estimator']}")
    w0 = max(len(r[0]) for r in rows)
    w1 = max(len(r[1]) for r in rows + [('', 'ours', '')])
    lines = [head, f"{'metric':{w0}s}  {'ours':>{w1}s}  paper ({pm}, i7-8750H C++)",
             '-' * (w0 + w1 + 30)]
    lines += [f'{a:{w0}s}  {b:>{w1}s}  {c}' for a, b, c in rows]
    if cfg['jobs'] > 1:
        lines.append(f"note: {cfg['timing_note']}")
    return '\n'.join(lines)


def is_perfect(summary: dict) -> bool:
    """What ``--oracle`` must give: every accuracy/recall 1, every error 0."""
    ones = ('arm_accuracy', 'topology_accuracy', 'lane_recall', 'lane_precision',
            'connectivity_recall')
    zeros = ('center_error_m_mean', 'angle_error_deg_mean', 'lane_error_cm_mean')
    return (summary['n_failed'] == 0 and all(summary[k] in (None, 1.0) for k in ones)
            and all(summary[k] is None or summary[k] < 1e-2 for k in zeros))


# ---------------------------------------------------------------- CLI
def _cmd(args) -> int:
    if not 0.0 <= args.empty_lanes < 1.0:
        print(f'bench: --empty-lanes {args.empty_lanes} not in [0, 1)', file=sys.stderr)
        return 2
    if args.empty_lanes and args.family != 'table1':
        print('bench: --empty-lanes applies to --family table1 only', file=sys.stderr)
        return 2
    opts = BenchOptions(n=args.n, mode=args.mode, samples=args.samples,
                        lane_samples=args.lane_samples, seed=args.seed, jobs=args.jobs,
                        oracle=args.oracle, warmup=not args.no_warmup, family=args.family,
                        empty_lanes=args.empty_lanes)
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
    p.add_argument('--n', type=int, default=1000, help='number of intersections')
    p.add_argument('--family', choices=FAMILIES, default='table1',
                   help='table1: our simulator; sumo: SUMO on generated + inD junctions; '
                   'av2: the Argoverse 2 scenarios in ../shared/realdata/av2')
    p.add_argument('--empty-lanes', type=float, default=0.0, metavar='P',
                   help='table1: leave each lane without traffic with probability P')
    p.add_argument('--mode', choices=MODES, default='tracked', help='detection input')
    p.add_argument('--samples', type=int, default=5000, help='topology MCMC samples')
    p.add_argument('--lane-samples', type=int, default=20000,
                   help='lane course MCMC samples (0 = skip the lane step)')
    p.add_argument('--seed', type=int, default=0, help='case i uses scenario seed + i')
    p.add_argument('--jobs', type=int, default=1, help='worker processes (spawn)')
    p.add_argument('--json', metavar='OUT', help='write config, summary and all cases')
    p.add_argument('--oracle', action='store_true',
                   help='score the ground truth itself (sanity: must be perfect)')
    p.add_argument('--no-warmup', action='store_true',
                   help='time the first case cold (imports / JIT compilation included)')
    p.set_defaults(func=_cmd)
    return p
