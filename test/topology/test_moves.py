"""Moves of Algorithm 1: validity and reversibility with consistent Hastings factors."""

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from intersection_estimator.model import Arm, Intersection
from intersection_estimator.topology import TopologyConfig
from intersection_estimator.topology.config import Tables
from intersection_estimator.topology.mcmc import run_chain
from intersection_estimator.topology.moves import (ADD_ARM, BEND_MOVE, CHANGE_GAP, LANE,
                                                   MOVE_NAMES, OFFSET, REMOVE_ARM, ROTATE, SHIFT,
                                                   WIDTH)
from intersection_estimator.topology.state import (GAP, HDR, MAXA, NIN, NOUT, P_FOCUS,
                                                   P_FOCUS_P, STRIDE, WID, arm_rows,
                                                   pack_state)
from reference.moves import is_valid, proposal_log_density, propose_kind, propose_move

from .strategies import states

# The arm-axis offset (arm_offset.py) and the bend (arm_bend.py) on, so that every move
# kind and the add-arm draws are covered; off, their moves are never picked.
OFF_MAX = 6.0
BEND_MAX = 30.0
CFG = TopologyConfig(arm_offset_max=OFF_MAX, arm_bend_max_deg=BEND_MAX)
TAB = Tables(CFG)
P = TAB.P
SET = settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def _lq(S_from, S_to, kind):
    return proposal_log_density(S_from, S_to, kind, P, TAB.logqn)


@SET
@given(states(OFF_MAX, BEND_MAX))
def test_generated_states_are_valid(S):
    assert is_valid(S, P)


@SET
@given(states(OFF_MAX, BEND_MAX), st.sampled_from(range(len(MOVE_NAMES))), st.integers(0, 2 ** 31 - 2))
def test_every_move_keeps_the_model_valid(S, kind, seed):
    ok, lq, S2 = propose_move(S, kind, P, TAB.logqn, seed)
    if ok:
        assert is_valid(S2, P), MOVE_NAMES[kind]
        assert math.isfinite(lq)


@SET
@given(states(OFF_MAX, BEND_MAX), st.sampled_from([ROTATE, SHIFT, CHANGE_GAP, WIDTH, OFFSET,
                                                    BEND_MOVE]),
       st.integers(0, 2 ** 31 - 2))
def test_continuous_moves_are_symmetric(S, kind, seed):
    ok, lq, S2 = propose_move(S, kind, P, TAB.logqn, seed)
    if not ok:
        return
    assert lq == 0.0
    changed = np.flatnonzero(S2 != S)
    if kind == SHIFT:
        assert set(changed) <= {0, 1}
        assert np.hypot(*(S2[:2] - S[:2])) <= CFG.shift_max + 1e-9
    else:
        assert len(changed) <= 1   # one parameter of one arm
        if len(changed):
            i = changed[0]
            step = {ROTATE: math.radians(CFG.rotate_max_deg), CHANGE_GAP: CFG.gap_step,
                    WIDTH: CFG.width_step, OFFSET: CFG.offset_step,
                    BEND_MOVE: max(math.radians(CFG.bend_step_deg), CFG.bend_at_step)}[kind]
            d = S2[i] - S[i]
            if kind == ROTATE:
                d = (d + math.pi) % (2 * math.pi) - math.pi
            assert abs(d) <= step + 1e-9    # the reverse step lies in the same range
    assert _lq(S, S2, kind) == _lq(S2, S, kind)


def _apply_lane_op(S, k, entering, add, variant):
    """-> (S2, log Hastings ratio) of lane-move variant 0 border, 1 median, 2 rescale."""
    S2 = S.copy()
    i = HDR + k * STRIDE
    j = i + (NIN if entering else NOUT)
    S2[j] += 1 if add else -1
    if variant == 1:
        S2[i + GAP] += -S[i + WID] if add else S[i + WID]
    if variant == 2:     # same road width: w' = w n / n', Jacobian n / n'
        if S2[j] < 1:
            return S2, math.nan    # no such proposal (matches nothing)
        S2[i + WID] = S[i + WID] * S[j] / S2[j]
        return S2, math.log(S[j] / S2[j])
    return S2, 0.0


@SET
@given(states(OFF_MAX, BEND_MAX), st.integers(0, 2 ** 31 - 2))
def test_lane_move_has_its_reverse(S, seed):
    ok, lq, S2 = propose_move(S, LANE, P, TAB.logqn, seed)
    if not ok:
        return
    found = False
    for k in range(int(S[2])):
        for entering in (True, False):
            for add in (True, False):
                for variant in (0, 1, 2):
                    fwd, lq_f = _apply_lane_op(S, k, entering, add, variant)
                    if np.allclose(fwd, S2, atol=1e-12) and abs(lq - lq_f) < 1e-12:
                        back, lq_b = _apply_lane_op(S2, k, entering, not add, variant)
                        assert np.allclose(back, S, atol=1e-9)
                        assert abs(lq_f + lq_b) < 1e-12   # ratios of a pair cancel
                        found = True
    assert found


def test_lane_move_rescale_keeps_road_width():
    """The rescale variant is proposed and keeps lanes x width of the changed direction
    (4 -> 5 and 5 -> 6 lanes of 3.5 m stay within [w_min, w_max])."""
    arms = [Arm(angle=a, gap=1.0, lanes_in=4, lanes_out=5, lane_width=3.5)
            for a in (0.0, math.pi / 2, math.pi, -math.pi / 2)]
    S = pack_state(Intersection(center=np.zeros(2), arms=arms))
    seen = 0
    for seed in range(400):
        ok, lq, S2 = propose_move(S, LANE, P, TAB.logqn, seed)
        if not ok or lq == 0.0:
            continue
        rows, rows2 = arm_rows(S), arm_rows(S2)
        k = int(np.flatnonzero(np.any(rows != rows2, axis=1))[0])
        for q in (2, 3):
            if rows2[k, q] != rows[k, q]:
                assert rows2[k, q] * rows2[k, 4] == pytest.approx(rows[k, q] * rows[k, 4])
                assert lq == pytest.approx(math.log(rows[k, q] / rows2[k, q]))
        assert rows2[k, 1] == rows[k, 1]
        seen += 1
    assert seen > 10


@SET
@given(states(OFF_MAX, BEND_MAX), st.integers(0, 2 ** 31 - 2))
def test_add_arm_ratio_matches_reference(S, seed):
    ok, lq, S2 = propose_move(S, ADD_ARM, P, TAB.logqn, seed)
    if not ok:
        return
    n2 = int(S2[2])
    assert n2 == int(S[2]) + 1
    assert np.array_equal(S2[:HDR + (n2 - 1) * STRIDE][3:], S[3:HDR + (n2 - 1) * STRIDE])
    expect = _lq(S2, S, REMOVE_ARM) - _lq(S, S2, ADD_ARM)
    assert abs(lq - expect) < 1e-9


@SET
@given(states(OFF_MAX, BEND_MAX), st.integers(0, 2 ** 31 - 2))
def test_remove_arm_ratio_matches_reference(S, seed):
    ok, lq, S2 = propose_move(S, REMOVE_ARM, P, TAB.logqn, seed)
    n = int(S[2])
    if n <= CFG.min_arms:
        assert not ok
        return
    rows, rows2 = arm_rows(S), arm_rows(S2)
    assert len(rows2) == n - 1
    missing = [r for r in rows if not any(np.array_equal(r, q) for q in rows2)]
    assert len(missing) == 1
    # the reverse proposal: add exactly the removed arm to S2
    S_back = S2.copy()
    S_back[HDR + (n - 1) * STRIDE: HDR + n * STRIDE] = missing[0]
    S_back[2] = n
    rev = _lq(S2, S_back, ADD_ARM)
    if not ok:
        assert rev == -math.inf     # rejected only when the add move cannot propose it
        return
    assert abs(lq - (rev - _lq(S, S2, REMOVE_ARM))) < 1e-9
    assert sorted(map(tuple, arm_rows(S_back))) == sorted(map(tuple, rows))


def test_add_then_remove_round_trip_is_detailed_balance_consistent():
    """Along a forward/backward pair the two log ratios cancel exactly."""
    rng = np.random.default_rng(3)
    S = pack_state(Intersection(center=np.zeros(2), arms=[Arm(angle=0.0), Arm(angle=2.0)]))
    hits = 0
    for seed in rng.integers(0, 2 ** 31 - 2, 200):
        ok, lq_add, S2 = propose_move(S, ADD_ARM, P, TAB.logqn, int(seed))
        if not ok:
            continue
        S_rm = S2.copy()
        lq_rm = None
        for s2 in range(200):   # find the removal of the added arm (slot 2)
            ok2, lq, S3 = propose_move(S2, REMOVE_ARM, P, TAB.logqn, s2)
            if ok2 and np.array_equal(S3[:HDR + 2 * STRIDE], S[:HDR + 2 * STRIDE]) \
                    and int(S3[2]) == 2:
                S_rm, lq_rm = S3, lq
                break
        assert lq_rm is not None
        assert abs(lq_add + lq_rm) < 1e-9
        assert np.array_equal(S_rm[:HDR + 2 * STRIDE], S[:HDR + 2 * STRIDE])
        hits += 1
    assert hits > 50


@pytest.mark.parametrize('offset_max,bend_max', [(0.0, 0.0), (OFF_MAX, 0.0), (0.0, 30.0),
                                                 (OFF_MAX, 30.0)])
def test_move_frequencies_follow_algorithm_1(offset_max, bend_max):
    """omega ~ U[0,1] picks the paper's moves with their probabilities (+ width, + offset
    and + bend when they are on; never when they are off)."""
    cfg = TopologyConfig(arm_offset_max=offset_max, arm_bend_max_deg=bend_max)
    tab = Tables(cfg)
    S = pack_state(Intersection(center=np.zeros(2), arms=[Arm(angle=a) for a in (0.0, 2.0, -2.0)]))
    C = np.zeros((MAXA, 0))
    stats = np.zeros(2 * len(MOVE_NAMES), np.int64)
    z = np.zeros(0)
    n = 20000
    run_chain(S.copy(), C, 0.0, 0.0, S.copy(), -np.inf, tab.P, tab.logPA, tab.logPn,
              tab.arm_const, tab.logqn, tab.cumqn, z, z, z, z, np.zeros(0, np.bool_), z, z, z,
              z, n, np.ones(n), 1, stats, np.zeros(6, np.int64), False)
    counts = stats[0::2] / n
    p = np.array([cfg.p_rotate, cfg.p_shift, cfg.p_gap, cfg.p_arm / 2, cfg.p_arm / 2,
                  cfg.p_lane, cfg.p_width, cfg.p_offset if offset_max > 0 else 0.0,
                  cfg.p_bend if bend_max > 0 else 0.0])
    p = p / p.sum()
    assert np.all(np.abs(counts - p) < 0.015), (counts, p)
    if offset_max == 0.0:
        assert counts[OFFSET] == 0.0


@SET
@given(states(OFF_MAX, BEND_MAX), st.sampled_from([ROTATE, CHANGE_GAP, WIDTH, OFFSET]), st.integers(0, 2 ** 31 - 2),
       st.integers(0, 7))
def test_focused_arm_moves_change_the_focus_arm_and_stay_symmetric(S, kind, seed, focus):
    """The descent's focus (``P_FOCUS``): with probability 1 every arm move picks that slot
    (slots beyond the arm count fall back to a uniform pick); the arm choice never depends
    on the state, so the move keeps Hastings factor 0."""
    n = int(S[2])
    Pf = P.copy()
    Pf[P_FOCUS], Pf[P_FOCUS_P] = focus, 1.0
    S2 = np.empty_like(S)
    ok, lq, k = propose_kind(S, S2, Pf, TAB.logqn, TAB.cumqn, kind, seed)
    assert lq == 0.0
    if focus < n:
        assert k == focus
        changed = np.flatnonzero(S2 != S)
        assert all(HDR + focus * STRIDE <= i < HDR + (focus + 1) * STRIDE for i in changed)
    else:
        assert 0 <= k < n


P_LAPLACE = Tables(TopologyConfig(arm_offset_max=OFF_MAX, arm_offset_prior='laplace')).P


@SET
@given(states(OFF_MAX, BEND_MAX), st.integers(0, 2 ** 31 - 2))
def test_add_arm_ratio_with_the_laplace_offset_prior(S, seed):
    """The add-arm move's log ratio with the Laplace offset draw is the reverse removal's
    proposal density over the forward one's, under the same prior kind."""
    ok, lq, S2 = propose_move(S, ADD_ARM, P_LAPLACE, TAB.logqn, seed)
    if not ok:
        return
    expect = (proposal_log_density(S2, S, REMOVE_ARM, P_LAPLACE, TAB.logqn)
              - proposal_log_density(S, S2, ADD_ARM, P_LAPLACE, TAB.logqn))
    assert abs(lq - expect) < 1e-9
