"""Approach lanes shaped by their traffic (lanes/follow.py)."""

from __future__ import annotations

from dataclasses import replace
import math

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from intersection_estimator.evaluate import lane_distance, orthogonal_distances
from intersection_estimator.lanes import LaneConfig
from intersection_estimator.lanes.follow import fit_offset, select_offset
from intersection_estimator.lanes.spline import _data
from intersection_estimator.lanes.init import (Trajectory, fit_frames, lane_specs,
                                               split_at_center, stop_distances)
from intersection_estimator.model import Arm, Intersection

LAT = (1.75, 5.25)          # entering lane centers of arm 0 (right-hand traffic, +n side)
CFG = replace(LaneConfig(), follow_lanes=0)     # straight approach lanes (paper §III-A)
ON = replace(CFG, follow_lanes=1)


def _topology():
    """T junction: arm 0 (+x) with two entering lanes, arms at 90 and 180 deg."""
    return Intersection(np.zeros(2), [Arm(0.0, lanes_in=2, lanes_out=1),
                                      Arm(math.pi / 2), Arm(math.pi, lanes_in=1, lanes_out=2)])


def _approach(lat: float, s0: float, radius: float, length: float = 70.0, step: float = 1.0):
    """True center line of an entering lane of arm 0 from its far end to x = 0: straight
    along +x up to ``s0``, beyond it an arc of ``radius`` [m] bending to +y (inf:
    straight), the lane ``lat`` [m] left of the road axis."""
    sig = np.arange(length, 0.0, -step)
    if math.isinf(radius):
        far = np.stack([s0 + sig, np.full_like(sig, lat)], axis=1)
    else:
        a = sig / radius
        axis = np.stack([s0 + radius * np.sin(a), radius * (1 - np.cos(a))], axis=1)
        far = axis + lat * np.stack([-np.sin(a), np.cos(a)], axis=1)
    near = np.stack([np.arange(s0, 0.0, -step), np.full(int(math.ceil(s0 / step)), lat)], 1)
    return np.concatenate([far, near])


def _trajs(lanes, radius, rng, per_lane=6, noise=0.25):
    """Vehicles driving ``lanes`` of arm 0 into the junction and on along arm 2 (-x)."""
    stop = float(stop_distances(_topology(), CFG)[0])
    out = []
    for k in lanes:
        for _ in range(per_lane):
            line = np.concatenate([_approach(LAT[k], stop, radius),
                                   np.stack([-np.arange(1.0, 60.0), np.full(59, LAT[0])], 1)])
            xy = line + rng.normal(0, 0.15, 2) * [0, 1] + rng.normal(0, noise, line.shape)
            tr = Trajectory(len(out), xy)
            tr.split = split_at_center(xy, np.zeros(2))
            tr.lane_in, tr.lane_out = (0, k), (2, 0)
            out.append(tr)
    return out, stop


def _specs(trajs, cfg):
    topo = _topology()
    stops = stop_distances(topo, cfg)
    frames = fit_frames(topo, trajs, stops, cfg)
    specs, _, index = lane_specs(topo, trajs, cfg, stops=stops, frames=frames)
    return specs, index


def _errors(specs, index, stop, radius):
    """Mean distance [m] of each entering lanelet of arm 0 to its true center line."""
    out = []
    for k in (0, 1):
        E = specs[index[(0, 1, k)]]
        truth = _approach(LAT[k], stop, radius, length=150.0, step=0.2)
        out.append(lane_distance(0.5 * (E.left + E.right), truth[truth[:, 0] >= stop - 1]))
    return out


def _connectors_meet(specs):
    for c in (s for s in specs if s.kind == 'connector'):
        E, O = specs[c.predecessor], specs[c.successor]
        assert np.allclose(c.left[0], E.left[-1]) and np.allclose(c.right[0], E.right[-1])
        assert np.allclose(c.left[-1], O.left[0]) and np.allclose(c.right[-1], O.right[0])


def test_curved_approach_follows_the_traffic():
    radius = 140.0                                   # ~29 deg of bend over 70 m
    trajs, stop = _trajs((0, 1), radius, np.random.default_rng(1))
    before = _errors(*_specs(trajs, CFG), stop, radius)
    specs, index = _specs(trajs, ON)
    after = _errors(specs, index, stop, radius)
    assert max(after) < 0.3 and max(after) < 0.25 * min(before), (before, after)
    _connectors_meet(specs)
    # with the common shift alone the lanes keep their width across the bend (borders
    # offset along the curve's normal); per-lane deviations may move each lane a little
    specs, index = _specs(trajs, replace(ON, follow_per_lane=0))
    E = specs[index[(0, 1, 0)]]
    w = np.linalg.norm(E.left - E.right, axis=1)
    assert np.ptp(w) < 0.05, w


def test_straight_approach_stays_straight():
    trajs, _ = _trajs((0, 1), math.inf, np.random.default_rng(2))
    off, _ = _specs(trajs, CFG)
    on, _ = _specs(trajs, ON)
    for a, b in zip(off, on):
        assert np.array_equal(a.left, b.left) and np.array_equal(a.right, b.right), a.id


def test_selection_rejects_a_shift_in_pure_noise():
    rng = np.random.default_rng(3)
    s = rng.uniform(10, 90, 400)
    assert select_offset(s, rng.normal(0, 0.3, 400), 10.0, 90.0, ON) is None
    bent = 0.002 * (s - 10) ** 2                     # 12.8 m at the far end
    fit = select_offset(s, bent + rng.normal(0, 0.3, 400), 10.0, 90.0, ON)
    err = np.abs(fit(s) - bent)
    assert fit is not None and err.max() < 0.1 * bent.max() and err.mean() < 0.15, err
    # the effective degrees of freedom fall with the smoothing penalty
    assert fit_offset(s, bent, 10.0, 90.0, 10.0, 1e4).edf < fit_offset(s, bent, 10.0, 90.0,
                                                                        10.0, 0.0).edf


def test_lane_without_traffic_moves_with_its_neighbour():
    radius = 140.0
    trajs, stop = _trajs((0,), radius, np.random.default_rng(4), per_lane=10)
    before = _errors(*_specs(trajs, CFG), stop, radius)
    specs, index = _specs(trajs, ON)
    after = _errors(specs, index, stop, radius)
    assert after[1] < 0.5 * before[1], (before, after)
    # parallel: lane 1 shares lane 0's outer border and keeps its width
    L0, L1 = specs[index[(0, 1, 0)]], specs[index[(0, 1, 1)]]
    shared = [np.allclose(L1.right, L0.left), np.allclose(L1.left, L0.right)]
    assert any(shared)
    w0 = np.linalg.norm(L0.left - L0.right, axis=1)
    w1 = np.linalg.norm(L1.left - L1.right, axis=1)
    assert np.allclose(w0, w1, atol=0.05)
    _connectors_meet(specs)


def test_compiled_normal_equations_match_the_design_matrix():
    """The banded kernel (``spline._data``, weighted, as the approach fit calls it) gives
    scipy's design-matrix products: points inside, on both
    ends and beyond the knots (clamped), with weights, for short and long axes."""
    from reference.follow import normal_reference
    rng = np.random.default_rng(11)
    for lo, hi, n in ((10.0, 90.0, 11), (0.0, 5.0, 4), (-3.0, 140.0, 17)):
        knots = np.r_[[lo] * 3, np.linspace(lo, hi, n - 2), [hi] * 3]
        s = np.r_[rng.uniform(lo - 5.0, hi + 5.0, 300), lo, hi]
        r, w = rng.normal(0, 1, len(s)), rng.uniform(0, 3, len(s))
        BtB, Btr = _data(r.reshape(-1, 1), s, knots, w)
        Btr = Btr[:, 0]
        ref_BtB, ref_Btr = normal_reference(s, r, w, lo, hi, knots)
        assert np.allclose(BtB, ref_BtB, rtol=1e-12, atol=1e-12)
        assert np.allclose(Btr, ref_Btr, rtol=1e-12, atol=1e-12)


def test_a_bent_arm_reaches_the_lane_step_as_its_chord():
    """The lane step draws straight lanes and bends them itself: a topology arm bent by
    30 deg at 20 m arrives as the straight arm through its axis point 50 m out (angle
    atan2(20 sin 0 + 30 sin 30, 20 + 30 cos 30) from the axis), unbent; an unbent
    topology is passed on as it is."""
    from intersection_estimator.lanes.init import chord_arms
    straight = Intersection(center=np.zeros(2), arms=[Arm(angle=a) for a in (0.0, 2.0, -2.0)])
    assert chord_arms(straight) is straight
    bent = Intersection(center=np.zeros(2), arms=[Arm(angle=0.0, bend=math.radians(30), bend_at=20.0),
                                                  Arm(angle=2.0), Arm(angle=-2.0)])
    out = chord_arms(bent)
    east = min(out.arms, key=lambda a: abs(a.angle))
    want = math.atan2(30 * math.sin(math.radians(30)), 20 + 30 * math.cos(math.radians(30)))
    assert east.angle == pytest.approx(want) and east.bend == 0.0 and east.bend_at == 0.0
    assert [a.angle for a in out.arms if a is not east] == [-2.0, 2.0]


def test_parts_reassigned_along_the_bent_axis():
    """``follow_reassign``: parts that the straight rays gave the neighbouring lane (on a
    bend the mean offset from a straight ray depends on where the part was seen) go back
    to the lane their offset from the shifted axis says, and the lane course improves;
    parts already right stay. Off: the assignment is left as it was."""
    radius = 140.0
    trajs, stop = _trajs((0, 1), radius, np.random.default_rng(5), per_lane=8)
    truth = [tr.lane_in for tr in trajs]
    for tr in trajs[:2] + trajs[8:10]:           # two parts of each lane on the other one
        tr.lane_in = (0, 1 - tr.lane_in[1])
    before = [tr.lane_in for tr in trajs]
    err_off = _errors(*_specs(trajs, replace(ON, follow_reassign=0)), stop, radius)
    assert [tr.lane_in for tr in trajs] == before
    specs, index = _specs(trajs, ON)                # on by default
    assert [tr.lane_in for tr in trajs] == truth
    err_on = _errors(specs, index, stop, radius)
    assert max(err_on) < max(err_off), (err_off, err_on)
    _connectors_meet(specs)


def test_nearest_lanes_measures_along_the_shifted_axis():
    """A part far out on the bend sits metres beside its lane's straight ray but on its
    lane along the shifted axis; a part without points in range is -1."""
    from intersection_estimator.lanes.follow import arm_shift, driven_lanes, nearest_lanes
    from intersection_estimator.lanes.init import arm_frames
    radius = 140.0
    trajs, stop = _trajs((0, 1), radius, np.random.default_rng(6), per_lane=6)
    topo = _topology()
    f = fit_frames(topo, trajs, stop_distances(topo, ON), ON)[0]
    lats = [f.lat[(1, k)] for k in (0, 1)]
    parts = [[tr.xy[:tr.split + 1] for tr in trajs if tr.lane_in == (0, k)] for k in (0, 1)]
    g = arm_shift(f, lats, driven_lanes(parts, f, stop, stop + 70.0, ON), stop, stop + 70.0, ON)
    assert g is not None
    far = [_approach(LAT[k], stop, radius)[:25] for k in (0, 1)]     # 45-70 m out
    straight = [(P - f.origin) @ f.n for P in far]
    assert abs(np.mean(straight[0]) - lats[0]) > abs(lats[1] - lats[0])   # the ray is wrong
    got = nearest_lanes(f, g, lats, far + [np.zeros((0, 2))], stop, stop + 70.0, ON)
    assert got.tolist() == [0, 1, -1]
    assert arm_frames(topo)[0].u @ f.u > 0.99


@settings(max_examples=40, deadline=None)
@given(curv=st.floats(-0.01, 0.01), tilt=st.floats(-0.3, 0.3), seed=st.integers(0, 2**16))
def test_foot_points_on_the_shifted_axis_match_a_dense_search(curv, tilt, seed):
    """``_signed_offsets`` (two Gauss-Newton steps) against the distance to the shifted axis
    drawn as a polyline of 1 cm segments: the same offset (to 1 mm) and station (to 5 cm)
    for points up to 8 m beside bends of up to ~1:1 slope, inside the fitted range."""
    from types import SimpleNamespace
    from intersection_estimator.lanes.follow import _signed_offsets
    rng = np.random.default_rng(seed)
    s = np.linspace(5.0, 95.0, 200)
    g = fit_offset(s, curv * (s - 5.0) ** 2 + tilt * s, 5.0, 95.0, 10.0, 0.0)
    frame = SimpleNamespace(origin=np.array([3.0, -2.0]), u=np.array([0.6, 0.8]),
                            n=np.array([-0.8, 0.6]))
    fine = np.arange(0.0, 100.0, 0.01)
    R = frame.origin + np.multiply.outer(fine, frame.u) + np.multiply.outer(g(fine), frame.n)
    ss, off = rng.uniform(15.0, 85.0, 30), rng.uniform(-8.0, 8.0, 30)
    d = g.slope(ss)
    N = (np.multiply.outer(1.0 / np.sqrt(1 + d * d), frame.n)
         - np.multiply.outer(d / np.sqrt(1 + d * d), frame.u))
    P = frame.origin + np.multiply.outer(ss, frame.u) + np.multiply.outer(g(ss), frame.n) \
        + off[:, None] * N
    s_got, off_got = _signed_offsets(P, frame, g, 5.0, 95.0)
    assert np.allclose(np.abs(off_got), orthogonal_distances(P, R), atol=1e-3)
    assert np.allclose(off_got, off, atol=1e-3) and np.allclose(s_got, ss, atol=0.05)


def test_constant_offset_of_a_lane_beside_the_axis():
    """``select_constant``: a lane's traffic 0.6 m beside the reference curve over part of
    the lane gives a constant 0.6 m everywhere (no slope to continue beyond its points);
    traffic centred on it, or too few points, gives none."""
    from intersection_estimator.lanes.follow import select_constant
    rng = np.random.default_rng(7)
    w = np.full(200, 1.0)
    fit = select_constant(0.6 + rng.normal(0, 0.2, 200), w, ON)
    assert fit is not None
    got = fit(np.array([0.0, 50.0, 500.0]))
    assert np.allclose(got, got[0]) and abs(got[0] - 0.6) < 0.05
    assert select_constant(rng.normal(0, 0.2, 200), w, ON) is None
    assert select_constant(np.full(5, 0.6), np.ones(5), ON) is None
