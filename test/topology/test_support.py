"""The reported estimate: arms that explain too few vehicle passages are left out."""

import copy
import math

import numpy as np
import pytest

from intersection_estimator.model import Arm
from intersection_estimator.observations import Detections
from intersection_estimator.topology import TopologyConfig, TopologyEstimator
from intersection_estimator.topology.config import Tables
from intersection_estimator.topology.mcmc import Posterior
from intersection_estimator.topology.state import pack_state
from intersection_estimator.topology.support import arm_support, reported

from .scenes import EASY, scene


def _stray_scene():
    """EASY[1] plus one radial false track at -40 deg, and the truth with that extra arm."""
    gt = EASY[1]
    u = np.array([math.cos(math.radians(-40.0)), math.sin(math.radians(-40.0))])
    xy = gt.center + np.outer(np.linspace(12.0, 40.0, 30), u) + np.array([-u[1], u[0]]) * 1.75
    stray = Detections.make(xy, np.arange(30) * 0.1, heading=math.atan2(-u[1], -u[0]),
                            track_id=999, speed=8.0)
    dets = Detections.concat([scene(gt, 'tracked', seed=1), stray])
    extra = copy.deepcopy(gt)
    extra.arms.append(Arm(angle=math.radians(-40.0), gap=0.0, lanes_in=1, lanes_out=1,
                          lane_width=3.5))
    return gt, dets, extra


@pytest.mark.parametrize('support,kept', [(2.5, 0), (0.0, 1)])
def test_an_arm_explaining_fewer_passages_than_min_arm_support_is_not_reported(support, kept):
    """One radial false track makes an arm pay for its prior (clutter floor); the
    reported estimate leaves it out, and its log posterior is that of what it reports."""
    gt, dets, extra = _stray_scene()
    cfg = TopologyConfig(min_arm_support=support, chains_tracked=1)
    est = TopologyEstimator(cfg, seed=0)
    est.set_observations(dets)
    post = Posterior(Tables(cfg), est.observations)
    S = pack_state(extra)
    sup = arm_support(post, S, cfg.clutter_floor)
    assert sup[-1] < 2.5 <= sup[:-1].min()          # the stray arm: one passage or two
    R, conf, lpost = reported(post, S, post(S), cfg)
    assert int(R[2]) == len(gt.arms) + kept
    assert lpost == pytest.approx(post(R))
    assert conf.shape == (int(R[2]),) and np.all((0 < conf) & (conf < 1))


def test_support_never_drops_below_min_arms():
    gt, dets, extra = _stray_scene()
    cfg = TopologyConfig(min_arm_support=1e9, min_arms=3, chains_tracked=1)
    est = TopologyEstimator(cfg, seed=0)
    est.set_observations(dets)
    post = Posterior(Tables(cfg), est.observations)
    R, _, _ = reported(post, pack_state(extra), 0.0, cfg)
    assert int(R[2]) == 3
