"""PNG plot of an estimate (matplotlib Agg): title, ego, one palette with the RViz markers."""

from __future__ import annotations

import matplotlib.pyplot as plt
from matplotlib.colors import to_rgb
import numpy as np
import pytest
from test_lanes_synth import synth_case

from intersection_estimator.export.plot import estimate_figure, plot_estimate, plot_title
from intersection_estimator.lanes import lanelets_from_topology
from intersection_estimator.palette import KIND_RGBA, RGBA
from intersection_estimator.pipeline import EstimateResult


def test_plot_written(tmp_path):
    topo, _, _, dets = synth_case(0, n_arms=3, lanes=(1, 1), per_lane=1)
    ls = lanelets_from_topology(topo)
    out = plot_estimate(tmp_path / 'a.png', topo, ls, dets=dets, gt_lanelets=ls, title='x',
                        ego=(3.0, -4.0, 0.5), frame='map', state='CONVERGED', stamp=12.5)
    data = out.read_bytes()
    assert data[:8] == b'\x89PNG\r\n\x1a\n' and len(data) > 10_000


def test_plot_without_observations_or_lanes(tmp_path):
    topo, _, _, _ = synth_case(1, n_arms=3, lanes=(1, 1), per_lane=1)
    assert (plot_estimate(tmp_path / 'b.png', topo, []).stat().st_size > 1000)
    assert (plot_estimate(tmp_path / 'c.png', None, [], view_radius=10.0).stat().st_size > 1000)


def test_title_names_frame_state_time_and_samples():
    topo, _, _, dets = synth_case(0, n_arms=3, lanes=(1, 1), per_lane=1)
    ls = lanelets_from_topology(topo)
    result = EstimateResult(topo, ls, topology_samples=10000, lane_samples=20000, state='CONVERGED')
    fig = estimate_figure(topo, ls, dets, frame='map', stamp=1_700_000_000.25, result=result)
    title = fig.axes[0].get_title()
    plt.close(fig)
    assert 'frame map' in title and 'state CONVERGED' in title
    assert '2023-11-14 22:13:20.250 UTC' in title and '1700000000.250 s' in title
    assert '10000 topology samples' in title and '20000 lane samples' in title
    assert f'{len(dets)} observations' in title and '3 arms' in title
    assert max(map(len, title.splitlines())) <= 90, title     # fits the figure's width
    # a bag without wall-clock stamps: its own time base, in seconds
    assert 't 42.000 s' in plot_title(stamp=42.0)
    assert plot_title() == 'intersection estimate: no intersection, 0 lanelets'


def test_ego_drawn_with_heading_and_kept_in_view():
    topo, _, _, _ = synth_case(0, n_arms=3, lanes=(1, 1), per_lane=1)
    far = np.asarray(topo.center) + [250.0, 0.0]
    fig = estimate_figure(topo, [], ego=(far[0], far[1], np.pi / 2))
    ax = fig.axes[0]
    (ego,) = [ln for ln in ax.get_lines() if ln.get_gid() == 'ego']
    assert np.allclose(ego.get_xydata()[0], far)
    assert to_rgb(ego.get_color()) == pytest.approx(RGBA['ego'][:3])
    assert ax.get_xlim()[1] > far[0]                        # the ego is inside the view
    assert any(a.arrow_patch is not None for a in ax.texts)  # the heading arrow
    plt.close(fig)
    fig = estimate_figure(topo, [])
    assert not [ln for ln in fig.axes[0].get_lines() if ln.get_gid() == 'ego']
    plt.close(fig)


def test_png_and_markers_share_one_palette():
    from msg_adapters.markers import COLORS
    topo, _, _, _ = synth_case(0, n_arms=3, lanes=(1, 1), per_lane=1)
    ls = lanelets_from_topology(topo)
    fig = estimate_figure(topo, ls)
    drawn = {ln.get_gid().split(':')[1]: to_rgb(ln.get_color()) for ln in fig.axes[0].get_lines()
             if (ln.get_gid() or '').startswith('center:')}
    plt.close(fig)
    assert set(drawn) == {'entering', 'leaving'}
    for kind, rgb in drawn.items():
        assert rgb == pytest.approx(KIND_RGBA[kind][:3])
        assert COLORS[kind][:3] == pytest.approx(rgb)     # the marker of the same lane
    fig = estimate_figure(topo, [])
    (center,) = [ln for ln in fig.axes[0].get_lines() if ln.get_gid() == 'center']
    assert to_rgb(center.get_color()) == pytest.approx(COLORS['center'][:3])
    plt.close(fig)
    assert KIND_RGBA['entering'][1] > KIND_RGBA['entering'][2]   # entering green,
    assert KIND_RGBA['leaving'][2] > KIND_RGBA['leaving'][1]     # leaving blue
