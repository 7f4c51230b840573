"""Issue 16: max_observations holds at every moment -- in the window between ticks, at the
window cut (also when every stamp is the same), and for messages held back in Ingest."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from intersection_estimator import params as P
from intersection_estimator.bagio import typestore
from intersection_estimator.ingest import Ingest
from intersection_estimator.observations import Detections
from intersection_estimator.pipeline import OnlineEstimator, PipelineConfig
from msg_adapters.odometry import odometry_msg
from msg_adapters.pointcloud2 import radar_cloud_msg
from msg_adapters.types import RosbagsTypes, make_header

T0 = 1_700_000_000.0


def _est(cap: int) -> OnlineEstimator:
    cfg = replace(PipelineConfig(), max_observations=cap, topology_samples=10, lane_samples=0)
    return OnlineEstimator(cfg)


def _dets(n: int, t: float, seed: int = 0) -> Detections:
    return Detections.make(np.random.default_rng(seed).normal(0.0, 20.0, (n, 2)), t)


def test_the_cap_holds_between_ticks_and_the_newest_stay():
    est = _est(100)
    for i in range(50):                       # 50 messages x 30 rows, no tick in between
        assert est.add(_dets(30, float(i), seed=i)) == 30
        assert est.n_observations <= 100
    win = est.window()
    assert len(win) == 100 and win.t.min() >= 46.0       # the newest 100 rows (stamps 46..49)
    assert est.evicted == 50 * 30 - 100


def test_one_message_larger_than_the_cap_keeps_its_newest_rows():
    est = _est(100)
    big = Detections.make(np.zeros((250, 2)), np.arange(250, dtype=float))
    est.add(big)
    assert est.n_observations == 100
    assert est.window().t.min() == 150.0


def test_window_cut_keeps_exactly_the_cap_when_all_stamps_agree():
    """header.stamp 0 everywhere: the cut-off stamp is every stamp, the cap still holds."""
    est = _est(1000)
    for i in range(5):
        est.add(_dets(200, 0.0, seed=i))
    est.config = replace(est.config, max_observations=300)     # lowered at run time
    est.tick(0.0)
    assert est.n_observations == 300 and len(est.window()) == 300


def test_a_burst_is_dropped_with_a_counted_reason():
    types = RosbagsTypes(typestore())
    values = dict(P.defaults(), max_observations=1000)
    ingest, est = Ingest(values, types), OnlineEstimator(P.pipeline_config(values))
    ingest.handle('odometry_topic', odometry_msg(types, T0, 0.0, 0.0, 0.0), est)
    rng = np.random.default_rng(1)
    for _ in range(20):                       # 20 clouds x 800 points, one stamp
        msg = radar_cloud_msg(types, make_header(types, 'radar', T0), rng.normal(0, 20, (800, 3)),
                              rng.normal(0, 5, 800))
        ingest.handle('radar_topics', msg, est)
        assert est.n_observations <= 1000
    assert ingest.dropped['window_full'] == 20 * 800 - 1000
    assert any(r == 'window_full' for r, _ in ingest.pop_warnings())


def test_held_back_messages_are_capped_in_points_too():
    """Clouds before the first ego pose wait, but never more points than max_observations."""
    types = RosbagsTypes(typestore())
    values = dict(P.defaults(), max_observations=1000)
    ingest, est = Ingest(values, types), OnlineEstimator(P.pipeline_config(values))
    rng = np.random.default_rng(2)
    for i in range(10):
        msg = radar_cloud_msg(types, make_header(types, 'base_link', T0 + 0.01 * i),
                              rng.normal(0, 20, (300, 3)), rng.normal(0, 5, 300))
        ingest.handle('radar_topics', msg, est)
    assert ingest._pending_points <= 1000 and len(ingest._pending) == 3
    assert ingest.dropped['no_ego_pose'] == 7
    for t in (T0, T0 + 0.2):
        ingest.handle('odometry_topic', odometry_msg(types, t, 0.0, 0.0, 0.0), est)
    assert est.n_observations == 900 and ingest._pending_points == 0
