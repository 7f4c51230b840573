"""Lanes the traffic shows side by side (beyond the paper, topology/side_by_side.py): the
count from overlapping lateral profiles on a curved road, the profiles of a scene's arm,
and the raised, refitted state that the reported estimate takes."""

from dataclasses import replace
import math

from hypothesis import given, settings, strategies as st
import numpy as np
import pytest

from intersection_estimator.model import ENTERING
from intersection_estimator.observations import Detections
from intersection_estimator.topology import TopologyConfig, TopologyEstimator
from intersection_estimator.topology.config import Tables
from intersection_estimator.topology.mcmc import Posterior
from intersection_estimator.topology.side_by_side import (NEARS, STEP, arm_profiles, counted,
                                                          entering_rows, fit_counts, lanes_beyond,
                                                          lanes_side_by_side, nearest_arm, occupied,
                                                          side_by_side, tracks_of)
from intersection_estimator.topology.state import HDR, NIN, NOUT, STRIDE, WID, pack_state
from intersection_estimator.topology.support import reported

from .scenes import EASY, _lane_point, scene, tracked_posterior, trajectories

CFG = TopologyConfig(chains_tracked=1)
W = 3.5


def _profiles(offsets, rng, lo=0.0, hi=60.0, curve=0.004, noise=0.15, grid=None):
    """One lateral profile per offset on a road that curves (t = curve * s^2: 14 m of
    sideways drift over 60 m, so the lane means of a straight frame mix), NaN off
    ``[lo, hi]``."""
    s = np.arange(0.0, 80.0, STEP) if grid is None else grid
    T = np.full((len(offsets), len(s)), np.nan)
    on = (s >= lo) & (s <= hi)
    for i, o in enumerate(offsets):
        T[i, on] = curve * s[on] ** 2 + o + rng.normal(0.0, noise, on.sum())
    return T


@pytest.mark.parametrize('offsets,lanes', [
    ((0.0, 0.1, -0.2, 0.05), 1),
    ((0.0, 0.1, W, W + 0.2), 2),
    ((0.0, 2 * W, 2 * W - 0.1), 3),            # a lane between them that no vehicle used
    ((0.0, 0.2, 0.5 * W), 1),                  # half a lane apart: not a lane of its own
])
def test_lanes_from_the_separation_whatever_the_curve(offsets, lanes):
    T = _profiles(offsets, np.random.default_rng(0))
    assert lanes_side_by_side(T, W, 8.0) == lanes


def test_a_turn_pocket_counts_near_the_box():
    """The pocket's vehicle drives beside the others over the first 24 m only and in the
    main lane beyond: over the whole overlap its median separation is 0."""
    rng = np.random.default_rng(2)
    T = _profiles([0.0, 0.1, -0.1, 0.0], rng)
    near = np.arange(T.shape[1]) * STEP < 24.0
    T[3, near] += W
    assert lanes_side_by_side(T, W, 8.0) == 2
    T[3, near] -= W
    assert lanes_side_by_side(T, W, 8.0) == 1


def test_a_short_turn_pocket_counts_in_the_shorter_near_window():
    """Two vehicles drive the pocket beside the others over the first 16 m and the main
    lane's course beyond (SUMO dev seed 16): over the first 36 m the median separation mixes
    both stretches, over the first 24 m it is the pocket's. Entering profiles are read over
    both stretches, leaving ones (no pockets) over the 36 m only."""
    rng = np.random.default_rng(4)
    T = _profiles([0.0, 0.1, -0.1, 0.0, 0.05], rng)
    pocket = np.arange(T.shape[1]) * STEP < 16.0
    T[3:, pocket] += W
    entering, leaving = NEARS
    assert lanes_side_by_side(T, W, 8.0, entering) == 2
    assert lanes_side_by_side(T, W, 8.0, leaving) == 1
    T[3:, pocket] -= W
    assert lanes_side_by_side(T, W, 8.0, entering) == 1


def test_the_parts_compared_are_counted():
    T = _profiles([0.0, 0.1, W, W], np.random.default_rng(3))
    assert side_by_side(T, W, 8.0) == (2, 4)
    assert side_by_side(T[:1], W, 8.0) == (0, 0)


@pytest.mark.parametrize('n,shown,compared,cap,single,want', [
    (1, 2, 4, 4, True, 2),          # raised to what is shown
    (4, 1, 4, 4, True, 2),          # at most one lane beyond it, once 4 parts were compared
    (4, 1, 3, 4, True, 4),          # too few parts compared: the MAP's count stands
    (4, 1, 9, 0, True, 4),          # no cap
    (3, 0, 0, 4, True, 1),          # no two parts side by side: one lane
    (3, 0, 0, 4, False, 3),         # ... unless switched off: the MAP's count stands
    (1, 0, 0, 4, True, 1),
    (9, 9, 9, 4, True, 6),          # never beyond max_lanes
])
def test_counted(n, shown, compared, cap, single, want):
    cfg = replace(CFG, side_by_side_cap=cap, side_by_side_single=single)
    assert counted(n, shown, compared, cfg) == want
    assert counted(n, shown, compared, cfg, beyond=0) == want


@pytest.mark.parametrize('n,shown,compared,beyond,want', [
    (1, 1, 4, 2, 2),                # raised by the lanes shown beyond the radius
    (5, 1, 4, 3, 4),                # capped one lane beyond the most shown
    (1, 0, 0, 2, 2),                # nothing shown within: raised to the lanes beyond
    (3, 0, 0, 2, 3),                # ... no parts compared: the MAP's count stands
    (3, 0, 0, 1, 1),                # one lane beyond shows no lane beside another
    (1, 3, 4, 0, 3),                # nothing beyond: as without the reach
])
def test_counted_with_the_lanes_beyond_the_radius(n, shown, compared, beyond, want):
    cfg = replace(CFG, side_by_side_cap=2, side_by_side_single=True)
    assert counted(n, shown, compared, cfg, beyond) == want


def test_an_arm_direction_without_parts_side_by_side_keeps_one_lane():
    """Arm 3's leaving parts, all but one dropped: nothing is shown side by side, so a
    state with 3 leaving lanes there is lowered to 1 and refitted; off, it stands."""
    gt = EASY[0]
    post = tracked_posterior(CFG, gt)
    dets = scene(gt, 'tracked', seed=3, clutter=10)
    tr = tracks_of(dets)
    S = pack_state(gt)
    _, T_out = arm_profiles(S, 3, tr, nearest_arm(S, tr.xy), entering_rows(S, tr), 12.0, 75.0)
    assert side_by_side(T_out, gt.arms[3].lane_width, 8.0)[0] == 2
    rng = np.random.default_rng(3)
    out3 = gt.arms[3].direction
    paths, seen = [], 0
    for xy, hd in trajectories(gt, rng, per_lane=2):
        leaves3 = (xy[-1] - gt.center) @ out3 > 40.0
        seen += leaves3
        if not leaves3 or seen == 1:           # one vehicle leaves on arm 3
            paths.append(Detections.make(xy + rng.normal(0, 0.3, xy.shape),
                                         np.arange(len(xy)) * 0.1, heading=hd,
                                         track_id=len(paths)))
    assert seen >= 2
    lone = tracks_of(Detections.concat(paths))
    more = S.copy()
    more[HDR + 3 * STRIDE + NOUT] = 3
    _, T_lone = arm_profiles(more, 3, lone, nearest_arm(more, lone.xy),
                             entering_rows(more, lone), 12.0, 75.0)
    assert side_by_side(T_lone, gt.arms[3].lane_width, 8.0)[0] == 0
    S2, lp = fit_counts(post, more.copy(), lone, CFG)
    assert lp is not None and S2[HDR + 3 * STRIDE + NOUT] == 1
    kept, lp = fit_counts(post, more.copy(), lone, replace(CFG, side_by_side_single=False,
                                                           side_by_side_occupied=False))
    assert kept[HDR + 3 * STRIDE + NOUT] == 3


def test_parts_that_do_not_overlap_show_nothing():
    rng = np.random.default_rng(1)
    T = np.vstack([_profiles([0.0], rng, 0.0, 20.0), _profiles([W], rng, 30.0, 60.0)])
    assert lanes_side_by_side(T, W, 8.0) == 0
    assert lanes_side_by_side(T[:1], W, 8.0) == 0


def test_a_scene_arm_gives_one_profile_per_part_and_its_lanes():
    gt = EASY[0]                                    # arm 3: 2 entering, 2 leaving lanes
    tr = tracks_of(scene(gt, 'tracked', seed=3, clutter=10))
    S = pack_state(gt)
    T_in, T_out = arm_profiles(S, 3, tr, nearest_arm(S, tr.xy), entering_rows(S, tr),
                               12.0, 75.0)
    assert len(T_in) == 4 and len(T_out) >= 2      # 2 vehicles per entering lane
    assert lanes_side_by_side(T_in, gt.arms[3].lane_width, 8.0) == 2


@pytest.mark.parametrize('k,side', [(1, NIN), (3, NOUT)])
def test_a_lane_too_few_is_raised_and_refitted(k, side):
    """(The scene's lanes have 2 vehicles each: the cap stays out of it.)"""
    gt = EASY[0]
    post = tracked_posterior(CFG, gt)
    tr = tracks_of(scene(gt, 'tracked', seed=3, clutter=10))
    S = pack_state(gt)
    fewer = S.copy()
    fewer[HDR + k * STRIDE + side] -= 1
    S2, lp = fit_counts(post, fewer.copy(), tr, CFG)
    assert lp is not None and S2[HDR + k * STRIDE + side] == S[HDR + k * STRIDE + side]
    assert lp == pytest.approx(post(S2))
    assert lp > post(fewer)


def test_the_truth_is_kept_and_the_step_can_be_switched_off():
    gt = EASY[0]
    post = tracked_posterior(CFG, gt)
    tr = tracks_of(scene(gt, 'tracked', seed=3, clutter=10))
    S = pack_state(gt)
    same, lp = fit_counts(post, S.copy(), tr, CFG)
    assert lp is None and np.array_equal(same, S)
    fewer = S.copy()
    fewer[HDR + 1 * STRIDE + NIN] -= 1
    off = replace(CFG, side_by_side_overlap=0.0)
    kept, lp = fit_counts(post, fewer.copy(), tr, off)
    assert lp is None and np.array_equal(kept, fewer)
    assert fit_counts(post, fewer.copy(), None, CFG)[1] is None


def test_the_reported_estimate_takes_the_raised_counts():
    gt = EASY[0]
    post = tracked_posterior(CFG, gt)
    tr = tracks_of(scene(gt, 'tracked', seed=3, clutter=10))
    fewer = pack_state(gt)
    fewer[HDR + 1 * STRIDE + NIN] -= 1
    S, conf, lpost = reported(post, fewer, post(fewer), CFG, tr)
    assert S[HDR + 1 * STRIDE + NIN] == gt.arms[1].lanes_in
    assert lpost == pytest.approx(post(S)) and len(conf) == len(gt.arms)
    S0, _, _ = reported(post, fewer, post(fewer), CFG)         # without tracks: as it was
    assert S0[HDR + 1 * STRIDE + NIN] == gt.arms[1].lanes_in - 1


@settings(max_examples=40, deadline=None)
@given(slots=st.lists(st.integers(0, 3), min_size=2, max_size=6),
       curve=st.floats(-0.006, 0.006), shift=st.floats(-5.0, 5.0), seed=st.integers(0, 99))
def test_the_count_is_the_span_of_the_slots_whatever_curve_and_shift(slots, curve, shift, seed):
    """Parts in lanes ``slots`` (whole lane widths apart) on any curve, the whole road
    shifted sideways: the lanes spanned are max - min + 1."""
    rng = np.random.default_rng(seed)
    T = _profiles([shift + W * k for k in slots], rng, curve=curve)
    assert lanes_side_by_side(T, W, 8.0) == max(slots) - min(slots) + 1


def test_lanes_far_beyond_what_the_traffic_shows_are_capped():
    """Arm 3's four entering parts show its 2 lanes: a state with 4 keeps at most 3."""
    gt = EASY[0]
    post = tracked_posterior(CFG, gt)
    tr = tracks_of(scene(gt, 'tracked', seed=3, clutter=10))
    more = pack_state(gt)
    more[HDR + 3 * STRIDE + NIN] = 4
    S2, lp = fit_counts(post, more.copy(), tr, CFG)
    assert lp is not None and S2[HDR + 3 * STRIDE + NIN] == 3
    kept, lp = fit_counts(post, more.copy(), tr, replace(CFG, side_by_side_cap=0,
                                                         side_by_side_occupied=False))
    assert lp is None and kept[HDR + 3 * STRIDE + NIN] == 4


def test_rows_without_a_heading_take_it_from_their_path():
    gt = EASY[0]
    dets = scene(gt, 'tracked', seed=3)
    with_heading = tracks_of(dets)
    dets.heading[:] = np.nan
    from_path = tracks_of(dets)
    # the scene's 0.3 m position noise on 1 m steps: the path heading is within ~20 deg
    cos = (with_heading.h * from_path.h).sum(1)
    assert np.median(cos) > np.cos(np.radians(10.0))
    S = pack_state(gt)
    T_in, _ = arm_profiles(S, 3, from_path, nearest_arm(S, from_path.xy),
                           entering_rows(S, from_path), 12.0, 75.0)
    assert lanes_side_by_side(T_in, gt.arms[3].lane_width, 8.0) == 2


@pytest.mark.parametrize('capped,lanes', [(True, 2), (False, 1)])
def test_lanes_are_read_at_a_width_the_map_state_did_not_widen(capped, lanes):
    """An entering direction of two lanes 2.75 m apart that the MAP state holds as one lane
    4 m wide (the width grew to cover the second lane's vehicles): at 4 m the two lanes lie
    0.69 widths apart, not one lane; read at ``lane_width`` (3.5 m), 0.79 widths, one lane
    apart, and the lane is raised."""
    from .scenes import easy_intersection
    gt = easy_intersection(lanes=((2, 1),) + ((1, 1),) * 3, width=2.75)
    cfg = replace(CFG, side_by_side_width=capped)
    post = tracked_posterior(cfg, gt)
    tr = tracks_of(scene(gt, 'tracked', seed=3, clutter=10))
    wide = pack_state(gt)
    k = next(i for i, a in enumerate(gt.arms) if a.lanes_in == 2)      # pack_state's order
    wide[HDR + k * STRIDE + NIN], wide[HDR + k * STRIDE + WID] = 1, 4.0
    S2, _ = fit_counts(post, wide.copy(), tr, cfg)
    assert S2[HDR + k * STRIDE + NIN] == lanes


@pytest.mark.parametrize('reach,lanes', [(20.0, 2), (0.0, 1)])
def test_a_lane_the_traffic_leaves_before_the_radius_is_read_beyond_it(reach, lanes):
    """The vehicles of an arm's second entering lane change out of it (here: are not seen)
    within 40 m of the center, inside ``track_radius``; 40-60 m out they drive beside the
    others. With ``side_by_side_reach`` the profiles reach beyond the radius and show it."""
    from .scenes import easy_intersection
    gt = easy_intersection(lanes=((2, 1),) + ((1, 1),) * 3)
    k = next(i for i, a in enumerate(gt.arms) if a.lanes_in == 2)
    per_lane = 2                                            # scene()'s default
    first = per_lane * (sum(a.lanes_in for a in gt.arms[:k]) + 1)   # trajectories()' order
    dets = scene(gt, 'tracked', seed=3, clutter=10)
    near = np.hypot(*(dets.xy - gt.center).T) < 40.0
    dets = dets.subset(np.flatnonzero(~(near & np.isin(dets.track_id, [first, first + 1]))))
    cfg = replace(CFG, track_radius=40.0, side_by_side_reach=reach)
    post = tracked_posterior(cfg, gt)
    S = pack_state(gt)
    S[HDR + k * STRIDE + NIN] = 1
    S2, _ = fit_counts(post, S.copy(), tracks_of(dets), cfg)
    assert S2[HDR + k * STRIDE + NIN] == lanes


def test_the_reach_beyond_the_radius_is_a_window_of_its_own():
    """The stations beyond ``track_radius`` are read on their own (``lanes_beyond``): a
    lane that the parts show only there is counted there and lost when read with the
    stations within, where the parts drive one lane; parts that overlap only beyond add
    nothing to the parts compared within."""
    rng = np.random.default_rng(5)
    grid = np.arange(12.0, 110.0, STEP)                     # 35 m beyond the radius
    inside = int(np.sum(grid < 75.0))
    T = _profiles([0.0, 0.1, -0.1, 0.05], rng, lo=12.0, hi=110.0, curve=0.0, grid=grid)
    T[1, inside:] += W                                      # one lane over, beyond only
    assert lanes_beyond(T[:, inside:], W, 8.0) == 2
    assert side_by_side(T[:, :inside], W, 8.0) == (1, 4)
    assert side_by_side(T, W, 8.0)[0] == 1                  # read with the rest: lost
    T = _profiles([0.0, W], rng, lo=12.0, hi=110.0, curve=0.0, grid=grid)
    T[1, :inside - 3] = np.nan                              # 4 m side by side within
    assert side_by_side(T[:, :inside], W, 8.0) == (0, 0)
    assert lanes_beyond(T[:, inside:], W, 8.0) == 2


def test_far_out_a_road_beside_is_not_lanes():
    """Beyond the radius the lateral band holds another road: parts 5 lane widths beside
    two lanes are read as their own road, not as lanes 3-6 of this one."""
    T = _profiles([0.0, 0.1, W, 5 * W], np.random.default_rng(6), curve=0.0)
    assert lanes_beyond(T, W, 8.0) == 2
    assert lanes_side_by_side(T, W, 8.0) == 6               # the whole-number rule alone


def test_a_lane_beyond_those_shown_that_no_part_drove_is_left_out():
    """Arm 3's four entering parts drive its 2 lanes: a state with 3 keeps them under the
    cap, and with ``side_by_side_occupied`` drops the third, which holds no part."""
    gt = EASY[0]
    post = tracked_posterior(CFG, gt)
    tr = tracks_of(scene(gt, 'tracked', seed=3, clutter=10))
    S = pack_state(gt)
    T_in, _ = arm_profiles(S, 3, tr, nearest_arm(S, tr.xy), entering_rows(S, tr), 12.0, 75.0)
    assert occupied(S, 3, T_in, 0) == 2 and occupied(S, 3, T_in[:0], 0) == 0
    more = S.copy()
    more[HDR + 3 * STRIDE + NIN] = 3
    assert occupied(more, 3, T_in, 0) == 2
    kept, lp = fit_counts(post, more.copy(), tr, replace(CFG, side_by_side_occupied=False))
    assert lp is None and kept[HDR + 3 * STRIDE + NIN] == 3
    S2, lp = fit_counts(post, more.copy(), tr, CFG)
    assert S2[HDR + 3 * STRIDE + NIN] == 2 and lp == pytest.approx(post(S2))


def _queue_scene(n_queue: int, beside: float = 0.0):
    """EASY[0] with arm 1's second entering lane driven by no vehicle but holding a queue
    of ``n_queue`` vehicles standing 7 m apart through the recording (speed 0, facing the
    box), the first 18 m from the center; ``beside``: the queue that many metres farther
    out across the lanes."""
    gt = EASY[0]
    rng = np.random.default_rng(7)
    paths = trajectories(gt, rng, per_lane=2)
    del paths[4:6]                         # the moving vehicles of arm 1's lane 1
    parts = [Detections.make(xy + rng.normal(0, 0.2, xy.shape), np.arange(len(xy)) * 0.1,
                             heading=hd, track_id=tid) for tid, (xy, hd) in enumerate(paths)]
    arm = gt.arms[1]
    for i in range(n_queue):
        p = _lane_point(gt, arm, ENTERING, 1, 18.0 + 7.0 * i) + beside * arm.normal
        parts.append(Detections.make(p + rng.normal(0, 0.2, (40, 2)), np.arange(40) * 0.1,
                                     heading=np.full(40, arm.angle + math.pi),
                                     track_id=500 + i, speed=np.zeros(40)))
    return gt, Detections.concat(parts)


@pytest.mark.parametrize('n_queue,beside,n_map,lanes', [(4, 0.0, 1, 2), (2, 0.0, 1, 1),
                                                       (4, 2 * W, 2, 1)])
def test_a_queue_beside_the_driven_lane_shows_its_lane(n_queue, beside, n_map, lanes):
    """Arm 1's vehicles all drive lane 0; lane 1 holds only a queue. The queue's vehicles
    stand one behind the other on their lane, so with ``side_by_side_queues`` (3) its line
    counts as a part of lane 1 beside lane 0's parts, and a state that missed the lane gets
    it back. Two vehicles (a pair parked at the kerb) are not a queue; a queue 3 lane
    widths beside the traffic (within the profiles' band of a 2-lane state) stands on
    another road, and the lane no vehicle drove is left out."""
    gt, dets = _queue_scene(n_queue, beside)
    cfg = replace(CFG, side_by_side_queues=3)
    est = TopologyEstimator(cfg, seed=0)
    est.set_observations(dets)
    post = Posterior(Tables(cfg), est.observations)
    tr = est._window_tracks()
    assert len(tr.qxy) == (n_queue if n_queue >= 3 else 0)
    start = pack_state(gt)
    start[HDR + STRIDE + NIN] = n_map
    S, _ = fit_counts(post, start.copy(), tr, cfg)
    assert S[HDR + STRIDE + NIN] == lanes
    moving_only = tracks_of(dets, (), cfg.min_track_speed)
    assert len(moving_only.qxy) == 0
    S, _ = fit_counts(post, start.copy(), moving_only, cfg)
    assert S[HDR + STRIDE + NIN] == 1
