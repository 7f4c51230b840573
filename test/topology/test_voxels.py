"""Voxelisation (paper §II-A): square and arm-aligned voxels, the fused radar pass."""

from dataclasses import replace

import numpy as np
from hypothesis import given, settings, strategies as st

from intersection_estimator.topology.preprocess import radar_observations, radar_rows
from intersection_estimator.topology.voxels import (RAYS, arm_voxel_set, radar_frame,
                                                    voxelise)
from reference.voxels import arm_voxels_reference, voxelise_reference

from .scenes import LEGACY_PREPROCESS as CFG, easy_intersection, scene


def test_voxelise_counts_and_means_per_class():
    xy = np.array([[0.1, 0.1], [0.5, 0.3], [0.2, 0.2], [5.0, 5.0], [-0.1, 0.0]])
    cls = np.array([0, 0, 1, 0, 0])
    vxy, vcls, cnt, _ = voxelise(xy, cls, 2.0)
    got = sorted(zip(map(tuple, np.round(vxy, 6)), vcls.tolist(), cnt.tolist()))
    assert got == sorted([((0.3, 0.2), 0, 2.0), ((0.2, 0.2), 1, 1.0), ((5.0, 5.0), 0, 1.0),
                          ((-0.1, 0.0), 0, 1.0)])


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
    cfg = replace(CFG, voxel_merge=merge, straight_run=straight, passage_gap=gap)
    got = arm_voxel_set(xy, cls, arm, s, t, stamp, cfg, vec)
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
    cfg = replace(CFG, min_center_dist=min_dist)
    got = radar_observations(dets, c, cfg, angles)
    rows = radar_rows(dets, cfg)
    arm, s, t, group, cls = radar_frame(
        rows.x, rows.y, rows.doppler, rows.sensor_x, rows.sensor_y, float(c[0]), float(c[1]),
        np.asarray(angles, float), cfg.arm_reach, cfg.min_radial_cos, cfg.min_doppler,
        cfg.keep_unknown_direction, RAYS)
    xy_rows = np.stack([rows.x, rows.y], axis=1)
    parts = [arm_voxel_set(xy_rows[g], cls[g], arm[g], s[g], t[g], rows.t[g], cfg)
             for g in (group == 1, group == 2)]
    xy, vc, cnt = (np.concatenate(p) for p in zip(*parts))
    keep = np.hypot(xy[:, 0] - c[0], xy[:, 1] - c[1]) >= min_dist
    assert len(got) == keep.sum() > 0
    np.testing.assert_array_equal(got.x, xy[keep, 0])
    np.testing.assert_array_equal(got.y, xy[keep, 1])
    np.testing.assert_array_equal(got.d, np.select([vc == 1, vc == 0], [1.0, -1.0], 0.0)[keep])
    np.testing.assert_array_equal(got.passages, cnt[keep])


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


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 10 ** 6), st.sampled_from([1, 2, 3]), st.booleans(),
       st.sampled_from([0.0, 1.0]), st.sampled_from(['dense', 'far', 'high', 'low', 'beyond']))
def test_arm_voxels_equal_the_kernel_before_the_dense_tables_bit_for_bit(seed, merge, straight,
                                                                         gap, layout):
    """The dense band / cell / neighbour tables (issue 18) give the arrays of the sorted
    keys and binary searches they replaced (test/reference/voxels_before.py), every float
    equal: rows in the box, a far-flung row (no dense table), bins at the top and the
    bottom of their key fields (along 510 / -511, lateral 2046 / -2047) and beyond them
    (the sorted path)."""
    from reference.voxels_before import arm_voxels_before
    from intersection_estimator.topology.voxels import arm_voxels
    rng = np.random.default_rng(seed)
    n = int(rng.integers(0, 2500))
    arm = rng.integers(0, 5, n)
    s = rng.uniform(-15.0, 120.0, n)
    t = np.round(rng.normal(0.0, 5.0, n), 1)
    if n and layout == 'far':
        s[0], t[0] = 4000.0, 1500.0
    if layout == 'high':      # the top of the key fields, still in a dense table
        s, t = np.minimum(s + 4990.0, 5109.9), np.minimum(t + 2035.0, 2046.9)
    if layout == 'low':
        s, t = np.maximum(s - 5095.0, -5110.0), np.maximum(t - 2035.0, -2047.0)
    if layout == 'beyond':    # bins spill into the next key field: sorted keys
        s, t = s + 5010.0, t + 2040.0
    cls = rng.integers(0, 4, n)
    stamp = np.round(rng.uniform(0.0, 30.0, n), int(seed % 3))
    if seed % 4:
        stamp = np.sort(stamp)
    vx, vy = rng.normal(size=n), rng.normal(size=n)
    args = (s * 0.6 - t * 0.8, s * 0.8 + t * 0.6, cls, arm, s, t, stamp, vx, vy, 10.0, 1.0,
            straight, merge, gap)
    got, want = arm_voxels(*args), arm_voxels_before(*args)
    for g, w in zip(got, want):
        assert g.dtype == w.dtype and g.shape == w.shape and g.tobytes() == w.tobytes()
