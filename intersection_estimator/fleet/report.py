"""``changes.json``, one PNG per changed intersection and the summary table (issue 17).

``changes.json`` (schema ``intersection_estimator/map_changes/1``, README "Fleet")::

    {"schema": "intersection_estimator/map_changes/1",
     "map": "MAP.osm", "config": {...ChangeConfig...},
     "bags": [{"bag": "name", "id": "sha256[:16]", "status": "ok|damaged|failed",
               "reason": "", "intersections": ["X12"], "unmatched": 0}],
     "intersections": [{"id": "X12", "center": [x, y], "drives": ["id", ...],
                        "passages": 0.0, "unobserved_arms": [2],
                        "changes": [{"kind": "lane_moved", "key": "...", "confidence": 0.97,
                                     "map_arm": 1, "direction": "in|out|", "map_lanes": ["931"],
                                     "evidence": {"drives_showing": 1, "drives_contradicting": 0,
                                                  "drives_not_seeing": 0, "passages": 8.1,
                                                  "log_odds": 3.4, "showing": ["id"],
                                                  "absence_kept": 0.4, ...}}],
                        "outvoted": [... same fields: shown by a drive, below min_confidence ...]}],
     "summary": {"bags": 3, "failed": 1, "intersections_seen": 1, "changed": 1,
                 "changes": {"lane_moved": 1}}}

``absence_kept`` (absences fused from several drives under one shared share of the element
whose drivers keep to their lanes, :func:`.fuse.shared_share`; absent when all is kept).

Floats are rounded to 6 digits and keys sorted, so equal results are equal bytes. No
machine paths: bags and the map by name.
"""

from __future__ import annotations

from dataclasses import asdict
import json
import math
from pathlib import Path

import numpy as np

from .changes import KINDS
from .prior_map import lane_centers

__all__ = ['SCHEMA', 'changes_doc', 'write_changes', 'plot_changes', 'summary_lines']

SCHEMA = 'intersection_estimator/map_changes/1'


def _clean(x):
    if isinstance(x, float):
        return round(x, 6) if math.isfinite(x) else None
    if isinstance(x, dict):
        return {str(k): _clean(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_clean(v) for v in x]
    if isinstance(x, np.generic):
        return _clean(x.item())
    return x


def _change(c) -> dict:
    return {'kind': c.kind, 'key': c.key, 'confidence': c.confidence, 'map_arm': c.map_arm,
            'direction': c.direction, 'map_lanes': list(c.map_lanes), 'evidence': dict(c.evidence)}


def changes_doc(fused: dict, results: list, mapped: list, map_name: str, cfg) -> dict:
    """The ``changes.json`` document (module docstring)."""
    centers = {m.id: [float(v) for v in m.center] for m in mapped}
    inters = [{'id': f.id, 'center': centers[f.id], 'drives': f.drives, 'passages': f.passages,
               'unobserved_arms': f.unobserved, 'changes': [_change(c) for c in f.changes],
               'outvoted': [_change(c) for c in f.candidates]} for _, f in sorted(fused.items())]
    counts = {k: sum(1 for i in inters for c in i['changes'] if c['kind'] == k) for k in KINDS}
    bags = [{'bag': r.bag, 'id': r.identity, 'status': r.status, 'reason': r.reason,
             'intersections': sorted({v.intersection for v in r.views}), 'unmatched': r.unmatched}
            for r in results]
    return _clean({'schema': SCHEMA, 'map': map_name, 'config': asdict(cfg), 'bags': bags,
                   'intersections': inters,
                   'summary': {'bags': len(results), 'failed': sum(r.status == 'failed' for r in results),
                               'intersections_seen': len(inters),
                               'changed': sum(1 for i in inters if i['changes']),
                               'changes': {k: v for k, v in counts.items() if v}}})


def write_changes(path, doc: dict) -> Path:
    path = Path(path)
    path.write_text(json.dumps(doc, indent=1, sort_keys=True) + '\n')
    return path


def plot_changes(path, X, inter: dict, estimates: list) -> Path:
    """Estimates (blue) over the prior map (grey), changed map lanes red, added arms orange."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    changed = {i for c in inter['changes'] for i in c['map_lanes']}
    fig, ax = plt.subplots(figsize=(7, 7), dpi=110)
    for lid, c in lane_centers(X):
        red = lid in changed
        ax.plot(c[:, 0], c[:, 1], color='tab:red' if red else '0.6', lw=2.5 if red else 1.0, zorder=3 if red else 1)
    for _, _, lanes in estimates:
        for ln in lanes:
            ln = np.asarray(ln)
            ax.plot(ln[:, 0], ln[:, 1], color='tab:blue', lw=0.8, alpha=0.6, zorder=2)
    for c in inter['changes']:
        if c['kind'] == 'arm_added':      # an arm the map lacks: a ray from the mapped center
            a = math.radians(c['evidence']['angle_deg'])
            ax.annotate('', xy=X.center + 60 * np.array([math.cos(a), math.sin(a)]), xytext=X.center,
                        arrowprops=dict(color='tab:orange', lw=2.5, arrowstyle='->'), zorder=4)
    ax.plot([], [], color='tab:blue', label='estimates')
    ax.plot([], [], color='0.6', label='prior map')
    ax.plot([], [], color='tab:red', lw=2.5, label='changed (map lanes)')
    text = '\n'.join(f"{c['kind']} arm {c['map_arm']}{c['direction']} conf {c['confidence']:.2f} "
                     f"({c['evidence']['drives_showing']} drives)" for c in inter['changes'])
    ax.text(0.01, 0.99, text, transform=ax.transAxes, va='top', fontsize=8, family='monospace',
            bbox=dict(facecolor='white', alpha=0.8, lw=0))
    ax.set_aspect('equal')
    ax.set_title(f"intersection {inter['id']}: {len(inter['changes'])} change(s)")
    ax.legend(loc='lower right', fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return Path(path)


def summary_lines(doc: dict) -> list[str]:
    """The printed summary: bags, then one row per intersection seen."""
    s = doc['summary']
    out = [f"{s['bags']} bags, {s['failed']} failed; {s['intersections_seen']} mapped intersections seen, "
           f"{s['changed']} changed"]
    for b in doc['bags']:
        if b['status'] != 'ok':
            out.append(f"  {b['status']}: {b['bag']}: {b['reason']}")
    out.append(f"{'intersection':<14}{'drives':>7}{'passages':>10}  changes")
    for i in doc['intersections']:
        ch = ', '.join(f"{c['kind']} ({c['confidence']:.2f})" for c in i['changes']) or 'none'
        if i['unobserved_arms']:
            ch += f"; unobserved arms {i['unobserved_arms']}"
        out.append(f"{i['id']:<14}{len(i['drives']):>7}{i['passages']:>10.1f}  {ch}")
    return out
