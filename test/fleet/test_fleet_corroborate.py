"""The drive's vehicles map-matched to the prior map (fleet/corroborate.py, issue 17): what
they drove is counted where the world's traffic was, claims they contradict are dropped,
and a real change's claim survives."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from intersection_estimator.export.osm import write_osm
from intersection_estimator.fleet.changes import ChangeConfig, Finding, compare
from intersection_estimator.fleet.corroborate import drive_traffic, match_traffic, refutes, tracks_of
from intersection_estimator.fleet.edits import apply_edit
from intersection_estimator.fleet.prior_map import load_prior_map
from intersection_estimator.pipeline import in_mode
from intersection_estimator.model import ENTERING, LEAVING

from .conftest import without_edit_lanes


def _prior(tmp_path, lls):
    (X,) = load_prior_map(write_osm(tmp_path / 'prior.osm', lls))
    return X

def _names(X):
    return {l.id: l.name for a in X.arms for l in a.lanes_in + a.lanes_out}

def test_vehicles_are_counted_on_the_lanes_the_world_used(tmp_path, cases):
    """Against the case's own map: every lane two or more vehicles drove has matched traffic,
    a lane nobody drove has none, and every matched turn is a mapped turn somebody took."""
    sc, _ = cases[5]
    X = _prior(tmp_path, sc.gt_lanelets)
    tr = drive_traffic(sc.detections('tracked'), X, ChangeConfig())
    names = _names(X)
    for lid, name in names.items():
        if sc.traffic.get(name, 0) >= 2:
            assert tr.vehicles.get(lid, 0) >= 1, name
        if sc.traffic.get(name, 0) == 0:
            assert tr.vehicles.get(lid, 0) == 0, name
    cons = {(c.lane_in, c.lane_out): c.name for c in X.connectors}
    assert tr.turns and all(t in cons and sc.traffic.get(cons[t], 0) > 0 for t in tr.turns)
    assert all(abs(o) < 0.3 for o in tr.offset_m.values())     # vehicles keep to the lane centers
    assert tr.off_map == []                                      # nothing drives beside the map

def test_a_moved_lane_keeps_its_claim_a_false_one_is_dropped(tmp_path, cases):
    """A lane the map has 1 m off: its vehicles drive ~1 m beside it (claim kept). The same
    claim against the right map is the estimator's error: the traffic drives on the mapped
    center line and drops it."""
    sc, r = cases[5]
    lls, what = apply_edit(sc, 'lane_moved', np.random.default_rng(5))
    X = _prior(tmp_path, lls)
    tr = drive_traffic(sc.detections('tracked'), X, ChangeConfig())
    (f,) = compare(r.intersection, r.lanelets, X, ChangeConfig(), tr).findings
    assert f.kind == 'lane_moved' and _names(X)[f.map_lanes[0]] == what['lane']
    assert 0.75 < abs(tr.offset_m[f.map_lanes[0]]) < 1.3
    X0 = _prior(tmp_path, sc.gt_lanelets)
    tr0 = drive_traffic(sc.detections('tracked'), X0, ChangeConfig())
    lid = next(i for i, n in _names(X0).items() if n == what['lane'])
    false = Finding('lane_moved', f'lane_moved:{lid}', 0.9, map_lanes=[lid])
    assert refutes(false, tr0, X0, 0.75, 30.0)

def test_estimator_errors_are_not_claimed_with_the_traffic(tmp_path, cases):
    """The estimate with one entering lane pushed 1.5 m sideways claims it moved; the drive's
    vehicles, on the mapped lane, refute that -- and only with corroboration off is it claimed."""
    sc, r = cases[5]
    X = _prior(tmp_path, sc.gt_lanelets)
    lanes = copy.deepcopy(r.lanelets)
    l = next(l for l in lanes if l.kind == 'entering' and l.support > 0)
    n = l.left[0] - l.center[0]
    n = n / np.hypot(*n)
    for name in ('left', 'right', 'center'):
        setattr(l, name, getattr(l, name) + 1.5 * n)
    claimed = compare(r.intersection, lanes, X).findings
    assert 'lane_moved' in [f.kind for f in claimed]
    tr = drive_traffic(sc.detections('tracked'), X, ChangeConfig())
    assert compare(r.intersection, lanes, X, ChangeConfig(), tr).findings == []

@pytest.mark.parametrize('edit, kind', [('lane_removed', 'lane_added'), ('arm_removed', 'arm_added'),
                                        ('connector_removed', 'connector_added')])
def test_real_changes_survive_the_traffic(tmp_path, cases, edit, kind):
    """Traffic on a lane or arm the map lacks drives outside every mapped lane; a turn the map
    lacks is driven from one mapped lane to the other: the expected claim is not dropped."""
    sc, r = cases[5]
    lls, what = apply_edit(sc, edit, np.random.default_rng(5))
    X = _prior(tmp_path, lls)
    tr = drive_traffic(sc.detections('tracked'), X, ChangeConfig())
    found = [f.kind for f in without_edit_lanes(
        edit, what, compare(r.intersection, r.lanelets, X, ChangeConfig(), tr).findings)]
    assert found == [kind], (what, found)
    if kind != 'connector_added':
        assert tr.off_map

def test_no_tracks_no_corroboration(tmp_path, cases):
    """Raw radar (no identities) has no vehicles to match: the estimate alone speaks; with
    corroboration switched off the window is not read."""
    sc, _ = cases[5]
    X = _prior(tmp_path, sc.gt_lanelets)
    raw = in_mode(sc.detections('tracked'), 'raw')
    assert tracks_of(raw) == [] and drive_traffic(raw, X, ChangeConfig()) is None
    assert drive_traffic(sc.detections('tracked'), X, ChangeConfig(corroborate=0)) is None
    assert match_traffic([], X, 1.75, 5).vehicles == {}

def test_cyclists_and_pedestrians_are_not_lane_traffic(cases):
    """Road users that keep to no lane (bicycle 6, pedestrian 7) are left out of the matching."""
    sc, _ = cases[5]
    d = sc.detections('tracked')
    from dataclasses import replace
    walkers = replace(d, label=np.full(len(d), 7, np.int16))
    assert tracks_of(walkers) == [] and len(tracks_of(d)) > 0

def test_bad_match_config_named():
    with pytest.raises(ValueError, match='match_gate_m'):
        ChangeConfig(match_gate_m=0.0).validate()
    with pytest.raises(ValueError, match='corroborate'):
        ChangeConfig(corroborate=2).validate()

def test_a_moved_lane_needs_its_vehicles_or_traffic_beside_the_map():
    """A lane claimed moved that no vehicle drove is shown moved only by traffic outside the
    mapped lanes of its arm direction (a lane moved farther than the matching gate)."""
    from types import SimpleNamespace
    from intersection_estimator.fleet.corroborate import TrafficOnMap
    X = SimpleNamespace(arms=[SimpleNamespace(angle=0.0), SimpleNamespace(angle=np.pi / 2)])
    f = Finding('lane_moved', 'lane_moved:L', 0.9, map_arm=1, direction='in', map_lanes=['L'])
    assert refutes(f, TrafficOnMap(), X, 0.75, 30.0)
    assert not refutes(f, TrafficOnMap(off_map=[(np.pi / 2 + 0.1, ENTERING)]), X, 0.75, 30.0)
    assert refutes(f, TrafficOnMap(off_map=[(np.pi / 2, LEAVING), (0.0, ENTERING)]), X, 0.75, 30.0)
    assert refutes(f, TrafficOnMap(vehicles={'L': 3}, offset_m={'L': 0.1}), X, 0.75, 30.0)
    assert not refutes(f, TrafficOnMap(vehicles={'L': 3}, offset_m={'L': -0.9}), X, 0.75, 30.0)

def test_a_queued_vehicle_uses_its_lane_a_parked_one_does_not(tmp_path, cases):
    """A vehicle that drove up to a queue and stands there is its lane's traffic (the world's
    ground truth counts it): its standing positions match the nearest lane. One standing
    through the whole window (parked) is not traffic."""
    from scipy.spatial import cKDTree
    from intersection_estimator.fleet import corroborate as co
    sc, _ = cases[5]
    X = _prior(tmp_path, sc.gt_lanelets)
    a, b = X.arms[0].lanes_in[0], X.arms[1].lanes_in[0]
    rng = np.random.default_rng(0)
    t = np.arange(0.0, 20.0, 0.1)
    stop = np.asarray(a.center, float)[len(a.center) // 2]
    queue = np.concatenate([stop + np.linspace(-12.0, 0.0, 40)[:, None] * (a.center[-1] - a.center[0])
                            / np.hypot(*(a.center[-1] - a.center[0])), np.repeat(stop[None], 160, 0)])
    parked = np.repeat(np.asarray(b.center, float)[len(b.center) // 2][None], len(t), 0)
    q, pk = (co._smoothed(p + rng.normal(0, 0.3, p.shape), t) for p in (queue, parked))
    assert co._drove(q) and not co._drove(pk)
    els = co._elements(X)
    P, T, I = co._samples(els)
    lane = np.array([el.direction != 0 for el in els])[I]
    u = co._headings(q, t)
    standing = ~np.isfinite(u[:, 0])
    assert standing.sum() > 100
    with_queue, _, _ = co._match_points(q, u, standing, cKDTree(P), T, I, lane, 1.75)
    without, _, _ = co._match_points(q, u, np.zeros(len(q), bool), cKDTree(P), T, I, lane, 1.75)
    ids = np.array([el.id for el in els])
    assert (ids[with_queue[standing]] == a.id).all() and (without[standing] == -1).all()
    tr = match_traffic([(parked + rng.normal(0, 0.3, parked.shape), t)], X, 1.75, 5)
    assert tr.vehicles == {} and tr.off_map == []
    # a queue past the mapped lane's far end, in line with it, is on no mapped lane (SUMO:
    # queues reach beyond the 60 m the map draws of an approach)
    c = np.asarray(a.center, float)
    out = (c[0] - c[1]) / np.hypot(*(c[0] - c[1]))
    beyond = c[0] + np.linspace(3.0, 12.0, 50)[:, None] * out
    m, _, _ = co._match_points(beyond, np.full_like(beyond, np.nan), np.ones(len(beyond), bool), cKDTree(P), T, I,
                            lane, 1.75)
    assert (m == -1).all()

def test_a_turn_starts_from_the_lane_driven_last():
    """A turn pocket's vehicle drives the through lane longer than the pocket; its turn
    starts from the pocket (the lane it drove last before the box), and ends on the leaving
    lane it drove first after it."""
    from intersection_estimator.fleet import corroborate as co
    z = np.zeros((2, 2))
    els = [co._Element('through', 0, ENTERING, z), co._Element('pocket', 0, ENTERING, z),
           co._Element('out0', 1, LEAVING, z), co._Element('out1', 1, LEAVING, z),
           co._Element('c', 0, 0, z, ('pocket', 'out0'))]
    match = np.array([0] * 30 + [1] * 8 + [4] * 6 + [2] * 12 + [3] * 20)
    tr = co.TrafficOnMap()
    co._count(tr, els, match, np.zeros(len(match)), 5, {e.id: e.arm for e in els if e.direction}, {})
    assert tr.turns == {('pocket', 'out0')}
    assert tr.vehicles == {'through': 1, 'pocket': 1, 'out0': 1, 'out1': 1}
    assert tr.passages == {(0, ENTERING): 1, (1, LEAVING): 1}
    assert tr.moves == {(0, ENTERING): {1: 1}, (1, LEAVING): {0: 1}}
    assert tr.lane_turns == {('pocket', 1): 1, ('out0', 0): 1}

def test_a_vehicle_seen_in_the_box_only_chose_no_lane():
    """Its turn is known from the connector it followed (the arms' turn counts keep it), but
    it was seen on no lane of one side: it chose no lane there and missed none (a missing
    lane's evidence, ``lane_turns``); on the side where it was seen on a lane it chose that."""
    from intersection_estimator.fleet import corroborate as co
    z = np.zeros((2, 2))
    els = [co._Element('in0', 0, ENTERING, z), co._Element('out0', 1, LEAVING, z),
           co._Element('c', 0, 0, z, ('in0', 'out0'))]
    arm_of = {e.id: e.arm for e in els if e.direction}
    box_only = co.TrafficOnMap()
    co._count(box_only, els, np.array([2] * 12), np.zeros(12), 5, arm_of, {})
    assert box_only.moves == {(0, ENTERING): {1: 1}, (1, LEAVING): {0: 1}}
    assert box_only.lane_turns == {}
    entering = co.TrafficOnMap()
    co._count(entering, els, np.array([0] * 8 + [2] * 12), np.zeros(20), 5, arm_of, {})
    assert entering.lane_turns == {('in0', 1): 1}


def test_a_lane_change_after_a_mapped_turn_is_that_turn():
    """A vehicle that followed the mapped turn in0 -> out0 to 90 % of its length and then left
    on out1 beside out0 took the mapped turn and changed lanes after the box: no turn the map
    lacks. One that left the mapped turn after 30 % of it drove a turn the map lacks."""
    from intersection_estimator.fleet import corroborate as co
    z = np.zeros((2, 2))
    els = [co._Element('in0', 0, ENTERING, z), co._Element('out0', 1, LEAVING, z), co._Element('out1', 1, LEAVING, z),
           co._Element('c', 0, 0, z, ('in0', 'out0'))]
    arm_of = {e.id: e.arm for e in els if e.direction}
    match = np.array([0] * 10 + [3] * 10 + [2] * 10)

    def turns(reach, share):
        along = np.where(match == 3, np.tile(np.linspace(0.0, reach, 10), 3), 0.0)
        tr = co.TrafficOnMap()
        co._count(tr, els, match, np.zeros(len(match)), 5, arm_of, {}, co._Follow(els, arm_of, share).at(along))
        return tr.turns

    assert turns(0.9, co.FOLLOW_SHARE) == {('in0', 'out0')}
    assert turns(0.3, co.FOLLOW_SHARE) == {('in0', 'out1')}
    assert turns(0.9, 0.95) == {('in0', 'out1')}
