"""Arms proposed where traffic is unexplained (beyond the paper, topology/unexplained.py):
the angle of a missing arm, nothing where every arm is there, the refitted candidate, and
the descent that adds it."""

import copy
import math

import numpy as np
import pytest

from intersection_estimator.topology import TopologyConfig
from intersection_estimator.topology.descent import descend
from intersection_estimator.topology.state import HDR, STRIDE, pack_state, unpack_state
from intersection_estimator.topology.unexplained import unexplained_angles, with_arm

from .scenes import EASY, same_topology, tracked_posterior

CFG = TopologyConfig(chains_tracked=1)


def _without(gt, k):
    bad = copy.deepcopy(gt)
    del bad.arms[k]
    return bad


def _gap_deg(a, b):
    return abs(math.degrees(math.remainder(a - b, 2 * math.pi)))


@pytest.mark.parametrize('gt_index,k', [(0, 1), (0, 3), (1, 0)])
def test_the_missing_arms_traffic_gives_its_angle(gt_index, k):
    gt = EASY[gt_index]
    post = tracked_posterior(CFG, gt)
    angles = unexplained_angles(pack_state(_without(gt, k)), post, CFG)
    assert angles, 'no angle proposed for the missing arm'
    assert _gap_deg(angles[0], gt.arms[k].angle) < 5.0


def test_nothing_where_every_arm_is_there_or_when_off():
    gt = EASY[0]
    post = tracked_posterior(CFG, gt)
    S = pack_state(gt)
    assert unexplained_angles(S, post, CFG) == []
    off = TopologyConfig(chains_tracked=1, descent_add_support=0.0)
    assert unexplained_angles(pack_state(_without(gt, 1)), post, off) == []


def test_an_angle_needs_the_passages():
    """The missing arm's parts are a few passages: a support above them proposes nothing."""
    gt = EASY[0]
    post = tracked_posterior(CFG, gt)
    S = pack_state(_without(gt, 1))
    assert unexplained_angles(S, post, CFG)
    many = TopologyConfig(chains_tracked=1, descent_add_support=1e4)
    assert unexplained_angles(S, post, many) == []


def test_with_arm_refits_the_new_arm_to_its_traffic():
    gt = EASY[0]
    k = 3                                          # lanes (2, 2)
    post = tracked_posterior(CFG, gt)
    S = pack_state(_without(gt, k))
    S2, L2 = with_arm(S, gt.arms[k].angle, post, CFG.lane_width)
    new = unpack_state(S2).arms[-1]
    assert (new.lanes_in, new.lanes_out) == (gt.arms[k].lanes_in, gt.arms[k].lanes_out)
    assert L2 == pytest.approx(post(S2), abs=1e-6) and L2 > post(S)
    # with the columns of S at hand only the new arm's is computed: the same state
    _, C = post.loglik(S)
    C0 = C.copy()
    S3, L3 = with_arm(S, gt.arms[k].angle, post, CFG.lane_width, C)
    assert np.array_equal(S3, S2) and L3 == pytest.approx(L2, abs=1e-9)
    assert np.array_equal(C, C0)
    n = len(gt.arms) - 1                           # the other arms and the center unchanged
    assert np.array_equal(S2[:HDR + n * STRIDE], np.r_[S[:2], n + 1, S[3:HDR + n * STRIDE]])


@pytest.mark.parametrize('k', [1, 3])
def test_descent_adds_the_missing_arm_and_not_when_off(k):
    """From the truth minus one arm the descent ends at the truth's topology with the
    proposal on; off, it cannot add an arm (its candidates only change or remove)."""
    gt = EASY[0]
    post = tracked_posterior(CFG, gt)
    S0 = pack_state(_without(gt, k))
    before = post(S0)
    res = descend(S0, CFG, post, np.random.default_rng(5))
    assert res.lpost > before
    assert same_topology(gt, unpack_state(res.S)), unpack_state(res.S)
    off = TopologyConfig(chains_tracked=1, descent_add_support=0.0)
    res_off = descend(S0, off, post, np.random.default_rng(5))
    assert len(unpack_state(res_off.S).arms) == len(gt.arms) - 1


@pytest.mark.parametrize('offset', [9.0, -9.0])
def test_an_arm_nine_metres_beside_the_center_is_reached(offset):
    """A stem that meets the main road 9 m beside the point where the other arms' axes
    cross (inD's net 2: its -67 deg road, 9.5 m beside the center the rest of the traffic
    fixes), four vehicles a lane: the refitted candidate lies on its traffic. With an
    offset bound of 6 m it cannot, and the grid settles on other lanes at another offset."""
    gt = copy.deepcopy(EASY[0])
    k = 1
    gt.arms[k].offset = offset
    S = pack_state(_without(gt, k))
    for cfg, ok in ((CFG, True), (TopologyConfig(chains_tracked=1, arm_offset_max=6.0), False)):
        post = tracked_posterior(cfg, gt, per_lane=4)
        S2, _ = with_arm(S, gt.arms[k].angle, post, cfg.lane_width)
        new = min(unpack_state(S2).arms, key=lambda a: _gap_deg(a.angle, gt.arms[k].angle))
        on_traffic = abs(new.offset - offset) < 0.5 and \
            (new.lanes_in, new.lanes_out) == (gt.arms[k].lanes_in, gt.arms[k].lanes_out)
        assert on_traffic == ok, (cfg.arm_offset_max, new)
