"""PNG plot of an estimate (matplotlib Agg)."""

from __future__ import annotations

from test_lanes_synth import synth_case

from intersection_estimator.export.plot import plot_estimate
from intersection_estimator.lanes import lanelets_from_topology


def test_plot_written(tmp_path):
    topo, _, _, dets = synth_case(0, n_arms=3, lanes=(1, 1), per_lane=1)
    ls = lanelets_from_topology(topo)
    out = plot_estimate(tmp_path / 'a.png', topo, ls, dets=dets, gt_lanelets=ls, title='x')
    data = out.read_bytes()
    assert data[:8] == b'\x89PNG\r\n\x1a\n' and len(data) > 10_000


def test_plot_without_observations_or_lanes(tmp_path):
    topo, _, _, _ = synth_case(1, n_arms=3, lanes=(1, 1), per_lane=1)
    assert (plot_estimate(tmp_path / 'b.png', topo, []).stat().st_size > 1000)
    assert (plot_estimate(tmp_path / 'c.png', None, [], view_radius=10.0).stat().st_size > 1000)
