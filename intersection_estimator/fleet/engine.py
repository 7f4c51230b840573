"""Run the estimator over many bags, one task per bag, locally or on Ray (issue 17).

* ``engine='local'``: in this process (``workers=1``) or a process pool;
* ``engine='ray'``: one Ray task per bag; ``ray.init()`` starts a local Ray on this
  machine (``workers`` CPUs) unless ``address`` names an existing cluster. ``ray`` is
  imported only here and only for this engine (``pip install .[fleet]``).

Determinism: a bag's seed comes from its identity (SHA-256 of its files' names and bytes),
never from its position or the worker that ran it; :func:`.fuse.fuse` sorts drives by
identity. So both engines, any worker count and any completion order give the same
``changes.json`` bytes.

The estimator is reached through ONE adapter, :func:`drive_estimates`, over the
``replay.replay`` summary: every intersection the drive passed (``summary.intersections``),
each matched to the map on its own.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import hashlib
import os
from pathlib import Path
import sys
import tempfile

from .changes import ChangeConfig, compare
from .corroborate import drive_traffic
from .match import match_intersection

__all__ = ['BagResult', 'bag_identity', 'seed_of', 'drive_estimates', 'process_bag', 'run', 'expand_bags']

ENGINES = ('local', 'ray')


@dataclass
class BagResult:
    """What one bag (drive) gave: its views of mapped intersections, or why it failed."""

    bag: str                       # the bag's name (no directories: no machine paths in outputs)
    identity: str
    status: str                    # 'ok' | 'damaged' | 'failed'
    reason: str = ''
    views: list = field(default_factory=list)       # [DriveView]
    estimates: list = field(default_factory=list)   # [(intersection id, center, lanelet center lines)]
    unmatched: int = 0             # estimates near no mapped intersection


def bag_identity(path) -> str:
    """SHA-256 (16 hex digits) of a bag's file names and bytes: the same bag, the same id."""
    p = Path(path)
    files = sorted(f for f in p.rglob('*') if f.is_file()) if p.is_dir() else [p]
    h = hashlib.sha256()
    for f in files:
        h.update(f.name.encode() + b'\0')
        with open(f, 'rb') as fh:
            for chunk in iter(lambda: fh.read(1 << 20), b''):
                h.update(chunk)
    return h.hexdigest()[:16]


def seed_of(identity: str) -> int:
    """The replay seed of a bag (within the ``seed`` parameter's range)."""
    return int(identity[:8], 16) % (2 ** 31 - 1)


def drive_estimates(bag: str, seed: int, params_file: str | None = None):
    """THE adapter to the replay API: ``([(Intersection, lanelets, window), ...], damage)`` for
    every intersection the drive passed, in drive order (``window``: the observations its
    estimate rests on, for :func:`.corroborate.drive_traffic`)."""
    from ..replay import replay
    with tempfile.TemporaryDirectory(prefix='ie_fleet_') as tmp:
        s = replay([bag], tmp, params_file=params_file, seed=seed, progress=False, write_outputs=False)
    ests = [(i.result.intersection, i.result.lanelets, i.window) for i in s.intersections
            if i.result.intersection is not None]
    return ests, s.truncated


def _one_line(exc, bag: str = '') -> str:
    text = ' '.join(str(exc).split())
    return f'{type(exc).__name__}: ' + (text.replace(str(bag), Path(bag).name) if bag else text)


def process_bag(bag: str, mapped: list, params_file: str | None = None,
                cfg: ChangeConfig = ChangeConfig()) -> BagResult:
    """One task: replay ``bag``, match its estimates to ``mapped``, compare. Never raises."""
    name = Path(bag).name
    try:
        ident = bag_identity(bag)
    except OSError as exc:
        return BagResult(name, '', 'failed', _one_line(exc, bag))
    try:
        ests, damage = drive_estimates(bag, seed_of(ident), params_file)
    except Exception as exc:  # noqa: BLE001 - a corrupt bag is reported, the fleet goes on
        return BagResult(name, ident, 'failed', _one_line(exc, bag))
    res = BagResult(name, ident, 'damaged' if damage else 'ok',
                    ' '.join(str(damage).split()).replace(str(bag), name))
    for I, lls, window in ests:
        X = match_intersection(I.center, mapped, cfg.gate_m)
        if X is None:
            res.unmatched += 1
            continue
        res.views.append(compare(I, lls, X, cfg, drive_traffic(window, X, cfg)))
        res.estimates.append((X.id, [float(v) for v in I.center],
                              [l.center.tolist() for l in lls]))
    return res


def expand_bags(paths) -> list[str]:
    """Bags of ``BAG_OR_DIR...``: a bag directory (with metadata.yaml) or file is itself; any
    other directory contributes the bags directly in it (sorted)."""
    def is_bag_dir(p: Path) -> bool:
        return (p / 'metadata.yaml').exists()
    out = []
    for s in paths:
        p = Path(s)
        if p.is_dir() and not is_bag_dir(p):
            out += [str(c) for c in sorted(p.iterdir())
                    if (c.is_dir() and is_bag_dir(c)) or c.suffix in ('.mcap', '.db3')]
        else:
            out.append(str(p))       # a missing path fails in its task, reported like a corrupt bag
    return out


def _bar(total: int, enabled: bool):
    from tqdm import tqdm
    return tqdm(total=total, unit='bag', desc='fleet', file=sys.stderr, disable=not enabled,
                mininterval=0.5, leave=False)


def _run_local(bags, mapped, params_file, cfg, workers, progress) -> list[BagResult]:
    out = {}
    with _bar(len(bags), progress) as bar:
        if workers <= 1:
            for i, b in enumerate(bags):
                out[i] = process_bag(b, mapped, params_file, cfg)
                bar.update(1)
        else:
            from concurrent.futures import ProcessPoolExecutor, as_completed
            with ProcessPoolExecutor(max_workers=workers) as pool:
                futs = {pool.submit(process_bag, b, mapped, params_file, cfg): i for i, b in enumerate(bags)}
                for f in as_completed(futs):
                    out[futs[f]] = f.result()
                    bar.update(1)
    return [out[i] for i in range(len(bags))]


def _ray_init(address: str | None, workers: int):
    import ray
    if ray.is_initialized():
        return ray, False
    if address:
        ray.init(address=address, log_to_driver=False)
    else:
        # the workers import the same intersection_estimator as this process
        here = str(Path(__file__).resolve().parents[2])
        path = os.pathsep.join(p for p in (here, os.environ.get('PYTHONPATH', '')) if p)
        ray.init(num_cpus=workers, include_dashboard=False, log_to_driver=False,
                 runtime_env={'env_vars': {'PYTHONPATH': path}})
    return ray, True


def _run_ray(bags, mapped, params_file, cfg, workers, progress, address) -> list[BagResult]:
    ray, started = _ray_init(address, workers)
    try:
        task = ray.remote(num_cpus=1, max_retries=0)(process_bag)
        ref_map = ray.put(mapped)
        refs = [task.remote(b, ref_map, params_file, cfg) for b in bags]
        index = {r: i for i, r in enumerate(refs)}
        out, pending = {}, list(refs)
        with _bar(len(bags), progress) as bar:
            while pending:
                done, pending = ray.wait(pending, num_returns=1)
                for r in done:
                    try:
                        out[index[r]] = ray.get(r)
                    except Exception as exc:  # noqa: BLE001 - a worker that died: that bag failed
                        b = bags[index[r]]
                        out[index[r]] = BagResult(Path(b).name, '', 'failed', _one_line(exc, b))
                    bar.update(1)
        return [out[i] for i in range(len(bags))]
    finally:
        if started:
            ray.shutdown()


def run(bags, mapped: list, *, engine: str = 'local', workers: int = 1, address: str | None = None,
        params_file: str | None = None, cfg: ChangeConfig = ChangeConfig(),
        progress: bool = True) -> list[BagResult]:
    """Every bag through :func:`process_bag` on ``engine``; results in the order of ``bags``."""
    if engine not in ENGINES:
        raise ValueError(f"engine: unknown '{engine}' ({' | '.join(ENGINES)})")
    if int(workers) < 1:
        raise ValueError(f'workers must be >= 1 (got {workers})')
    if engine == 'ray':
        return _run_ray(bags, mapped, params_file, cfg, int(workers), progress, address)
    return _run_local(bags, mapped, params_file, cfg, int(workers), progress)
