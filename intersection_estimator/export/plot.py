"""PNG plot of an estimate: observations underneath, arms, lanelets coloured by kind, the ego.

Colours come from :mod:`intersection_estimator.palette` (entering green, leaving blue,
connector orange: the same as the RViz markers). The title says what the picture is: the
fixed frame, the estimator state, the data time it estimates and the sample counts (see
:func:`plot_title`).
"""

from __future__ import annotations

from datetime import datetime, timezone
import math

import matplotlib

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from ..palette import KIND_RGBA, PNG_NEUTRAL, RGBA, kind_rgba, rgb_hex  # noqa: E402

__all__ = ['plot_estimate', 'estimate_figure', 'plot_title', 'KIND_COLOURS']

#: matplotlib colour per lanelet kind (from the shared palette)
KIND_COLOURS = {k: rgb_hex(v) for k, v in KIND_RGBA.items()}
_EPOCH_MIN = 1e8   # stamps above this are wall-clock epoch seconds (~1973 on), else a bag's own base


def _extent(intersection, lanelets, dets, ego=None):
    pts = [np.asarray(intersection.center, float).reshape(1, 2)] if intersection is not None else []
    pts += [l.center for l in lanelets if len(l.center)]
    if not pts and dets is not None and len(dets):
        pts.append(dets.xy)
    if ego is not None:
        pts.append(np.asarray(ego, float)[:2].reshape(1, 2))
    if not pts:
        return None
    P = np.concatenate(pts)
    lo, hi = P.min(0) - 10.0, P.max(0) + 10.0
    return lo, hi


def _stamp_text(stamp: float) -> str:
    if stamp >= _EPOCH_MIN:
        utc = datetime.fromtimestamp(stamp, tz=timezone.utc)
        return f"t {utc.strftime('%Y-%m-%d %H:%M:%S.%f')[:-3]} UTC ({stamp:.3f} s)"
    return f't {stamp:.3f} s'


def plot_title(frame=None, state=None, stamp=None, topology_samples=None, lane_samples=None,
               observations=None, intersection=None, lanelets=()) -> str:
    """Title lines: what was estimated, then frame, state and data time, then the sample
    counts (lines short enough for the figure's width).

    Parts that are not known (``None``) are left out; the first line is always there.
    """
    what = 'no intersection' if intersection is None else f'{len(intersection.arms)} arms'
    head = f'intersection estimate: {what}, {len(lanelets)} lanelets'
    if observations is not None:
        head += f', {int(observations)} observations'
    where, samples = [], []
    if frame:
        where.append(f'frame {frame}')
    if state:
        where.append(f'state {state}')
    if stamp is not None and math.isfinite(float(stamp)):
        where.append(_stamp_text(float(stamp)))
    if topology_samples is not None:
        samples.append(f'{int(topology_samples)} topology samples')
    if lane_samples is not None:
        samples.append(f'{int(lane_samples)} lane samples')
    return '\n'.join([head] + [', '.join(p) for p in (where, samples) if p])


def _draw_observations(ax, dets):
    if dets is None or not len(dets):
        return
    tracked = dets.track_id >= 0
    ax.scatter(dets.xy[~tracked, 0], dets.xy[~tracked, 1], s=3, c=[PNG_NEUTRAL['detections']], lw=0,
               label='detections', zorder=1)
    if tracked.any():
        ax.scatter(dets.xy[tracked, 0], dets.xy[tracked, 1], s=3, c=[PNG_NEUTRAL['tracked']], lw=0,
                   label='tracked', zorder=1)


def _draw_topology(ax, intersection, arm_length):
    if intersection is None:
        return
    c = np.asarray(intersection.center, float)
    ax.plot(*c, '+', color=RGBA['center'][:3], ms=12, mew=2, zorder=5, gid='center')
    for i, a in enumerate(intersection.arms):
        e = c + arm_length * np.array([math.cos(a.angle), math.sin(a.angle)])
        ax.plot([c[0], e[0]], [c[1], e[1]], color=PNG_NEUTRAL['arm'], ls='-.', lw=0.8, zorder=2)
        ax.annotate(f'{i}', e, fontsize=9)


def _draw_lanelets(ax, lanelets):
    seen = set()
    for l in lanelets:
        col = kind_rgba(l.kind)[:3]
        for b in (l.left, l.right):
            if len(b):
                ax.plot(b[:, 0], b[:, 1], color=col, lw=0.6, alpha=0.6, zorder=3)
        if not len(l.center):
            continue
        ax.plot(l.center[:, 0], l.center[:, 1], color=col, lw=1.6, zorder=4,
                label=l.kind if l.kind not in seen else None, gid=f'center:{l.kind}')
        seen.add(l.kind)
        if len(l.center) >= 2:
            m = len(l.center) // 2
            p, q = l.center[m - 1], l.center[m]
            ax.annotate('', q, p, arrowprops=dict(arrowstyle='->', color=col), zorder=4)


def _draw_ego(ax, ego):
    """The ego at (x, y[, yaw]): a dot, and an arrow along its heading when the yaw is known."""
    if ego is None:
        return
    e = np.asarray(ego, float).ravel()
    col = RGBA['ego'][:3]
    ax.plot(e[0], e[1], 'o', color=col, ms=8, zorder=6, label='ego', gid='ego')
    if len(e) >= 3 and math.isfinite(e[2]):
        d = 6.0 * np.array([math.cos(e[2]), math.sin(e[2])])
        ax.annotate('', e[:2] + d, e[:2], arrowprops=dict(arrowstyle='-|>', color=col, lw=1.5),
                    zorder=6)


def estimate_figure(intersection, lanelets, dets=None, gt_lanelets=None, title=None,
                    arm_length: float = 60.0, view_radius: float | None = None, *, ego=None,
                    frame=None, state=None, stamp=None, topology_samples=None, lane_samples=None,
                    result=None):
    """The matplotlib Figure :func:`plot_estimate` saves (close it with ``plt.close(fig)``).

    ``ego``: (x, y) or (x, y, yaw) in the fixed frame, drawn when given. ``result`` (a
    :class:`~intersection_estimator.pipeline.EstimateResult`) gives ``state`` and the sample
    counts where they are not passed. ``title`` (optional) is put above the
    :func:`plot_title` lines made of the other keywords.
    """
    if result is not None:
        state = state or result.state
        topology_samples = result.topology_samples if topology_samples is None else topology_samples
        lane_samples = result.lane_samples if lane_samples is None else lane_samples
    fig, ax = plt.subplots(figsize=(8, 8), dpi=110)
    _draw_observations(ax, dets)
    _draw_topology(ax, intersection, arm_length)
    _draw_lanelets(ax, lanelets)
    for i, l in enumerate(gt_lanelets or []):
        ax.plot(l.center[:, 0], l.center[:, 1], '--', color=PNG_NEUTRAL['ground_truth'], lw=0.9,
                zorder=4, label='ground truth' if i == 0 else None)
    _draw_ego(ax, ego)
    ext = _extent(intersection, lanelets, dets, ego)
    if view_radius is not None and intersection is not None:
        c = np.asarray(intersection.center, float)
        ext = (c - view_radius, c + view_radius)
    if ext is not None:
        ax.set_xlim(ext[0][0], ext[1][0])
        ax.set_ylim(ext[0][1], ext[1][1])
    ax.set_aspect('equal')
    ax.set_xlabel(f'x [m] ({frame})' if frame else 'x [m]')
    ax.set_ylabel(f'y [m] ({frame})' if frame else 'y [m]')
    auto = plot_title(frame, state, stamp, topology_samples, lane_samples,
                      None if dets is None else len(dets), intersection, lanelets)
    ax.set_title(f'{title}\n{auto}' if title else auto, fontsize=9)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(loc='upper right', fontsize=8)
    fig.tight_layout()
    return fig


def plot_estimate(path, intersection, lanelets, dets=None, gt_lanelets=None, title=None,
                  arm_length: float = 60.0, view_radius: float | None = None, **info):
    """Write a PNG of the estimate to ``path``; returns ``path``.

    Tracked detections are drawn as darker grey dots than untracked ones; the
    topology's arms as dash-dotted rays from the center; lanelets with their borders
    (thin) and center lines coloured by kind; ground truth center lines dashed black;
    the ego when ``ego=`` is given. ``info`` keywords (``ego``, ``frame``, ``state``,
    ``stamp``, ``topology_samples``, ``lane_samples``): see :func:`estimate_figure`.
    """
    fig = estimate_figure(intersection, lanelets, dets, gt_lanelets, title, arm_length, view_radius,
                          **info)
    fig.savefig(path)
    plt.close(fig)
    return path
