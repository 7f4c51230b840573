"""The reported estimate: arms that explain too few vehicle passages are left out."""

import copy
from dataclasses import replace
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


def test_an_arm_that_explains_nothing_and_no_track_drove_is_left_out():
    """The MAP's arm with no passage and no track along it next to the box (a junk side
    reaching onto another approach) is left out; the same arm with one vehicle driving it
    stays; ``min_arms`` still holds."""
    from intersection_estimator.topology.side_by_side import tracks_of
    from intersection_estimator.topology.support import drop_empty_arms
    from .test_weak_arms import CFG, GT, _dets, _lone_vehicle, _posterior
    S = pack_state(GT)                                   # four arms, arm LONE undriven
    dets = _dets()
    post, tr = _posterior(dets), tracks_of(dets)
    sup = arm_support(post, S, CFG.clutter_floor)
    R, sup2 = drop_empty_arms(post, S, sup, CFG, tr)
    assert int(R[2]) == 3 and len(sup2) == 3
    assert drop_empty_arms(post, S, sup, replace(CFG, min_arms=4), tr)[0] is S
    assert int(reported(post, S, post(S), replace(CFG, empty_arm_drop=True), tr)[0][2]) == 3
    driven = _dets([_lone_vehicle])
    post, tr = _posterior(driven), tracks_of(driven)
    sup = arm_support(post, S, CFG.clutter_floor)
    assert drop_empty_arms(post, S, sup, CFG, tr)[0] is S


def test_a_window_of_radar_tracker_tracks_leaves_no_empty_arm_out():
    """The radar tracker's tracks break next to the box: real arms look empty there, so
    such a window reports its arms as the MAP and the counts leave them."""
    from intersection_estimator.tracking.tracker import RADAR_TRACK_ID0
    from .test_weak_arms import CFG, _dets
    dets = _dets()
    est = TopologyEstimator(replace(CFG, empty_arm_drop=True), seed=0)
    est.set_observations(dets)
    assert est._window_cfg.empty_arm_drop
    est.set_observations(replace(dets, track_id=dets.track_id + RADAR_TRACK_ID0))
    assert not est._window_cfg.empty_arm_drop
