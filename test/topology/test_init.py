"""Initialisation: meeting point of the driving lines, arm angles, lane guess."""

import math

import numpy as np
import pytest

from intersection_estimator.topology.init import (BOX_M, initial_arm_angles, initial_center,
                                                  initial_lanes, lane_guess, seed_lines)
from intersection_estimator.topology.likelihood import ObservationSet
from intersection_estimator.topology.preprocess import preprocess
from reference.init import initial_center_reference, initial_lanes_reference

from .scenes import LEGACY_PREPROCESS as CFG, easy_intersection, scene


def test_initial_center_and_arms_from_driving_lines():
    gt = easy_intersection(4, lanes=((2, 1), (1, 2), (1, 1), (2, 2)), center=(12.0, -7.0))
    for mode in ('tracked', 'heading', 'raw'):
        dets = scene(gt, mode, seed=1)
        p, o, w = seed_lines(dets, CFG)
        c = initial_center(p, o, w)
        assert np.hypot(*(c - gt.center)) < 8.0, mode
        ang = initial_arm_angles(p, o, w, c, math.radians(30), 6)
        if mode != 'raw':
            assert len(ang) == 4
            for a in gt.arms:
                assert min(abs((a.angle - b + math.pi) % (2 * math.pi) - math.pi) for b in ang) \
                    < math.radians(5)


def test_initial_lanes_recover_lane_counts():
    gt = easy_intersection(4, lanes=((2, 1), (1, 3), (1, 1), (2, 2)), center=(0.0, 0.0),
                           gap=1.0, width=3.25)
    dets = scene(gt, 'tracked', seed=2)
    obs = preprocess(dets, gt.center + 2.0, CFG)
    c, params = initial_lanes(obs, gt.center + 2.0, [a.angle for a in gt.arms], 3.5, 6, 4.0,
                              width_range=(2.75, 4.0))
    assert np.hypot(*(c - gt.center)) < 0.5
    assert [(p[1], p[2]) for p in params] == [(a.lanes_in, a.lanes_out) for a in gt.arms]


def _road_parts(angle_deg: float, lateral: float, n: int = 6) -> ObservationSet:
    """Trajectory parts of one arm: entering and leaving, one lane each, 20-60 m out,
    the arm's axis shifted ``lateral`` metres to its left."""
    u = np.array([math.cos(math.radians(angle_deg)), math.sin(math.radians(angle_deg))])
    nrm = np.array([-u[1], u[0]])
    s = np.linspace(20.0, 60.0, n)
    ent = s[:, None] * u + (lateral - 1.75) * nrm        # right-hand traffic: entering on the right
    lea = s[:, None] * u + (lateral + 1.75) * nrm
    xy = np.vstack([ent, lea])
    h = np.vstack([np.tile(-u, (n, 1)), np.tile(u, (n, 1))])
    m = 2 * n
    return ObservationSet(x=xy[:, 0], y=xy[:, 1], hx=h[:, 0], hy=h[:, 1], has_o=np.ones(m, bool),
                          d=np.r_[np.ones(n), -np.ones(n)], w=np.ones(m), sigma=np.full(m, 0.8),
                          sigma_ang=np.full(m, 0.1))


def test_the_center_stays_where_the_arms_axes_meet_outside_the_box():
    """Two arms of one road, 8 deg from collinear, one offset by 4 m: their axes meet
    ~29 m away. That is no refinement of the driving lines' center (init.BOX_M, windows
    with trajectories); an ordinary 4-arm scene 2 m off still moves to its center
    (previous test)."""
    a, b = _road_parts(0.0, 0.0), _road_parts(172.0, 4.0)
    obs = ObservationSet(**{f: np.concatenate([getattr(a, f), getattr(b, f)])
                            for f in ('x', 'y', 'hx', 'hy', 'has_o', 'd', 'w', 'sigma', 'sigma_ang')})
    angles = [0.0, math.radians(172.0)]
    c, params = initial_lanes(obs, np.zeros(2), angles, 3.5, 6, 4.0)
    assert np.array_equal(c, np.zeros(2))
    assert [(p[1], p[2]) for p in params] == [(1, 1), (1, 1)]
    cx, cy, _ = lane_guess(obs.x, obs.y, obs.hx, obs.hy, obs.has_o, obs.d, obs.w, 0.0, 0.0,
                           np.array(angles), 3.5, 6, 4.0, 1.0, 3, 3.5, 3.5, False)
    assert math.hypot(cx, cy) > 3 * BOX_M           # the axes' meeting point itself: far out
    far, _ = initial_lanes(obs, np.zeros(2), angles, 3.5, 6, 4.0, max_move=math.inf)
    np.testing.assert_allclose(far, (cx, cy))      # voxel windows (no trajectories) keep it


@pytest.mark.parametrize('mode', ['raw', 'tracked', 'heading'])
def test_compiled_initialisation_equals_the_numpy_reference(mode):
    """initial_center (IRLS) and initial_lanes (lane guess) match the numpy code they
    replaced: centers to 1e-9 m, gaps / widths to 1e-9, lane counts exactly."""
    from intersection_estimator.sim import SimConfig, simulate_scenario
    for seed in range(12):
        dets = simulate_scenario(seed, SimConfig()).detections(mode)
        p, o, w = seed_lines(dets, CFG)
        c = initial_center(p, o, w)
        np.testing.assert_allclose(c, initial_center_reference(p, o, w), rtol=0, atol=1e-9)
        angles = initial_arm_angles(p, o, w, c, math.radians(30.0), 6)
        obs = preprocess(dets, c, CFG, angles)
        for wr in (None, (2.75, 4.0)):
            c1, g1 = initial_lanes(obs, c, angles, 3.5, 6, 4.0, 1, width_range=wr)
            c2, g2 = initial_lanes_reference(obs, c, angles, 3.5, 6, 4.0, 1, width_range=wr)
            np.testing.assert_allclose(c1, c2, rtol=0, atol=1e-9)
            assert [(n1, n2) for _, n1, n2, _ in g1] == [(n1, n2) for _, n1, n2, _ in g2]
            np.testing.assert_allclose([(g, wd) for g, _, _, wd in g1],
                                       [(g, wd) for g, _, _, wd in g2], rtol=0, atol=1e-9)


@pytest.mark.parametrize('mode', ['tracked', 'raw', 'heading'])
def test_arm_angles_equal_the_loop_of_rolls(mode):
    """The vectorised histogram smoothing and peak search of ``initial_arm_angles`` give
    the angles of the loop they replaced (test/reference/init.py), float for float, on
    simulated scenes around the initial center and around shifted centers."""
    from intersection_estimator.pipeline import in_mode
    from intersection_estimator.sim import simulate_scenario
    from intersection_estimator.topology.config import TopologyConfig
    from intersection_estimator.topology.init import seed_lines
    from reference.init import initial_arm_angles_reference
    cfg = TopologyConfig()
    rng = np.random.default_rng(5)
    for seed in range(6):
        dets = in_mode(simulate_scenario(seed).detections(mode), mode)
        p, o, w = seed_lines(dets, cfg.preprocess_config())
        c = initial_center(p, o, w)
        for cc in (c, c + rng.normal(0.0, 10.0, 2)):
            for peak_frac in (cfg.init_peak_frac, 0.0):
                args = (p, o, w, cc, math.radians(cfg.min_sep_deg), cfg.max_arms)
                assert initial_arm_angles(*args, peak_frac=peak_frac) == \
                    initial_arm_angles_reference(*args, peak_frac=peak_frac)
