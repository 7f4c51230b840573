#!/usr/bin/env python3
"""Must-reach tables of issue 17 (map-change detection), on the Table I or the SUMO family.

kinds   per map edit (arm removed, lane added, lane removed, lane moved 1 m, connector
        removed) and the unchanged map, over --n cases (seeds --seed..--seed+n-1, tracked
        objects, one estimate per case, full sample budget): recall = the expected change at
        the edited element; false = share of cases with any other change claimed;
        ``observable``: the cases whose edited element carried traffic in the world (a lane
        no vehicle drove cannot be shown added or moved; the SUMO family has many), recall
        over those as ``recall_observable``. Beside them one *world* edit, ``arm_closed``
        (``edits.world_without_arm``): the vehicles of one arm taken out of the world and
        the case estimated anew, against the unchanged map; the change to find is
        ``arm_removed`` (no map edit of the issue asks for it).
fusion  --fusion-n cases (seeds --fusion-seed..), 10 short drives each (a --share of the vehicles, own noise):
        recall / false-change rate of the fused result from the first 1, 3 and 10 drives,
        edits cycling through the kinds; false changes also against the unchanged map
        (``connector_unused`` counted apart in both, as in the kinds table; columns
        ``*_incl_unused`` with it).
scale   --bags simulated bags through ``fleet`` with ``--engine local --workers 1`` and
        ``--engine ray --workers 2`` side by side (small replay budget), speed-up and Ray's
        overhead per bag; skipped with --bags 0.

--family sumo takes the cases from ``scenarios.sumo.sumo_scenario(seed)`` (a FamilyScenario:
the same ``gt``, ``gt_lanelets``, ``traffic``, ``tracks``, ``detections`` the edits and the
drive variants use; ~1-4 s of SUMO per case, kept in --cache as well).

Usage: .venv/bin/python scripts/fleet_bench.py --n 50 --fusion-n 10 --bags 0 --json fleet_bench.json
       .venv/bin/python scripts/fleet_bench.py --family sumo --n 200 --fusion-n 0 --cache /tmp/fc --json s.json
"""

from __future__ import annotations

import argparse
from dataclasses import asdict
import json
import math
from pathlib import Path
import shutil
import sys
import tempfile
import time

import numpy as np

from intersection_estimator.export.osm import write_osm
from intersection_estimator.fleet.changes import ChangeConfig, compare
from intersection_estimator.fleet.corroborate import drive_traffic
from intersection_estimator.fleet.edits import (EDITS, EXPECTED, WORLD_EDITS, apply_edit, arm_lane_points, drive_variant,
                                                world_without_arm)
from intersection_estimator.fleet.fuse import fuse
from intersection_estimator.fleet.prior_map import load_prior_map
from intersection_estimator.pipeline import estimate
from intersection_estimator.scenarios.sumo_gt import snap_connectors
from intersection_estimator.sim import simulate_scenario

FAST = {'timer_period': 1.0, 'topology_samples': 1500, 'lane_samples': 3000}
CACHE: Path | None = None     # --cache: estimates kept between runs (they do not depend on the map)
FAMILY = 'table1'             # --family
WORLD = True                  # --no-world: skip the world edits (each estimates its case anew)
CFG = ChangeConfig()


def _scenario(seed: int):
    """Case ``seed`` of the --family (SUMO cases pickled into --cache: SUMO costs seconds)."""
    import pickle
    if FAMILY == 'table1':
        return simulate_scenario(seed)
    if FAMILY == 'av2':              # the real recordings: case = scenario index (0..2)
        from intersection_estimator.realdata.av2 import find_scenarios, load_av2
        from intersection_estimator.scenarios.sumo_net import realdata_dir
        sc = load_av2(find_scenarios(realdata_dir() / 'av2')[seed])
        snap_connectors(sc.gt_lanelets)
        return sc
    from intersection_estimator.scenarios.sumo import sumo_scenario
    f = None if CACHE is None else CACHE / f'sumo_scenario_{seed}.pkl'
    if f is not None and f.exists():
        sc = pickle.loads(f.read_bytes())
    else:
        sc = sumo_scenario(seed)
        if f is not None:
            f.write_bytes(pickle.dumps(sc))
    snap_connectors(sc.gt_lanelets)
    return sc


def _estimate(sc, seed: int):
    import pickle
    prefix = '' if FAMILY == 'table1' else f'{FAMILY}_'
    f = None if CACHE is None else CACHE / f'{prefix}{sc.seed}_{len(sc.tracks)}_{seed}.pkl'
    if f is not None and f.exists():
        return pickle.loads(f.read_bytes())
    r = estimate(sc.detections('tracked'), seed=seed)
    if f is not None:
        f.write_bytes(pickle.dumps(r))
    return r


def _prior(lls, tmp: Path):
    (X,) = load_prior_map(write_osm(tmp / 'prior.osm', lls))
    return X


def _names(X) -> dict:
    names = {l.id: l.name for a in X.arms for l in a.lanes_in + a.lanes_out}
    names.update({c.id: c.name for c in X.connectors})
    return names


def _hit(edit, what, f, X, sc) -> bool:
    """Is finding ``f`` the change the edit ``what`` made (the right element)?"""
    if f.kind != EXPECTED[edit]:
        return False
    names = _names(X)
    lanes = [names.get(i, '') for i in f.map_lanes]
    if edit == 'arm_removed':
        gt = sc.gt.arms[what['arm']].angle
        return abs(math.remainder(math.radians(f.evidence['angle_deg']) - gt, 2 * math.pi)) < math.radians(30)
    if edit == 'lane_added':
        return len(lanes) == 1 and lanes[0].endswith('_extra')
    if edit == 'lane_removed':
        d = 'in' if what['kind'] == 'entering' else 'out'
        arm_names = {l.name.split('_')[0] for l in X.arms[f.map_arm].lanes_in + X.arms[f.map_arm].lanes_out}
        return f.direction == d and arm_names == {f"a{what['arm']}"}
    if edit == 'lane_moved':
        return lanes == [what['lane']]
    src, dst = what['connector'][2:].split('_')
    return lanes == [f'{src[:2]}_in{src[3:]}', f'{dst[:2]}_out{dst[3:]}']


def _observable(edit, what, sc) -> bool:
    """Did the world's traffic use the element the edit is about (can the data show it)?"""
    t = sc.traffic
    if edit == 'none':
        return True
    if edit == 'arm_removed':
        return any(t.get(l.id, 0) > 0 for l in sc.gt_lanelets if what['arm'] in (l.arm, l.arm_to))
    if edit == 'lane_added':          # the map's extra lane: its arm direction must carry traffic
        return any(t.get(l.id, 0) > 0 for l in sc.gt_lanelets if l.arm == what['arm'] and l.kind == what['kind'])
    if edit in ('lane_removed', 'lane_moved'):
        return t.get(what['lane'], 0) > 0
    return t.get(what['connector'], 0) > 0


def _maps(seed: int, sc, tmp: Path) -> dict:
    """edit -> (what, prior map) of case ``seed`` ('none': the unchanged map); kept in --cache
    (written with our Lanelet2 export and loaded back, ~0.4 s each; independent of the rules)."""
    import pickle
    f = None if CACHE is None else CACHE / f'{FAMILY}_maps_{seed}.pkl'
    if f is not None and f.exists():
        return pickle.loads(f.read_bytes())
    out = {'none': (None, _prior(sc.gt_lanelets, tmp))}
    for edit in EDITS:
        lls, what = apply_edit(sc, edit, np.random.default_rng(seed))
        out[edit] = (what, None if lls is None else _prior(lls, tmp))
    if f is not None:
        f.write_bytes(pickle.dumps(out))
    return out


def _case_rows(seed: int, tmp: Path) -> list[dict]:
    sc = _scenario(seed)
    r = _estimate(sc, seed)
    if r.intersection is None:
        return [{'seed': seed, 'edit': e, 'applicable': True, 'observable': True, 'hit': False, 'false': False,
                 'false_incl_unused': False, 'claimed': []} for e in ('none',) + EDITS + (tuple(WORLD_EDITS) if WORLD else ())]
    rows = []
    maps = _maps(seed, sc, tmp)
    dets = sc.detections('tracked')
    view = compare(r.intersection, r.lanelets, maps['none'][1], CFG, drive_traffic(dets, maps['none'][1], CFG))
    rows.append({'seed': seed, 'edit': 'none', 'applicable': True, 'observable': True,
                 **_scored(view.findings, lambda f: False), 'hit': not view.findings})
    for edit in EDITS:
        what, X = maps[edit]
        if X is None:
            rows.append({'seed': seed, 'edit': edit, 'applicable': False})
            continue
        fs = compare(r.intersection, r.lanelets, X, CFG, drive_traffic(dets, X, CFG)).findings
        rows.append({'seed': seed, 'edit': edit, 'applicable': True, 'observable': _observable(edit, what, sc),
                     'what': what, **_scored(fs, lambda f: _hit(edit, what, f, X, sc),
                                             _part_of(edit, what, X, sc))})
    if WORLD:
        rows.append(_closed_arm_row(seed, sc, maps['none'][1]))
    return rows


def _mapped_arm_of(sc, arm: int, X) -> int:
    """The mapped arm whose lanes lie on the ground truth's arm ``arm`` (median distance)."""
    from scipy.spatial import cKDTree
    from intersection_estimator.evaluate import resample
    tree = cKDTree(arm_lane_points(sc.gt_lanelets, arm))
    return int(np.argmin([np.median(tree.query(np.concatenate([resample(np.asarray(l.center, float))
                                                               for l in a.lanes_in + a.lanes_out]))[0])
                          for a in X.arms]))


def _closed_arm_row(seed: int, sc, X) -> dict:
    """World edit ``arm_closed`` (``WORLD_EDITS``): the vehicles of one arm gone, the map the
    unchanged ground truth, estimated anew; hit = ``arm_removed`` of the mapped arm on it."""
    world, what = world_without_arm(sc, np.random.default_rng(seed))
    if world is None:
        return {'seed': seed, 'edit': 'arm_closed', 'applicable': False}
    r = _estimate(world, seed)
    m = _mapped_arm_of(sc, what['arm'], X)
    fs = [] if r.intersection is None else compare(
        r.intersection, r.lanelets, X, CFG, drive_traffic(world.detections('tracked'), X, CFG)).findings
    return {'seed': seed, 'edit': 'arm_closed', 'applicable': True, 'observable': True, 'what': what,
            **_scored(fs, lambda f: f.kind == 'arm_removed' and f.map_arm == m)}


def _scored(fs, is_hit, is_part=lambda f: False) -> dict:
    """A row's flags from its findings ``fs``: hit (one finding is the applied edit),
    false (any other finding but an unused connector or one that is part of the edit,
    ``is_part``), and every claim with its confidence and whether it is the edit (for
    :func:`_operating_points`)."""
    hits = [f for f in fs if is_hit(f)]
    others = [f for f in fs if f not in hits[:1] and not is_part(f)]
    return {'hit': bool(hits), 'false': any(f.kind != 'connector_unused' for f in others),
            'false_incl_unused': bool(others), 'claimed': [f.key for f in fs],
            'claims': [{'key': f.key, 'kind': f.kind, 'confidence': round(float(f.confidence), 4),
                        'hit': f in hits, 'part': bool(is_part(f))} for f in fs]}


def _part_of(edit, what, X, sc):
    """Findings that are part of the edit: with an arm gone from the map, a lane its turns
    needed on another arm is gone too (``edits._arm_removed``), and showing it is right."""
    if edit != 'arm_removed' or not what.get('lanes'):
        return lambda f: False
    gone = {(_mapped_arm_of(sc, arm, X), 'in' if kind == 'entering' else 'out') for arm, kind in what['lanes']}
    return lambda f: f.kind == 'lane_added' and (f.map_arm, f.direction) in gone


#: reporting thresholds of the operating-point table (ChangeConfig.min_confidence is the first)
TAUS = (0.5, 0.6, 0.7, 0.8, 0.9, 0.95)


def _operating_points(rows: list[dict]) -> list[dict]:
    """Per edit and reporting threshold ``tau``: recall and false rate when only findings
    of confidence >= tau are reported (the same rows; what a user gets from raising
    ``min_confidence``)."""
    out = []
    for edit in ('none',) + EDITS + (tuple(WORLD_EDITS) if WORLD else ()):
        rs = [r for r in rows if r['edit'] == edit and r['applicable'] and 'claims' in r]
        row = {'edit': edit}
        for tau in TAUS:
            rec = fal = 0
            for r in rs:
                kept = [c for c in r['claims'] if c['confidence'] >= tau]
                hits = [c for c in kept if c['hit']]
                others = [c for c in kept if c is not (hits[0] if hits else None) and not c.get('part')]
                rec += (not kept) if edit == 'none' else bool(hits)
                fal += any(c['kind'] != 'connector_unused' for c in others)
            n = max(len(rs), 1)
            row[f'{tau:g}'] = f'{100 * rec / n:.1f} / {100 * fal / n:.1f}'
        out.append(row)
    return out


def _kind_table(rows: list[dict]) -> list[dict]:
    out = []
    for edit in ('none',) + EDITS + (tuple(WORLD_EDITS) if WORLD else ()):
        rs = [r for r in rows if r['edit'] == edit and r['applicable']]
        n = len(rs)
        obs = [r for r in rs if r['observable']]
        out.append({'edit': edit, 'expected': {**EXPECTED, **WORLD_EDITS}.get(edit, '(no change)'), 'cases': n,
                    'not_applicable': sum(1 for r in rows if r['edit'] == edit and not r['applicable']),
                    'recall': sum(r['hit'] for r in rs) / max(n, 1),
                    'observable': len(obs), 'recall_observable': sum(r['hit'] for r in obs) / max(len(obs), 1),
                    'false_rate': sum(r['false'] for r in rs) / max(n, 1),
                    'false_rate_incl_unused': sum(r['false_incl_unused'] for r in rs) / max(n, 1)})
    return out


def _fusion_case(seed: int, edit: str, drives: int, share: float, tmp: Path):
    sc = _scenario(seed)
    lls, what = apply_edit(sc, edit, np.random.default_rng(seed))
    if lls is None:
        return None
    X, X0 = _prior(lls, tmp), _prior(sc.gt_lanelets, tmp)
    views, views0 = [], []
    for d in range(1, drives + 1):
        drive = drive_variant(sc, d, share)
        r = _estimate(drive, seed * 100 + d)
        if r.intersection is not None:
            dets = drive.detections('tracked')
            views.append((f'd{d:02d}', compare(r.intersection, r.lanelets, X, CFG, drive_traffic(dets, X, CFG))))
            views0.append((f'd{d:02d}', compare(r.intersection, r.lanelets, X0, CFG, drive_traffic(dets, X0, CFG))))
    return sc, X, X0, what, views, views0


FUSION_ROWS: list = []       # per case and k: what the fused result claimed (JSON 'fusion_rows')


def _fusion_table(seeds, share: float, tmp: Path) -> list[dict]:
    res = {k: {'hit': 0, 'false': 0, 'false_strict': 0, 'false0': 0, 'false0_strict': 0, 'n': 0} for k in (1, 3, 10)}
    for i, seed in enumerate(seeds):
        edit = EDITS[i % len(EDITS)]
        case = _fusion_case(seed, edit, 10, share, tmp)
        if case is None:
            continue
        sc, X, X0, what, views, views0 = case
        for k in res:
            fx = fuse(views[:k], CFG).get(X.id)
            f0 = fuse(views0[:k], CFG).get(X0.id)
            ch = [] if fx is None else fx.changes
            hits = [c for c in ch if _hit(edit, what, c, X, sc)]
            res[k]['n'] += 1
            res[k]['hit'] += bool(hits)
            part = _part_of(edit, what, X, sc)
            others = [c for c in ch if c not in hits[:1] and not part(c)]
            # as in the kinds table: 'connector_unused' counted apart (true of the data)
            res[k]['false'] += any(c.kind != 'connector_unused' for c in others)
            res[k]['false_strict'] += bool(others)
            ch0 = [] if f0 is None else f0.changes
            res[k]['false0_strict'] += bool(ch0)
            # 'connector_unused' is the weaker report (no vehicle took a mapped turn),
            # true of the simulated traffic, which does not drive every connector
            res[k]['false0'] += any(c.kind != 'connector_unused' for c in ch0)
            FUSION_ROWS.append({'seed': seed, 'edit': edit, 'what': what, 'drives': k, 'views': len(views[:k]),
                                'hit': bool(hits), 'claimed': [(c.key, round(c.confidence, 3)) for c in ch],
                                'claimed_unchanged': [(c.key, round(c.confidence, 3)) for c in ch0],
                                'per_drive': [[(f.key, round(f.confidence, 3)) for f in v.findings]
                                              for _, v in views[:k]] if k == 10 else None,
                                'per_drive_unchanged': [[(f.key, round(f.confidence, 3)) for f in v.findings]
                                                        for _, v in views0[:k]] if k == 10 else None})
        print(f'fusion case {seed} ({edit}) done', file=sys.stderr)
    return [{'drives': k, 'cases': v['n'], 'recall': v['hit'] / max(v['n'], 1),
             'false_rate_changed_map': v['false'] / max(v['n'], 1),
             'false_rate_changed_incl_unused': v['false_strict'] / max(v['n'], 1),
             'false_rate_unchanged_map': v['false0'] / max(v['n'], 1),
             'false_rate_unchanged_incl_unused': v['false0_strict'] / max(v['n'], 1)} for k, v in res.items()]


def _scale(n_bags: int, tmp: Path, budget: str = 'fast') -> dict:
    """``n_bags`` drives of seed 5's intersection, local x1 vs Ray x2 in one run; ``budget``
    'fast' (:data:`FAST`, ~0.5-3 s per bag) or 'node' (the node's default per-tick budget, as a
    fleet would replay: ~5-10 s per bag)."""
    from intersection_estimator.bagio import write_scenario_bag
    from intersection_estimator.fleet.cli import run_fleet
    sc = simulate_scenario(5)
    bags = tmp / 'bags'
    for d in range(1, n_bags + 1):
        write_scenario_bag(drive_variant(sc, d, 0.8), bags / f'drive{d:03d}', sensors=('tracked',), autoware=False)
    write_osm(tmp / 'map.osm', sc.gt_lanelets)
    params = tmp / 'params.yaml'
    params.write_text('intersection_estimator:\n  ros__parameters:\n'
                      + ''.join(f'    {k}: {v}\n' for k, v in (FAST if budget == 'fast' else {'seed': 0}).items()))
    wall, ok = {}, {}
    for engine, workers in (('local', 1), ('ray', 2)):
        t0 = time.perf_counter()
        doc = run_fleet([str(bags)], tmp / 'map.osm', tmp / engine, engine=engine, workers=workers,
                        params_file=str(params), progress=False)
        wall[engine] = time.perf_counter() - t0
        ok[engine] = sum(b['status'] == 'ok' for b in doc['bags'])
    same = (tmp / 'local' / 'changes.json').read_bytes() == (tmp / 'ray' / 'changes.json').read_bytes()
    per_bag = wall['local'] / n_bags
    return {'bags': n_bags, 'budget': budget, 'ok_bags': ok, 'local_workers1_s': wall['local'], 'ray_workers2_s': wall['ray'],
            'speedup': wall['local'] / wall['ray'], 'identical_changes_json': same,
            # Ray's cost beyond a perfect 2-way split of the local per-bag time
            'ray_overhead_per_bag_s': (wall['ray'] - wall['local'] / 2) / n_bags, 'local_per_bag_s': per_bag}


def _md(rows: list[dict], cols: list[str]) -> str:
    def fmt(v):
        return f'{100 * v:.1f} %' if isinstance(v, float) and v <= 1.0 else (f'{v:.2f}' if isinstance(v, float) else str(v))
    return '\n'.join(['| ' + ' | '.join(cols) + ' |', '|' + '---|' * len(cols)]
                     + ['| ' + ' | '.join(fmt(r[c]) for c in cols) + ' |' for r in rows])


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument('--family', choices=('table1', 'sumo', 'av2'), default='table1',
                    help='scenario family (av2: the three real scenarios, --seed 0 --n 3)')
    ap.add_argument('--n', type=int, default=50, help='cases per change kind (0 = skip the kinds table)')
    ap.add_argument('--seed', type=int, default=0, help='first case seed of the kinds table')
    ap.add_argument('--fusion-n', type=int, default=10, help='cases for the fusion table (10 drives each; 0 = skip)')
    ap.add_argument('--fusion-seed', type=int, default=1000, help='first case seed of the fusion table')
    ap.add_argument('--share', type=float, default=0.3, help='share of the vehicles one short drive sees')
    ap.add_argument('--bags', type=int, default=0, help='bags for the local-vs-Ray speed-up (0 = skip)')
    ap.add_argument('--bag-budget', choices=('fast', 'node'), default='fast',
                    help="replay budget of the --bags runs: 'fast' (small), 'node' (the node's defaults)")
    ap.add_argument('--set', action='append', default=[], metavar='FIELD=VALUE',
                    help='ChangeConfig field for this run (e.g. change_prior=0.05); default: the package defaults')
    ap.add_argument('--json', default=None, help='write all figures here')
    ap.add_argument('--cache', default=None, help='keep estimates here between runs (map-independent)')
    ap.add_argument('--no-world', action='store_true',
                    help='map edits only: skip the world edits (arm_closed), which estimate each case anew')
    args = ap.parse_args()
    global CACHE, FAMILY, CFG, WORLD
    FAMILY = args.family
    WORLD = not args.no_world
    from dataclasses import replace
    CFG = replace(CFG, **{k: float(v) for k, v in (a.split('=', 1) for a in args.set)})
    CFG.validate()
    if args.cache:
        CACHE = Path(args.cache)
        CACHE.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix='fleet_bench_'))
    out: dict = {'family': args.family, 'n': args.n, 'seed': args.seed, 'fusion_n': args.fusion_n,
                 'fusion_seed': args.fusion_seed, 'share': args.share, 'change_config': asdict(CFG)}
    try:
        t0 = time.perf_counter()
        rows = []
        for s in range(args.seed, args.seed + args.n):
            rows += _case_rows(s, tmp)
            if FAMILY != 'table1':
                print(f'case {s} done', file=sys.stderr, flush=True)
        if rows:
            out['kinds'] = _kind_table(rows)
            out['kinds_failures'] = [r for r in rows if r['applicable'] and (not r['hit'] or r['false_incl_unused'])]
            out['kinds_rows'] = rows
            print(_md(out['kinds'], ['edit', 'expected', 'cases', 'not_applicable', 'recall', 'observable',
                                     'recall_observable', 'false_rate', 'false_rate_incl_unused']))
            out['operating_points'] = _operating_points(rows)
            print('recall / false [%] when only findings of confidence >= tau are reported:')
            print(_md(out['operating_points'], ['edit'] + [f'{t:g}' for t in TAUS]))
            print(f'({time.perf_counter() - t0:.0f} s)')
        if args.fusion_n:
            out['fusion'] = _fusion_table(range(args.fusion_seed, args.fusion_seed + args.fusion_n), args.share, tmp)
            out['fusion_rows'] = FUSION_ROWS
            print(_md(out['fusion'], ['drives', 'cases', 'recall', 'false_rate_changed_map', 'false_rate_changed_incl_unused',
                                      'false_rate_unchanged_map', 'false_rate_unchanged_incl_unused']))
        if args.bags:
            out['scale'] = _scale(args.bags, tmp / 'scale', args.bag_budget)
            print(json.dumps(out['scale'], indent=1))
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=1) + '\n')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
