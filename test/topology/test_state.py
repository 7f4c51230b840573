"""Packed state layout: named slots, pack / unpack, the chain container, state geometry."""

import math

import numpy as np
import pytest

from intersection_estimator.model import Arm, Intersection
from intersection_estimator.topology.state import (ANG, CX, CY, GAP, HDR, MAXA, NARMS, NIN, NOUT,
                                                   STATE_LEN, STRIDE, WID, Chain, arm_angles,
                                                   arm_rows, largest_gap, pack_state,
                                                   separation_ok, unpack_state, wrap)

INTER = Intersection(center=np.array([1.0, 2.0]),
                     arms=[Arm(angle=0.5, gap=1.0, lanes_in=2, lanes_out=3, lane_width=3.2),
                           Arm(angle=-2.0, gap=0.0, lanes_in=1, lanes_out=1, lane_width=3.6)])


def test_pack_unpack_round_trip():
    back = unpack_state(pack_state(INTER))
    assert np.allclose(back.center, INTER.center)
    for a, b in zip(INTER.arms, back.arms):
        assert (a.lanes_in, a.lanes_out) == (b.lanes_in, b.lanes_out)
        assert math.isclose(a.angle, b.angle) and math.isclose(a.gap, b.gap)
        assert math.isclose(a.lane_width, b.lane_width)


def test_named_slots_hold_what_their_names_say():
    S = pack_state(INTER)
    assert S.shape == (STATE_LEN,) and (S[CX], S[CY], S[NARMS]) == (1.0, 2.0, 2.0)
    for k, a in enumerate(INTER.arms):
        i = HDR + k * STRIDE
        assert (S[i + ANG], S[i + GAP], S[i + NIN], S[i + NOUT], S[i + WID]) == (
            a.angle, a.gap, a.lanes_in, a.lanes_out, a.lane_width)
    assert arm_rows(S).shape == (2, STRIDE)
    assert np.array_equal(arm_angles(S), [a.angle for a in INTER.arms])
    conf = unpack_state(S, -1, confidence=[0.2, 0.9])
    assert conf.traffic_side == -1 and [a.confidence for a in conf.arms] == [0.2, 0.9]


def test_too_many_arms_are_refused():
    inter = Intersection(center=np.zeros(2), arms=[Arm(angle=0.1 * k) for k in range(MAXA + 1)])
    with pytest.raises(ValueError, match='at most'):
        pack_state(inter)


def test_chain_start():
    S = pack_state(INTER)
    c = Chain.start(S, 5, 7)
    assert c.C.shape == (MAXA, 5) and c.stats.shape == (14,) and c.step == 0
    assert c.best_lpost == -math.inf and c.S is not S and np.array_equal(c.best_S, S)


def test_state_geometry():
    assert wrap(math.pi) == -math.pi and math.isclose(wrap(3 * math.pi / 2), -math.pi / 2)
    S = pack_state(Intersection(center=np.zeros(2),
                                arms=[Arm(angle=0.0), Arm(angle=0.3), Arm(angle=math.pi)]))
    assert not separation_ok(S, 0, 0.5) and separation_ok(S, 2, 0.5)
    start, width = largest_gap(S)
    assert math.isclose(start, math.pi) and math.isclose(width, math.pi)
