"""Preprocessing (paper §II-A): Doppler direction, clutter filter, voxels, trajectory split."""

import math

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from intersection_estimator._kernels import radar_frame
from intersection_estimator.likelihood import ObservationSet
from intersection_estimator.observations import Detections
from intersection_estimator.preprocess import (RAYS, PreprocessConfig, _arm_voxels,
                                               heading_observations, initial_arm_angles, initial_center,
                                               initial_lanes, preprocess, radar_observations,
                                               radar_rows, passages, seed_lines,
                                               tracked_observations, voxelise)

from topology_scenes import easy_intersection, scene

CFG = PreprocessConfig()


def test_voxelise_counts_and_means_per_class():
    xy = np.array([[0.1, 0.1], [0.5, 0.3], [0.2, 0.2], [5.0, 5.0], [-0.1, 0.0]])
    cls = np.array([0, 0, 1, 0, 0])
    vxy, vcls, cnt, _ = voxelise(xy, cls, 2.0)
    got = sorted(zip(map(tuple, np.round(vxy, 6)), vcls.tolist(), cnt.tolist()))
    assert got == sorted([((0.3, 0.2), 0, 2.0), ((0.2, 0.2), 1, 1.0), ((5.0, 5.0), 0, 1.0),
                          ((-0.1, 0.0), 0, 1.0)])


def test_straight_trajectory_splits_at_closest_point():
    """A vehicle crossing straight through the center gives one entering and one leaving
    part with the mean point on each side and the driving direction."""
    x = np.arange(-50.0, 50.5, 1.0)
    xy = np.stack([x, np.full_like(x, -1.75)], axis=1)
    dets = Detections.make(xy, t=np.arange(len(x)) * 0.1, heading=0.0, track_id=7)
    obs = tracked_observations(dets, (0.0, 0.0), CFG)
    assert len(obs) == 2
    i_in = int(np.argmin(obs.x))
    assert obs.x[i_in] < -20 and obs.x[1 - i_in] > 20
    assert np.allclose(obs.y, -1.75) and np.allclose(obs.hx, 1.0) and np.allclose(obs.hy, 0.0)
    assert obs.d[i_in] == 1.0 and obs.d[1 - i_in] == -1.0     # entering, then leaving


def test_turn_is_trimmed_from_the_part():
    """Entering along +x toward the center, then turning left: the entering part's mean
    stays on the straight lane (the arc inside the box is trimmed)."""
    s = np.arange(60.0, 10.0, -1.0)
    p_in = np.stack([s, np.full_like(s, 1.75)], axis=1)
    phi = np.linspace(-math.pi / 2, 0.0, 20)
    arc = np.stack([10.0 * np.cos(phi) + 0.0, 10.0 * np.sin(phi) + 11.75], axis=1)[::-1] * [1, 1]
    arc = np.stack([10.0 - 10.0 * np.sin(np.linspace(0, math.pi / 2, 20)),
                    1.75 + 10.0 * (1 - np.cos(np.linspace(0, math.pi / 2, 20)))], axis=1)
    xy = np.concatenate([p_in, arc])
    d = np.gradient(xy, axis=0)
    dets = Detections.make(xy, t=np.arange(len(xy)) * 0.1, heading=np.arctan2(d[:, 1], d[:, 0]),
                           track_id=1)
    trimmed = tracked_observations(dets, (0.0, 0.0), CFG)
    whole = tracked_observations(dets, (0.0, 0.0), PreprocessConfig(trim_turn_deg=0.0))
    k = int(np.argmax(trimmed.x))
    assert abs(trimmed.y[k] - 1.75) < 0.05 and abs(trimmed.hy[k]) < 0.05
    assert abs(whole.y[int(np.argmax(whole.x))] - 1.75) > abs(trimmed.y[k] - 1.75)


def test_static_false_tracks_are_dropped():
    rng = np.random.default_rng(0)
    xy = rng.normal([30.0, 5.0], 0.8, (4, 2))
    dets = Detections.make(xy, t=np.arange(4) * 0.1, heading=rng.uniform(-3, 3, 4), track_id=99)
    assert len(tracked_observations(dets, (0.0, 0.0), CFG)) == 0


def _radar(xy, dop, sensor, rcs=10.0):
    return Detections.make(np.asarray(xy, float), doppler=dop, sensor_xy=sensor, rcs=rcs)


def test_doppler_direction_rule_with_line_of_sight():
    """Sensor on the arm at (30, -1.75) looking toward the center at (0, 0)."""
    sensor = (30.0, -1.75)
    cfg = PreprocessConfig(voxel_size=0.5)
    # ahead of the sensor (between sensor and center): moving toward the center = toward
    # the sensor's look direction = away from the sensor -> doppler > 0 -> entering
    ahead = radar_observations(_radar([[15.0, 1.75]], 5.0, sensor), (0.0, 0.0), cfg)
    assert ahead.d.tolist() == [1.0]
    # behind the sensor: the paper's rule flips
    behind = radar_observations(_radar([[50.0, 1.75]], 5.0, sensor), (0.0, 0.0), cfg)
    assert behind.d.tolist() == [-1.0]
    # beyond the center on the opposite arm: moving away from the sensor = leaving
    far = radar_observations(_radar([[-30.0, -1.75]], 5.0, sensor), (0.0, 0.0), cfg)
    assert far.d.tolist() == [-1.0]
    # cross traffic seen at a right angle: direction unknown (d = 0), or dropped
    side = radar_observations(_radar([[15.0, 15.0]], 5.0, (30.0, 0.0)), (0.0, 0.0),
                              PreprocessConfig(min_radial_cos=0.25))
    assert side.d.tolist() == [0.0]
    side = radar_observations(_radar([[15.0, 15.0]], 5.0, (30.0, 0.0)), (0.0, 0.0),
                              PreprocessConfig(min_radial_cos=0.25, keep_unknown_direction=False))
    assert len(side) == 0


def test_radar_clutter_filter():
    sensor = (30.0, 0.0)
    dets = Detections.concat([_radar([[10.0, 2.0]], 0.1, sensor, rcs=-5),   # static clutter
                              _radar([[10.0, 2.0]], 6.0, sensor, rcs=-10),  # weak
                              _radar([[12.0, 2.0]], 6.0, sensor, rcs=np.nan),
                              _radar([[14.0, 2.0]], 6.0, sensor),
                              _radar([[16.0, 2.0]], 0.1, sensor, rcs=12)])  # slow vehicle
    obs = radar_observations(dets, (0.0, 0.0), PreprocessConfig(voxel_size=1.0))
    assert sorted(zip(obs.x.round(1).tolist(), obs.d.tolist())) == [(12.0, 1.0), (14.0, 1.0),
                                                                    (16.0, 0.0)]


def test_heading_detections_are_voxelised_with_their_heading():
    xy = np.array([[20.0, 1.0], [20.4, 1.2], [20.2, 1.1], [-20.0, -1.0]])
    h = np.array([2.9, 2.85, 2.95, math.pi])
    obs = heading_observations(Detections.make(xy, heading=h), (0.0, 0.0),
                               PreprocessConfig(voxel_size=2.0))
    assert len(obs) == 2
    k = int(np.argmax(obs.x))
    assert obs.w[k] == 3.0 * obs.w[1 - k] and abs(math.atan2(obs.hy[k], obs.hx[k]) - 2.9) < 1e-3
    assert obs.d[k] == 1.0 and obs.d[1 - k] == -1.0   # toward / away from the center


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


def test_empty_and_degenerate_inputs():
    empty = Detections.empty()
    assert len(preprocess(empty, (0, 0), CFG)) == 0
    assert initial_center(*seed_lines(empty, CFG)) is None
    one = Detections.make([[1.0, 2.0]], heading=0.0, track_id=0)
    assert len(preprocess(one, (0, 0), CFG)) == 0


def _corridor_weight(obs, center, angle, reach=12.0):
    """Observation weight within ``reach`` of the ray from ``center`` at ``angle``, beyond 10 m."""
    v = np.stack([obs.x - center[0], obs.y - center[1]], axis=1)
    s = v @ np.array([math.cos(angle), math.sin(angle)])
    t = v @ np.array([-math.sin(angle), math.cos(angle)])
    return float(obs.w[(s > 10.0) & (np.abs(t) < reach)].sum())


def test_an_arm_the_chain_has_not_found_keeps_its_radar_and_heading_data():
    """Rows on no current arm are voxelised along rays, not along a neighbouring arm, where
    the straight-run filter used to drop them all: the chain could never add that arm."""
    inter = easy_intersection(4, lanes=((2, 2),) * 4)
    angles = [a.angle for a in inter.arms]
    for mode, fn in (('raw', radar_observations), ('heading', heading_observations)):
        dets = scene(inter, mode, seed=3)
        full = fn(dets, inter.center, CFG, angles)
        for k in range(len(angles)):
            missing = fn(dets, inter.center, CFG, angles[:k] + angles[k + 1:])
            w_full = _corridor_weight(full, inter.center, angles[k])
            assert w_full > 0
            assert _corridor_weight(missing, inter.center, angles[k]) > 0.5 * w_full, (mode, k)


# ----------------------------------------------------------------- compiled voxels == numpy

def arm_voxels_reference(xy, cls, arm, s, t, stamp, cfg: PreprocessConfig, vec=None):
    """Plain numpy voxelisation, written independently of the compiled kernel.

    Returns mean position, class, weight in vehicle passages (and summed ``vec``)."""
    si = np.floor(s / cfg.voxel_length).astype(np.int64)
    ti = np.floor(t / cfg.voxel_width).astype(np.int64)
    key = ((arm * 1024 + si + 512) * 4096 + ti + 2048) * 4 + cls
    uk, inv, cnt = np.unique(key, return_inverse=True, return_counts=True)
    inv = inv.reshape(-1)
    p = xy
    mean = np.stack([np.bincount(inv, p[:, 0], len(uk)), np.bincount(inv, p[:, 1], len(uk))],
                    axis=1) / cnt[:, None]
    if cfg.straight_run:   # occupied neighbour (lateral band +-1) before and after
        step = 4096 * 4
        before = np.zeros(len(uk), bool)
        after = np.zeros(len(uk), bool)
        for dt in (-4, 0, 4):
            before |= np.isin(uk - step + dt, uk, assume_unique=True)
            after |= np.isin(uk + step + dt, uk, assume_unique=True)
        keepv = before & after
    else:
        keepv = np.ones(len(uk), bool)
    # detections per vehicle passage of an along-arm bin (all lateral bins together)
    band = (arm * 1024 + si + 512) * 4 + cls
    ub, binv = np.unique(band, return_inverse=True)
    n_pass = passages(binv.reshape(-1), stamp, len(ub), cfg.passage_gap).sum()
    per_pass = len(xy) / max(n_pass, 1.0) if cfg.passage_gap > 0 else 1.0
    sv = np.zeros((len(uk), 2))
    if vec is not None:
        sv = np.stack([np.bincount(inv, vec[:, 0], len(uk)),
                       np.bincount(inv, vec[:, 1], len(uk))], axis=1)
    uk, mean, cnt, sv = uk[keepv], mean[keepv], cnt[keepv].astype(np.float64), sv[keepv]
    if cfg.voxel_merge > 1:   # fewer, longer voxels for the sampler (filter ran at full res.)
        si_k = (uk // (4096 * 4)) % 1024
        arm_k = uk // (4096 * 4 * 1024)
        rest = uk % (4096 * 4)
        key2 = (arm_k * 1024 + si_k // cfg.voxel_merge) * (4096 * 4) + rest
        u2, inv2 = np.unique(key2, return_inverse=True)
        inv2 = inv2.reshape(-1)
        c2 = np.bincount(inv2, cnt, len(u2))
        mean = np.stack([np.bincount(inv2, cnt * mean[:, 0], len(u2)),
                         np.bincount(inv2, cnt * mean[:, 1], len(u2))], axis=1) / c2[:, None]
        sv = np.stack([np.bincount(inv2, sv[:, 0], len(u2)), np.bincount(inv2, sv[:, 1], len(u2))],
                      axis=1)
        uk, cnt = u2, c2
    if vec is not None:
        return mean, uk % 4, cnt / per_pass, sv
    return mean, uk % 4, cnt / per_pass


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 10 ** 6), st.sampled_from([1, 2, 3]), st.booleans(),
       st.sampled_from([0.0, 1.0]), st.booleans())
def test_compiled_arm_voxels_equal_the_numpy_reference(seed, merge, straight, gap, with_vec):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(0, 3000))
    arm = rng.integers(0, 4, n)
    s = rng.uniform(-5.0, 90.0, n)
    t = rng.normal(0.0, 6.0, n)
    if seed % 5 == 0 and n:   # one far-flung row: too wide for the dense cell table
        s[0], t[0] = 4000.0, 1500.0
    xy = np.stack([s * 0.7 - t * 0.3, s * 0.3 + t * 0.7], axis=1)
    cls = rng.integers(0, 3, n)
    stamp = rng.uniform(0.0, 30.0, n)
    if seed % 2:   # sensor cycles: exact 1 s gaps
        stamp = np.round(stamp, 1)
    if seed % 3:   # rows in time order (as recorded): the kernel counts passages in one pass
        stamp = np.sort(stamp)
    vec = rng.normal(size=(n, 2)) if with_vec else None
    cfg = PreprocessConfig(voxel_merge=merge, straight_run=straight, passage_gap=gap)
    got = _arm_voxels(xy, cls, arm, s, t, stamp, cfg, vec)
    want = arm_voxels_reference(xy, cls, arm, s, t, stamp, cfg, vec)
    assert len(got) == len(want)
    for g, w in zip(got, want):
        np.testing.assert_allclose(g, w, rtol=1e-9, atol=1e-9)


@settings(max_examples=15, deadline=None)
@given(st.integers(0, 50), st.floats(-3.0, 3.0), st.floats(-0.1, 0.1), st.sampled_from([0.0, 20.0]))
def test_fused_radar_voxels_equal_frame_then_voxels(seed, shift, turn, min_dist):
    """radar_observations' single compiled pass == radar_frame, _arm_voxels of the rows on
    an arm and of those along rays, near-center drop (the steps it fuses)."""
    inter = easy_intersection(3 + seed % 2, lanes=((1, 2),) * (3 + seed % 2))
    dets = scene(inter, 'raw', seed=seed)
    c = np.asarray(inter.center) + shift
    angles = [a.angle + turn for a in inter.arms][:-1] if seed % 3 == 0 else \
        [a.angle + turn for a in inter.arms]
    cfg = PreprocessConfig(min_center_dist=min_dist)
    got = radar_observations(dets, c, cfg, angles)
    rows = radar_rows(dets, cfg)
    arm, s, t, group, cls = radar_frame(
        rows.x, rows.y, rows.doppler, rows.sensor_x, rows.sensor_y, float(c[0]), float(c[1]),
        np.asarray(angles, float), cfg.arm_reach, cfg.min_radial_cos, cfg.min_doppler,
        cfg.keep_unknown_direction, RAYS)
    xy_rows = np.stack([rows.x, rows.y], axis=1)
    parts = [_arm_voxels(xy_rows[g], cls[g], arm[g], s[g], t[g], rows.t[g], cfg)
             for g in (group == 1, group == 2)]
    xy, vc, cnt = (np.concatenate(p) for p in zip(*parts))
    keep = np.hypot(xy[:, 0] - c[0], xy[:, 1] - c[1]) >= min_dist
    assert len(got) == keep.sum() > 0
    np.testing.assert_array_equal(got.x, xy[keep, 0])
    np.testing.assert_array_equal(got.y, xy[keep, 1])
    np.testing.assert_array_equal(got.d, np.select([vc == 1, vc == 0], [1.0, -1.0], 0.0)[keep])
    np.testing.assert_array_equal(got.passages, cnt[keep])


def voxelise_reference(xy, cls, size, vec):
    """np.unique voxels: sorted (x bin, y bin, class) keys, means, first class, counts."""
    ij = np.floor(xy / size).astype(np.int64)
    key = (((ij[:, 0] + (1 << 20)) << 22) + (ij[:, 1] + (1 << 20))) * 64 + cls
    uk, inv, cnt = np.unique(key, return_inverse=True, return_counts=True)
    inv = inv.reshape(-1)
    mean = np.stack([np.bincount(inv, xy[:, 0]), np.bincount(inv, xy[:, 1])], axis=1) / cnt[:, None]
    sv = np.stack([np.bincount(inv, vec[:, 0], len(uk)), np.bincount(inv, vec[:, 1], len(uk))], 1)
    return mean, uk % 64, cnt.astype(np.float64), sv


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 10 ** 6), st.sampled_from([0.5, 3.0, 6.0]), st.booleans())
def test_compiled_voxel_index_equals_sorted_unique_keys(seed, size, far):
    """voxelise's compiled grouping (dense table, or a sort for far-flung rows) numbers
    voxels in sorted-key order, exactly as np.unique did."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 2000))
    xy = rng.normal(0.0, 40.0, (n, 2))
    if far:
        xy[0] = (3e4, -2e4)
    cls = rng.integers(0, 8, n)
    vec = rng.normal(size=(n, 2))
    got = voxelise(xy, cls, size, vec)
    want = voxelise_reference(xy, cls, size, vec)
    for g, w in zip(got, want):
        np.testing.assert_array_equal(g, w)


# ----------------------------------------------------- compiled initialisation == numpy

def _wmedian_reference(x, w):
    i = np.argsort(x)
    cw = np.cumsum(w[i])
    return float(x[i][np.searchsorted(cw, 0.5 * cw[-1])])


def initial_center_reference(p, o, w, scale=6.0, iters=30):
    """The numpy IRLS the compiled ``irls_center`` replaced."""
    if len(p) == 0:
        return None
    c0 = np.array([_wmedian_reference(p[:, 0], w), _wmedian_reference(p[:, 1], w)])
    nx, ny = -o[:, 1], o[:, 0]
    d = nx * p[:, 0] + ny * p[:, 1]                 # line i: <n_i, x> = d_i
    outer = np.stack([nx * nx, nx * ny, ny * ny])   # n n^T, upper triangle
    c = c0.copy()
    for _ in range(iters):
        wi = w / (1.0 + ((nx * c[0] + ny * c[1] - d) / scale) ** 2)
        mxx, mxy, myy = outer @ wi
        bx, by = (wi * d) @ np.stack([nx, ny], axis=1)
        lam = 1e-3 * max(mxx + myy, 1e-9)
        M = np.array([[mxx + lam, mxy], [mxy, myy + lam]])
        c_new = np.linalg.solve(M, np.array([bx, by]) + lam * c0)
        if np.hypot(*(c_new - c)) < 1e-3:
            c = c_new
            break
        c = c_new
    return c


def _robust_range_reference(x: np.ndarray, w: np.ndarray, tail: float = 0.03) -> tuple[float, float]:
    """Weighted (tail, 1 - tail) quantiles."""
    i = np.argsort(x)
    x, cw = x[i], np.cumsum(w[i])
    lo = int(np.searchsorted(cw, tail * cw[-1], side='right'))
    hi = int(np.searchsorted(cw, (1.0 - tail) * cw[-1], side='left'))
    return float(x[min(lo, len(x) - 1)]), float(x[min(hi, len(x) - 1)])


def initial_lanes_reference(obs: ObservationSet, center, angles, lane_width: float,
                            max_lanes: int, gap_max: float, traffic_side: int = 1, iters: int = 3,
                            width_range=None):
    """The numpy lane guess the compiled ``lane_guess`` replaced."""
    c = np.asarray(center, float).copy()
    n_arm = len(angles)
    u = np.array([[math.cos(a), math.sin(a)] for a in angles]).reshape(n_arm, 2)
    nrm = np.stack([-u[:, 1], u[:, 0]], axis=1)
    params = [(0.0, 1, 1, lane_width)] * n_arm
    if len(obs) == 0 or n_arm == 0:
        return c, params
    p = obs.xy
    o = np.stack([obs.hx, obs.hy], axis=1)
    for _ in range(iters):
        v = p - c
        s = v @ u.T
        t = v @ nrm.T
        par = np.abs(o @ u.T)
        ok = (s > 8.0) & (np.abs(t) < 25.0) & (~obs.has_o[:, None] | (par > math.cos(math.radians(20))))
        cost = np.where(ok, np.abs(t), np.inf)
        arm = np.argmin(cost, axis=1)
        has = np.isfinite(cost[np.arange(len(p)), arm])
        A = np.zeros((2, 2))
        b = np.zeros(2)
        params = []
        for k in range(n_arm):
            m = has & (arm == k)
            ent = np.where(obs.has_o[m], (o[m] @ u[k]) < 0, obs.d[m] > 0)
            tk = t[m, k] * traffic_side
            wk_ = obs.w[m]
            ti, to = tk[ent], -tk[~ent]
            if len(ti) == 0 or len(to) == 0:
                params.append((0.0, 1, 1, lane_width))
                continue
            lo_i, hi_i = _robust_range_reference(ti, wk_[ent])
            lo_o, hi_o = _robust_range_reference(to, wk_[~ent])
            axis = 0.5 * (lo_i - lo_o) * traffic_side       # lateral offset of the median axis
            inner = 0.5 * (lo_i + lo_o)                      # gap/2 + w/2
            gap = float(np.clip(2.0 * (inner - 0.5 * lane_width), 0.0, gap_max))
            nin = int(np.clip(round((hi_i - lo_i) / lane_width) + 1, 1, max_lanes))
            nout = int(np.clip(round((hi_o - lo_o) / lane_width) + 1, 1, max_lanes))
            wd = lane_width
            if width_range is not None and nin + nout > 2:
                wd = ((hi_i - lo_i) + (hi_o - lo_o)) / (nin + nout - 2)
                wd = float(np.clip(wd, *width_range))
            gap = float(np.clip(2.0 * (inner - 0.5 * wd), 0.0, gap_max))
            params.append((gap, nin, nout, wd))
            wk = float(min(len(ti), len(to)))
            A += wk * np.outer(nrm[k], nrm[k])
            b += wk * nrm[k] * (nrm[k] @ c + axis)
        lam = 1e-3 * max(np.trace(A), 1e-9)
        c = np.linalg.solve(A + lam * np.eye(2), b + lam * c)
    return c, params


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
