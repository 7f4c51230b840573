"""PNG plot of an estimate: observations underneath, arms, lanelets coloured by kind."""

from __future__ import annotations

import math

import matplotlib

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

__all__ = ['plot_estimate', 'KIND_COLOURS']

KIND_COLOURS = {'entering': 'tab:blue', 'leaving': 'tab:green', 'connector': 'tab:orange'}


def _extent(intersection, lanelets, dets):
    pts = [np.asarray(intersection.center, float).reshape(1, 2)] if intersection is not None else []
    pts += [l.center for l in lanelets if len(l.center)]
    if not pts and dets is not None and len(dets):
        pts.append(dets.xy)
    if not pts:
        return None
    P = np.concatenate(pts)
    lo, hi = P.min(0) - 10.0, P.max(0) + 10.0
    return lo, hi


def plot_estimate(path, intersection, lanelets, dets=None, gt_lanelets=None, title=None,
                  arm_length: float = 60.0, view_radius: float | None = None):
    """Write a PNG of the estimate to ``path``; returns ``path``.

    Tracked detections are drawn per track (thin grey lines), others as dots; the
    topology's arms as dash-dotted rays from the center; lanelets with their borders
    (thin) and center lines coloured by kind; ground truth center lines dashed black.
    """
    fig, ax = plt.subplots(figsize=(8, 8), dpi=110)
    if dets is not None and len(dets):
        tracked = dets.track_id >= 0
        ax.scatter(dets.xy[~tracked, 0], dets.xy[~tracked, 1], s=3, c='0.75', lw=0,
                   label='detections', zorder=1)
        if tracked.any():
            ax.scatter(dets.xy[tracked, 0], dets.xy[tracked, 1], s=3, c='0.55', lw=0,
                       label='tracked', zorder=1)
    if intersection is not None:
        c = np.asarray(intersection.center, float)
        ax.plot(*c, 'k+', ms=12, mew=2, zorder=5)
        for i, a in enumerate(intersection.arms):
            e = c + arm_length * np.array([math.cos(a.angle), math.sin(a.angle)])
            ax.plot([c[0], e[0]], [c[1], e[1]], color='k', ls='-.', lw=0.8, zorder=2)
            ax.annotate(f'{i}', e, fontsize=9)
    seen = set()
    for l in lanelets:
        col = KIND_COLOURS.get(l.kind, 'tab:purple')
        for b in (l.left, l.right):
            if len(b):
                ax.plot(b[:, 0], b[:, 1], color=col, lw=0.6, alpha=0.6, zorder=3)
        if len(l.center):
            ax.plot(l.center[:, 0], l.center[:, 1], color=col, lw=1.6, zorder=4,
                    label=l.kind if l.kind not in seen else None)
            seen.add(l.kind)
            if len(l.center) >= 2:
                m = len(l.center) // 2
                p, q = l.center[m - 1], l.center[m]
                ax.annotate('', q, p, arrowprops=dict(arrowstyle='->', color=col), zorder=4)
    for i, l in enumerate(gt_lanelets or []):
        ax.plot(l.center[:, 0], l.center[:, 1], 'k--', lw=0.9, zorder=4,
                label='ground truth' if i == 0 else None)
    ext = _extent(intersection, lanelets, dets)
    if view_radius is not None and intersection is not None:
        c = np.asarray(intersection.center, float)
        ext = (c - view_radius, c + view_radius)
    if ext is not None:
        ax.set_xlim(ext[0][0], ext[1][0])
        ax.set_ylim(ext[0][1], ext[1][1])
    ax.set_aspect('equal')
    ax.set_xlabel('x [m]')
    ax.set_ylabel('y [m]')
    if title:
        ax.set_title(title)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(loc='upper right', fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path
