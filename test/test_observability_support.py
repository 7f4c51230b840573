"""Per-arm / per-lane support (vehicle passages, confidence) in the estimate (issue 15)."""

from __future__ import annotations

import json
import math

import pytest

from intersection_estimator.estimate_io import dumps, estimate_to_dict, parse_estimate
from intersection_estimator.pipeline import estimate
from intersection_estimator.sim import simulate_scenario
from intersection_estimator.tracking import TrackerConfig


@pytest.fixture(scope='module')
def tracked():
    sc = simulate_scenario(5)
    return sc, estimate(sc.detections('tracked'), mode='tracked', topology_samples=1500,
                        lane_samples=2000, seed=0)


def test_lane_support_counts_the_trajectories_and_sets_confidence(tracked):
    sc, res = tracked
    lanes = {ll.id: ll for ll in res.lanelets}
    assert all(ll.support >= 1 for ll in lanes.values() if ll.kind != 'connector')
    for ll in lanes.values():
        assert ll.confidence == pytest.approx(1 - math.exp(-ll.support / 3))
    # a trajectory on a connector also counts on the lanes it joins
    for ll in lanes.values():
        if ll.kind == 'connector':
            into = [e for e in lanes.values() if ll.id in e.successors]
            assert into and into[0].support >= ll.support
            assert lanes[ll.successors[0]].support >= ll.support
    # the arms' passages are those of their lanes
    for i, arm in enumerate(res.intersection.arms):
        own = sum(ll.support for ll in lanes.values() if ll.kind != 'connector' and ll.arm == i)
        assert arm.support == own > 0
    # roughly one entering and one leaving part per vehicle
    true_vehicles = len(sc.tracks)
    assert 0.8 * 2 * true_vehicles <= sum(a.support for a in res.intersection.arms) \
        <= 2 * true_vehicles + 20


def test_support_round_trips_through_estimate_json(tracked):
    _, res = tracked
    doc = json.loads(dumps(estimate_to_dict(res.intersection, res.lanelets, res.stats())))
    assert all('support' in a for a in doc['arms']) and all('support' in x for x in doc['lanes'])
    inter, lanes, _ = parse_estimate(doc)
    assert [a.support for a in inter.arms] == [a.support for a in res.intersection.arms]
    assert sorted(ll.support for ll in lanes) == sorted(ll.support for ll in res.lanelets)


def test_raw_arms_get_the_passages_behind_their_confidence():
    """The paper's raw model (radar tracker off): voxels, no passages per lane."""
    sc = simulate_scenario(5)
    res = estimate(sc.detections('raw'), mode='raw', topology_samples=1500, seed=0,
                   tracker_config=TrackerConfig(enabled=False))
    for arm in res.intersection.arms:
        assert arm.support > 0
        assert 1 - math.exp(-arm.support / 3) == pytest.approx(arm.confidence, abs=1e-9)
    for ll in res.lanelets:
        assert ll.support == 0 and ll.confidence == res.intersection.arms[ll.arm].confidence


def test_radar_tracks_give_the_lanes_their_passages():
    """With the radar tracker (default) raw radar has trajectories: lanes count passages."""
    sc = simulate_scenario(5)
    res = estimate(sc.detections('raw'), mode='raw', topology_samples=1500, lane_samples=500, seed=0)
    assert sum(ll.support for ll in res.lanelets) > 0
    assert all(a.support > 0 for a in res.intersection.arms)
