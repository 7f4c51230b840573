"""Lane-graph ground truth and the traffic-following floor on a hand-made lane graph:
a T junction whose south approach gains a turn pocket before the stop line."""

import math

import numpy as np
import pytest

from intersection_estimator.evaluate import lane_distance
from intersection_estimator.scenarios.floor import (label_points, match_segments, traffic_counts,
                                                    traffic_line)
from intersection_estimator.scenarios.lanegraph import Segment, gt_from_lane_graph


def _line(a, b, n=20):
    return np.linspace(a, b, n)


def _graph():
    """Arms east (0 deg), west (180 deg), south (-90 deg); right-hand traffic, 3.5 m lanes.
    South entering: one lane 'sU' far out, splitting into 'sA' (through... left) and 'sB'
    (right turn) 40 m before the stop line."""
    w = 3.5
    segs = {
        'eI': Segment('eI', _line([80, 1.75], [10, 1.75])), 'eO': Segment('eO', _line([10, -1.75], [80, -1.75])),
        'wI': Segment('wI', _line([-80, -1.75], [-10, -1.75])), 'wO': Segment('wO', _line([-10, 1.75], [-80, 1.75])),
        'sU': Segment('sU', _line([1.75, -100], [1.75, -50])),
        'sA': Segment('sA', _line([1.75, -50], [1.75, -10])),
        'sB': Segment('sB', _line([1.75, -50], [5.25, -10])),
        'sO': Segment('sO', _line([-1.75, -10], [-1.75, -80])),
    }
    for s in segs.values():
        s.width = w
    con = {'c1': ('eI', 'wO'), 'c2': ('wI', 'eO'), 'c3': ('sA', 'wO'), 'c4': ('sB', 'eO'),
           'c5': ('eI', 'sO'), 'c6': ('wI', 'sO')}
    for cid, (a, b) in con.items():
        segs[cid] = Segment(cid, np.stack([segs[a].center[-1], segs[b].center[0]]), width=w,
                            preds=[a], succs=[b], connector=True)
        segs[a].succs.append(cid)
        segs[b].preds.append(cid)
    segs['sU'].succs = ['sA', 'sB']
    segs['sA'].preds = segs['sB'].preds = ['sU']
    return segs


def test_gt_from_lane_graph_arms_lanes_connectors():
    gt = gt_from_lane_graph(_graph(), arm_length=60.0)
    arms = gt.intersection.arms
    angles = sorted(math.degrees(a.angle) for a in arms)
    assert angles == pytest.approx([-180, -90, 0], abs=5)     # sorted like Intersection.arms
    south = next(i for i, a in enumerate(arms) if abs(math.degrees(a.angle) + 90) < 5)
    assert (arms[south].lanes_in, arms[south].lanes_out) == (2, 1)      # the pocket counts
    assert sum(ll.kind == 'connector' for ll in gt.lanelets) == 6
    by_id = {ll.id: ll for ll in gt.lanelets}
    # both south lanes grew back through the shared upstream segment
    for k in (0, 1):
        assert gt.segments_of[f'a{south}_in{k}'][0] == 'sU'
    # lane 0 is next to the median: the straight one ('sA', x = 1.75), lane 1 the pocket
    assert by_id[f'a{south}_in0'].center[-1][0] == pytest.approx(1.75)
    assert by_id[f'a{south}_in1'].center[-1][0] == pytest.approx(5.25)
    for ll in gt.lanelets:
        if ll.kind == 'connector':
            assert ll.successors and by_id[ll.successors[0]].kind == 'leaving'
    with pytest.raises(ValueError, match='no connector'):
        gt_from_lane_graph({'x': Segment('x', _line([0, 0], [10, 0]))})


def test_traffic_line_follows_the_points():
    lane = _line([0.0, 0.0], [60.0, 0.0], 61)
    rng = np.random.default_rng(0)
    x = rng.uniform(5, 55, 3000)
    pts = np.stack([x, 0.3 + rng.normal(0, 1.0, len(x))], axis=1)
    tl = traffic_line(lane, pts)
    assert lane_distance(tl, lane) == pytest.approx(0.3, abs=0.05)
    assert tl[:, 0].min() > 2.0 and tl[:, 0].max() < 58.0     # only where points support it
    assert traffic_line(lane, pts[:1]) is None


def test_labels_follow_the_vehicles_connector():
    segs = _graph()
    gt = gt_from_lane_graph(segs, arm_length=60.0)
    south = next(i for i, a in enumerate(gt.intersection.arms)
                 if abs(math.degrees(a.angle) + 90) < 5)
    # vehicle 'v' drives sU -> sB -> c4 -> eO; vehicle 'u' only sU (left the scene)
    seg = np.array(['sU', 'sU', 'sB', 'c4', 'eO', 'eO', 'sU', 'sU', 'sU'])
    veh = np.array(['v'] * 6 + ['u'] * 3)
    lab = label_points(seg, veh, gt)
    pocket = f'a{south}_in1'
    assert list(lab[:3]) == [pocket] * 3                   # shared 'sU' -> the pocket lane
    assert lab[3].startswith('c_') and lab[4] == lab[5] != ''
    assert list(lab[6:]) == [''] * 3                       # two lanes own 'sU': undecided
    counts = traffic_counts(gt.lanelets, lab, veh, min_points=2)
    assert counts[pocket] == 1 and counts[f'a{south}_in0'] == 0


def test_labels_where_connectors_share_their_first_pieces():
    """An inD ring: the turn to arm 2 and the one to arm 0 run through the same two pieces
    ('j5', 'link') and part at the next node ('j2a' / 'j2b'); the parting piece decides."""
    from types import SimpleNamespace as L
    lls = [L(id='a1_in0', kind='entering', successors=['c_to2', 'c_to0']),
           L(id='c_to2', kind='connector', successors=['a2_out0']),
           L(id='c_to0', kind='connector', successors=['a0_out0']),
           L(id='a2_out0', kind='leaving', successors=[]),
           L(id='a0_out0', kind='leaving', successors=[])]
    gt = L(lanelets=lls, segments_of={'a1_in0': ['in'], 'c_to2': ['j5', 'link', 'j2a'],
                                      'c_to0': ['j5', 'link', 'j2b'], 'a2_out0': ['out2'],
                                      'a0_out0': ['out0']})
    # 'v' turns to arm 2 (seen 4 times on the shared link, once where it parts); 'w' goes
    # to arm 0; 'u' was seen on the shared pieces only
    seg = np.array(['in', 'j5', 'link', 'link', 'link', 'link', 'j2a', 'out2', 'out2',
                    'in', 'link', 'j2b', 'out0', 'j5', 'link'])
    veh = np.array(['v'] * 9 + ['w'] * 4 + ['u'] * 2)
    lab = label_points(seg, veh, gt)
    assert list(lab[:9]) == ['a1_in0'] + ['c_to2'] * 6 + ['a2_out0'] * 2
    assert list(lab[9:13]) == ['a1_in0', 'c_to0', 'c_to0', 'a0_out0']
    assert list(lab[13:]) == ['', '']                       # undecided, not guessed


def test_map_matching_needs_distance_and_heading():
    segs = _graph()
    xy = np.array([[40.0, 1.9], [40.0, 1.9], [40.0, 9.0]])
    hd = np.array([math.pi, 0.0, math.pi])    # along eI (westward), against it, too far
    m = match_segments(xy, hd, segs)
    assert list(m) == ['eI', '', '']


def test_route_labels_of_a_table1_scene():
    from intersection_estimator.scenarios.floor import route_labels
    from intersection_estimator.sim import simulate_scenario
    sc = simulate_scenario(4)
    d = sc.detections('tracked')
    lab = route_labels(d, sc.tracks, sc.gt_lanelets)
    real = d.track_id < 1_000_000
    assert (lab[~real] == '').all() and (lab[real] != '').mean() > 0.9
    routes = {tr.id: set(tr.route) for tr in sc.tracks}
    assert all(lid in routes[int(t)] for lid, t in zip(lab[real], d.track_id[real]) if lid)


def test_a_vehicle_that_never_drove_is_not_traffic():
    """A parked car (1 m sensor noise around one spot) loses its labels, so it neither
    counts for its lane nor shapes the traffic line; a car that drives, and one that drives
    up to a queue and stands there for most of the recording, keep theirs."""
    from intersection_estimator.scenarios.floor import drove
    rng = np.random.default_rng(7)
    t = np.arange(300) * 0.1
    parked = np.array([10.0, 3.0]) + rng.normal(0, 1.0, (300, 2))
    moving = np.stack([10.0 * t, np.zeros_like(t)], 1) + rng.normal(0, 1.0, (300, 2))
    queued = np.stack([np.minimum(10.0 * t, 12.0), np.full_like(t, -3.0)], 1) \
        + rng.normal(0, 1.0, (300, 2))
    xy = np.concatenate([parked, moving, queued])
    vehicle = np.repeat([5, 6, 7], 300)
    order = rng.permutation(len(xy))              # rows in any order: time decides
    labels = np.full(len(xy), 'lane_a')
    out = drove(labels[order], vehicle[order], xy[order], np.tile(t, 3)[order])
    kept = {v: set(out[vehicle[order] == v]) for v in (5, 6, 7)}
    assert kept == {5: {''}, 6: {'lane_a'}, 7: {'lane_a'}}
    counts = traffic_counts([type('L', (), {'id': 'lane_a'})()], out, vehicle[order])
    assert counts == {'lane_a': 2}
