"""Prior P(I) = P(|A|) P(|L|) (paper §II-C1)."""

import math

import numpy as np
import pytest
from hypothesis import given, settings

from intersection_estimator.model import Arm, Intersection
from intersection_estimator.topology import TopologyConfig
from intersection_estimator.topology.config import Tables
from intersection_estimator.topology.prior import (ARM_COUNT_PRIOR, LANE_COUNT_PRIOR,
                                                   arm_log_const, count_log_table, log_prior)
from intersection_estimator.topology.state import MAXA, arm_rows, pack_state
from reference.prior import log_prior_reference

from .strategies import states

TAB = Tables(TopologyConfig())


def test_default_tables_are_distributions():
    for t in (ARM_COUNT_PRIOR, LANE_COUNT_PRIOR):
        assert math.isclose(sum(t), 1.0, abs_tol=1e-5)
        assert min(t) >= 0 and t[0] == 0.0
    assert len(ARM_COUNT_PRIOR) == MAXA + 1


def test_priors_favour_fewer_lanes_but_allow_benchmark_counts():
    p = LANE_COUNT_PRIOR
    assert p[1] > p[2] > p[3] >= p[4] > p[5]
    assert p[4] > 0.05                               # 4 lanes are not unlikely a priori
    mean_arms = sum(i * q for i, q in enumerate(ARM_COUNT_PRIOR))
    assert 2.5 < mean_arms < 4.0                     # between real world (2.5) and Table I (4)


def test_count_table_renormalises_on_bounds():
    t = count_log_table(LANE_COUNT_PRIOR, 1, 4, 7)
    assert math.isclose(np.exp(t[1:5]).sum(), 1.0)
    assert np.all(np.isneginf(t[[0, 5, 6]]))


@settings(max_examples=60, deadline=None)
@given(states())
def test_compiled_prior_equals_reference(S):
    rows = arm_rows(S)
    ref = log_prior_reference(rows[:, 2], rows[:, 3], TAB.logPA, TAB.logPn, TAB.arm_const)
    assert abs(log_prior(S, TAB.logPA, TAB.logPn, TAB.arm_const) - ref) < 1e-9


def test_prior_is_permutation_invariant_and_penalises_lanes():
    a = [Arm(0.0, lanes_in=1, lanes_out=2), Arm(2.0, lanes_in=3, lanes_out=1), Arm(-2.0)]
    S1 = pack_state(Intersection(np.zeros(2), a))
    S2 = S1.copy()
    rows = arm_rows(S2)
    rows[:] = rows[::-1].copy()
    lp = log_prior(S1, TAB.logPA, TAB.logPn, TAB.arm_const)
    assert math.isclose(lp, log_prior(S2, TAB.logPA, TAB.logPn, TAB.arm_const))
    a[0].lanes_in = 4
    assert log_prior(pack_state(Intersection(np.zeros(2), a)), TAB.logPA, TAB.logPn,
                       TAB.arm_const) < lp


def test_arm_constant_is_the_uniform_densities():
    c = arm_log_const(4.0, 3.0, 3.5, True)
    assert math.isclose(c, -math.log(2 * math.pi * 4.0 * 0.5))
    assert math.isclose(arm_log_const(4.0, 3.0, 3.5, False), -math.log(2 * math.pi * 4.0))


@pytest.mark.parametrize('field,value', [('arm_count_prior', (0.0,) * (MAXA + 1)),
                                         ('lane_count_prior', (1.0, 0.0, 0.0)),
                                         ('arm_count_prior', (0.5, 0.5))])
def test_invalid_prior_tables_are_rejected(field, value):
    with pytest.raises(ValueError, match=field):
        TopologyConfig(**{field: value}).validate()
