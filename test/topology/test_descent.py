"""The greedy descent at the end of the schedule (beyond the paper), on its own."""

import copy
import math

import numpy as np
import pytest

from intersection_estimator.topology import TopologyConfig
from intersection_estimator.topology.config import Tables
from intersection_estimator.topology.descent import DESCENT_STEPS, candidates, descend
from intersection_estimator.topology.mcmc import Posterior
from intersection_estimator.topology.state import pack_state, unpack_state

from .scenes import EASY, same_topology, tracked_posterior


def _off_by(gt, k, field, d):
    bad = copy.deepcopy(gt)
    setattr(bad.arms[k], field, getattr(bad.arms[k], field) + d)
    return bad


@pytest.mark.parametrize('field,d', [('lanes_in', 1), ('lanes_out', 1), ('lanes_in', -1)])
def test_descent_repairs_a_lane_count_and_never_lowers_thetracked_posterior(field, d):
    """Left one lane off (and the center shifted by 1 m) the descent finds the true counts
    and does not lose posterior."""
    gt = EASY[0]
    cfg = TopologyConfig(chains_tracked=1)
    post = tracked_posterior(cfg, gt)
    bad = _off_by(gt, 1, field, d)
    bad.center = bad.center + np.array([1.0, 0.0])
    S0 = pack_state(bad)
    before = post(S0)
    assert post(pack_state(gt)) > before        # the scene decides: truth scores higher
    res = descend(S0, cfg, post, np.random.default_rng(5))
    assert res.lpost >= before and res.samples > 0
    assert res.lpost == pytest.approx(post(res.S), abs=1e-6)
    assert same_topology(gt, unpack_state(res.S)), unpack_state(res.S)


def test_descent_off_or_without_observations_returns_the_start_unchanged():
    gt = EASY[1]
    S0 = pack_state(gt)
    for cfg, post in ((TopologyConfig(descent_rounds=0), tracked_posterior(TopologyConfig(), gt)),
                      (TopologyConfig(), Posterior(Tables(TopologyConfig()),
                                                   tracked_posterior(TopologyConfig(), gt).obs.subset(
                                                       np.zeros(0, np.int64))))):
        res = descend(S0, cfg, post, np.random.default_rng(0))
        assert np.array_equal(res.S, S0) and res.samples == 0 and res.lpost == -math.inf


def test_a_passed_deadline_stops_the_candidates_but_keeps_the_first_run():
    """With the deadline already passed only the initial run from the MAP state happens."""
    gt = EASY[0]
    cfg = TopologyConfig()
    post = tracked_posterior(cfg, gt)
    res = descend(pack_state(gt), cfg, post, np.random.default_rng(1), deadline=0.0)
    assert res.samples == cfg.descent_samples


def test_candidates_are_lane_steps_within_bounds_and_removals():
    cfg = TopologyConfig(max_lanes=2)
    gt = EASY[0]                                  # lanes (1,1) (2,1) (1,2) (2,2)
    post = tracked_posterior(cfg, gt)
    S = pack_state(gt)
    cands = list(candidates(S, cfg, post))
    removals = [S2 for S2, k in cands if k < 0]
    assert len(removals) == len(gt.arms)          # 4 arms > min_arms
    for S2, k in cands:
        if k >= 0:
            a, b = gt.arms[k], unpack_state(S2).arms[k]
            step = (b.lanes_in - a.lanes_in, b.lanes_out - a.lanes_out)
            assert step in DESCENT_STEPS
            assert 1 <= min(b.lanes_in, b.lanes_out) and max(b.lanes_in, b.lanes_out) <= 2
    # arm 3 has (2, 2): only steps that lower a count stay within max_lanes = 2
    assert {(unpack_state(S2).arms[3].lanes_in, unpack_state(S2).arms[3].lanes_out)
            for S2, k in cands if k == 3} == {(1, 2), (2, 1)}
