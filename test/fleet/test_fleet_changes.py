"""Change detection on constructed prior maps (issue 17, slice 2): each kind found, nothing
else claimed; removals only where the data can show them."""

from __future__ import annotations

import copy
from dataclasses import replace

import numpy as np
import pytest

from intersection_estimator.export.osm import write_osm
from intersection_estimator.fleet.changes import ChangeConfig, compare
from intersection_estimator.fleet.corroborate import drive_traffic
from intersection_estimator.fleet.edits import EDITS, EXPECTED, apply_edit
from intersection_estimator.fleet.prior_map import load_prior_map

from .conftest import without_edit_lanes

SEEDS = (1, 2, 5)


def _prior(tmp_path, lls):
    (X,) = load_prior_map(write_osm(tmp_path / 'prior.osm', lls))
    return X


@pytest.mark.parametrize('edit', EDITS)
@pytest.mark.parametrize('seed', SEEDS)
def test_each_edit_found_and_nothing_else(tmp_path, cases, seed, edit):
    sc, r = cases[seed]
    lls, what = apply_edit(sc, edit, np.random.default_rng(seed))
    assert lls is not None
    X = _prior(tmp_path, lls)
    traffic = drive_traffic(sc.detections('tracked'), X, ChangeConfig())     # as the fleet compares
    view = compare(r.intersection, r.lanelets, X, ChangeConfig(), traffic)
    if edit == 'lane_added' and not view.findings:
        # the extra lane serves the kerb lane's turns: only their vehicles show it missing,
        # and one or two of them leave it "weak" (fusion adds such drives up)
        (f,) = [f for f in view.weak if f.kind == 'lane_removed']
        assert f.evidence['vehicles_its_turns'] <= 2 and 0 < f.confidence <= 0.5
        return
    found = without_edit_lanes(edit, what, view.findings)
    assert [f.kind for f in found] == [EXPECTED[edit]], (what, view.findings)
    f = found[0]
    assert 0.5 < f.confidence <= 1.0 and f.evidence['passages'] > 0
    by_name = {l.id: l.name for a in X.arms for l in a.lanes_in + a.lanes_out}
    if edit == 'lane_moved':
        assert [by_name[i] for i in f.map_lanes] == [what['lane']]
        assert 0.75 < f.evidence['offset_m'] < 1.3
    if edit == 'connector_removed':          # the turn the map lost, in map lane ids
        src, dst = what['connector'][2:].split('_')
        assert [by_name[i] for i in f.map_lanes] == [f'{src[:2]}_in{src[3:]}', f'{dst[:2]}_out{dst[3:]}']
    if edit == 'lane_added':                 # the map's extra lane is the one reported removed
        assert [by_name[i].endswith('_extra') for i in f.map_lanes] == [True]


def _drop_arm(r, e):
    """The estimate without its arm ``e`` (as if no vehicle had used that arm)."""
    I = copy.deepcopy(r.intersection)
    del I.arms[e]
    ren = {old: new for new, old in enumerate(i for i in range(len(r.intersection.arms)) if i != e)}
    lls = []
    for l in copy.deepcopy(r.lanelets):
        if l.arm == e or l.arm_to == e:
            continue
        l.arm = ren[l.arm]
        l.arm_to = ren.get(l.arm_to, -1)
        lls.append(l)
    return I, lls


def test_unused_arm_is_unobserved_or_removed_by_passages(tmp_path, cases):
    """A mapped arm without traffic: 'unobserved' unless the vehicles whose turns the drive
    saw, all avoiding it, outweigh the prior: ``E[(1 - S)^K]`` with ``S`` the Jeffreys share
    of the arm's mapped turns; the rule before (``turn_absence=0``): ``(1 - 1/arms)^passages``."""
    from scipy.special import betaln
    sc, r = cases[5]
    X = _prior(tmp_path, sc.gt_lanelets)
    I, lls = _drop_arm(r, 1)
    few = compare(I, lls, X, ChangeConfig(absence_prior=1e-12))
    assert few.findings == [] and few.unobserved == [1]
    assert 'arm_removed' in [f.kind for f in few.weak]
    many = compare(I, lls, X)
    (f,) = many.findings
    assert f.kind == 'arm_removed' and many.unobserved == []
    k = f.evidence['vehicles_known_turn']
    # the turns the estimate's connectors show, none into or out of the arm
    assert k == sum(l.support for l in lls if l.kind == 'connector') > 0
    a, b = 0.5 * f.evidence['turns_of_arm'], 0.5 * (f.evidence['turns_mapped'] - f.evidence['turns_of_arm'])
    assert f.log_lr == pytest.approx(-(betaln(a, b + k) - betaln(a, b)))
    old = compare(I, lls, X, ChangeConfig(turn_absence=0)).findings[0]
    assert old.log_lr == pytest.approx(-many.passages * np.log(1 - 1 / 3))


def test_arm_removed_needs_vehicles_that_could_have_used_it(tmp_path, cases):
    """Vehicles seen on one arm only (turn unknown) say nothing about a missing arm: they may
    have come from or gone to it out of sight (the AV2 clips)."""
    sc, r = cases[5]
    X = _prior(tmp_path, sc.gt_lanelets)
    I, lls = _drop_arm(r, 1)
    for l in lls:
        if l.kind == 'connector':
            l.support = 0          # the lanes' vehicles stay, no turn was seen
    lls[0].support = max(lls[0].support, 1)
    view = compare(I, lls, X)
    assert view.findings == [] and view.unobserved == [1]
    (f,) = [f for f in view.weak if f.kind == 'arm_removed']
    assert f.evidence['vehicles_known_turn'] == 0 and f.log_lr == 0.0


def test_connector_unused_only_for_undriven_turns(tmp_path, cases):
    sc, r = cases[5]
    X = _prior(tmp_path, sc.gt_lanelets)
    assert compare(r.intersection, r.lanelets, X).findings == []    # default prior: too few passages
    view = compare(r.intersection, r.lanelets, X, ChangeConfig(absence_prior=0.9))
    unused = sorted(next(c.name for c in X.connectors if c.id == f.map_lanes[0]) for f in view.findings)
    assert {f.kind for f in view.findings} == {'connector_unused'}
    undriven = {k for k, v in sc.traffic.items() if k.startswith('c_') and v == 0}
    assert unused and set(unused) <= undriven
    for f in view.findings:      # its entering lane was left by >= 1 other, driven turn
        assert f.evidence['passages'] >= 1


def test_bad_config_named():
    with pytest.raises(ValueError, match='moved_m'):
        replace(ChangeConfig(), moved_m=0).validate()
    with pytest.raises(ValueError, match='min_confidence'):
        ChangeConfig(min_confidence=1.5).validate()
    with pytest.raises(ValueError, match='absence_prior'):
        ChangeConfig(absence_prior=0.0).validate()


def test_lane_removed_is_keyed_by_the_mapped_lane(tmp_path, cases):
    """A missing lane is one finding per *mapped lane* (key = its id), and the lanes the drive
    drove are listed in ``lanes_seen`` (they refute the lane's absence in fusion). The old
    key per arm direction let drives that missed *different* lanes add up to one removal."""
    sc, r = cases[5]
    lls, what = apply_edit(sc, 'lane_added', np.random.default_rng(5))
    X = _prior(tmp_path, lls)
    view = compare(r.intersection, r.lanelets, X)
    (f,) = [f for f in view.findings + view.weak if f.kind == 'lane_removed']
    names = {l.id: l.name for a in X.arms for l in a.lanes_in + a.lanes_out}
    assert f.key == f'lane_removed:{f.map_lanes[0]}' and names[f.map_lanes[0]].endswith('_extra')
    arm = X.arms[f.map_arm]
    same_dir = arm.lanes_in if f.direction == 'in' else arm.lanes_out
    others = {l.id for l in same_dir} - set(f.map_lanes)
    assert others and others <= view.lanes_seen and f.map_lanes[0] not in view.lanes_seen


def test_lane_evidence_is_the_vehicles_on_the_lane(tmp_path, cases):
    """A moved lane rests on the vehicles that drove the estimated lane (1/3 nat each), not on
    the arm's confidence: one vehicle -> log LR 1/3; a lane no vehicle drove shows nothing.
    (The old rule gave every lane finding its arm's confidence, ~0.99 here.)"""
    sc, r = cases[5]
    lls, what = apply_edit(sc, 'lane_moved', np.random.default_rng(5))
    X = _prior(tmp_path, lls)
    (f,) = compare(r.intersection, r.lanelets, X).findings
    lanes = copy.deepcopy(r.lanelets)
    est = None
    for l in lanes:               # the estimated lane the finding is about: its support shows up
        if l.kind == 'connector' or l.lane_index != f.evidence['lane_index']:
            continue
        keep, l.support = l.support, 1
        v = compare(r.intersection, lanes, X)
        if any(x.key == f.key and x.evidence['support'] == 1 for x in v.findings + v.weak):
            est = l
            break
        l.support = keep
    assert est is not None
    est.support = 1
    one = compare(r.intersection, lanes, X)
    (g,) = [x for x in one.findings + one.weak if x.key == f.key]
    assert g.log_lr == pytest.approx(1.0 / 3.0) and g.confidence == pytest.approx(1 / (1 + np.exp(-1 / 3)))
    est.support = 0
    none = compare(r.intersection, lanes, X)
    assert f.key not in {x.key for x in none.findings}


def test_absence_with_varying_shares():
    """share_concentration k: the element's share ~ Beta(k f, k (1 - f)); k = 0 is (1 - f)^P."""
    from math import lgamma, log
    from intersection_estimator.fleet.changes import _absence
    old = _absence('lane_removed', 'k', 12.0, 0.5, ChangeConfig(share_concentration=0.0))
    assert old.log_lr == pytest.approx(-12.0 * log(0.5))
    new = _absence('lane_removed', 'k', 12.0, 0.5, ChangeConfig(share_concentration=3.0))
    a = b = 1.5
    assert new.log_lr == pytest.approx(-(lgamma(b + 12) + lgamma(a + b) - lgamma(b) - lgamma(a + b + 12)))
    assert 0 < new.log_lr < old.log_lr
    more = _absence('lane_removed', 'k', 24.0, 0.5, ChangeConfig(share_concentration=3.0))
    assert more.log_lr > new.log_lr
    with pytest.raises(ValueError, match='share_concentration'):
        ChangeConfig(share_concentration=-1.0).validate()


def test_added_arm_contradicted_by_absence_evidence(tmp_path, cases):
    """A drive without an arm the map lacks speaks against it by the absence likelihood of its
    passages (none used an extra arm, share 1 / (arms + 1)), not by its certainty of having
    seen the intersection at all (the old rule: total_conf, ~1 for any drive)."""
    from intersection_estimator.fleet.changes import Finding, _absence
    sc, r = cases[5]
    X = _prior(tmp_path, sc.gt_lanelets)
    cfg = ChangeConfig(share_concentration=3.0)
    view = compare(r.intersection, r.lanelets, X, cfg)
    llr = _absence('arm_added', '', view.passages, 1.0 / (len(X.arms) + 1), cfg).log_lr
    assert view.no_new_arm_llr == pytest.approx(llr)
    q = view.contradiction(Finding('arm_added', 'arm_added:after0', 0.9, 0))
    assert q == pytest.approx(1 / (1 + np.exp(-llr))) and q < view.total_conf


def test_lane_identity_is_by_position_not_index(tmp_path, cases):
    """An estimated lane is the mapped lane it lies on, not the one with its index: the same
    lanes with the lane indices of one entering direction rotated by one (the short drives'
    estimator error: lanes shifted by one index, count unchanged) show no change against the
    unchanged map. Paired by index (the old rule) they read as lanes moved by a lane width
    and their turns as turns the map lacks."""
    from intersection_estimator.fleet.match import match_arms
    sc, r = cases[5]
    X = _prior(tmp_path, sc.gt_lanelets)
    assert compare(r.intersection, r.lanelets, X).findings == []
    amap = match_arms([a.angle for a in r.intersection.arms], [a.angle for a in X.arms])
    # an estimated arm whose entering direction has >= 2 lanes, with turns from it
    e = next(e for e in sorted(amap) if r.intersection.arms[e].lanes_in >= 2)
    n = r.intersection.arms[e].lanes_in
    lanes = copy.deepcopy(r.lanelets)
    rot = {k: (k + 1) % n for k in range(n)}
    for l in lanes:
        if l.arm == e and l.kind in ('entering', 'connector'):
            l.lane_index = rot[l.lane_index]
    view = compare(r.intersection, lanes, X)
    assert view.findings == [], [f.key for f in view.findings]
    assert view.used == compare(r.intersection, r.lanelets, X).used


def _turns_map(keys):
    """A mapped intersection reduced to what the turn rule reads: its connectors' keys."""
    from types import SimpleNamespace
    return SimpleNamespace(connectors=[SimpleNamespace(key=k) for k in keys])


def test_lane_absence_counts_the_vehicles_of_its_turns():
    """A missing lane is evidenced by the vehicles of the turns it serves: two lanes of arm 0
    go to arm 1 (through), lane 2 alone to arm 2 (right turn). Vehicles seen going through
    say nothing about the turn lane; seen turning right they all missed it (its share 1)."""
    from math import log
    from intersection_estimator.fleet.changes import _lane_absence
    from intersection_estimator.model import ENTERING
    X = _turns_map([(0, 0, 1, 0), (0, 1, 1, 0), (0, 2, 2, 0)])
    cfg = ChangeConfig()
    turn_lane = _lane_absence('L2', 2, 0, ENTERING, 12.0, 3, X, {1: 12.0}, cfg)
    assert turn_lane.log_lr < 0.1 and turn_lane.confidence < 0.5         # nobody turned right: unobserved
    through = _lane_absence('L1', 1, 0, ENTERING, 12.0, 3, X, {1: 12.0}, cfg)
    assert through.log_lr == pytest.approx(12.0 * log(2.0))              # 12 through vehicles, 1 of 2 lanes
    right = _lane_absence('L2', 2, 0, ENTERING, 3.0, 3, X, {2: 3.0}, cfg)
    assert right.log_lr > 20 and right.confidence > 0.99                 # 3 right turners, its only lane
    # turns not seen: the drive's turn shares (Dirichlet, MOVE_PRIOR) carry the passages over
    seen_none = _lane_absence('L1', 1, 0, ENTERING, 12.0, 3, X, {}, cfg)
    assert 0 < seen_none.log_lr < through.log_lr
    # a mapped lane without mapped turns: any vehicle of its direction could have used it
    bare = _lane_absence('L3', 3, 0, ENTERING, 12.0, 4, X, {1: 12.0}, cfg)
    assert bare.log_lr == pytest.approx(-12.0 * log(1 - 1 / 4))


def test_unknown_turn_llr_is_the_beta_binomial_at_full_share():
    from scipy.special import betaln
    from intersection_estimator.fleet.changes import _unknown_turn_llr
    assert _unknown_turn_llr(6.0, 0.5, 1.0, 1.0) == pytest.approx(-(betaln(0.5, 7.0) - betaln(0.5, 1.0)))
    assert _unknown_turn_llr(0.0, 0.5, 1.0, 1.0) == 0.0
    assert 0 < _unknown_turn_llr(6.0, 0.5, 1.0, 0.5) < _unknown_turn_llr(6.0, 0.5, 1.0, 1.0)


def test_added_lane_edit_serves_its_neighbours_turns(tmp_path, cases):
    """The map's extra lane leads where the kerb lane beside it leads (a mapped lane without
    turns is no lane a detector could miss by its turns), joined at shared end points."""
    sc, _ = cases[5]
    lls, what = apply_edit(sc, 'lane_added', np.random.default_rng(5))
    X = _prior(tmp_path, lls)
    arm = X.arms[[a.index for a in X.arms if any(l.name.endswith('_extra') for l in a.lanes_in + a.lanes_out)][0]]
    extra = next(l for l in arm.lanes_in + arm.lanes_out if l.name.endswith('_extra'))
    kerb = next(l for l in arm.lanes_in + arm.lanes_out if extra.name == l.name + '_extra')
    ends = {c.lane_out if extra.direction == 1 else c.lane_in for c in X.connectors
            if extra.id in (c.lane_in, c.lane_out)}
    kerb_ends = {c.lane_out if kerb.direction == 1 else c.lane_in for c in X.connectors
                 if kerb.id in (c.lane_in, c.lane_out)}
    assert ends and ends == kerb_ends


def test_a_closed_arm_is_found_removed(tmp_path, cases):
    """World edit ``arm_closed``: every vehicle that drove one arm taken out of the world,
    the case estimated anew, the map unchanged -> ``arm_removed`` of that arm, found by the
    vehicles seen turning between the others (the benchmark's ``arm_closed`` row)."""
    from scipy.spatial import cKDTree
    from intersection_estimator.evaluate import resample
    from intersection_estimator.fleet.edits import ARM_TOUCH_M, world_without_arm
    from intersection_estimator.pipeline import estimate
    sc, _ = cases[2]
    world, what = world_without_arm(sc, np.random.default_rng(0))
    a = what['arm']
    tree = cKDTree(np.concatenate([resample(np.asarray(l.center, float), 0.25) for l in sc.gt_lanelets
                                   if l.arm == a and l.kind != 'connector']))
    assert a != sc.ego.arm and what['vehicles'] == len(sc.tracks) - len(world.tracks) > 0
    assert all(tree.query(t.xy)[0].min() >= ARM_TOUCH_M for t in world.tracks)
    X = _prior(tmp_path, sc.gt_lanelets)
    r = estimate(world.detections('tracked'), seed=0)
    view = compare(r.intersection, r.lanelets, X, ChangeConfig(), drive_traffic(world.detections('tracked'), X,
                                                                                 ChangeConfig()))
    removed = [f for f in view.findings if f.kind == 'arm_removed']
    (f,) = removed
    names = {l.name.split('_')[0] for l in X.arms[f.map_arm].lanes_in + X.arms[f.map_arm].lanes_out}
    assert names == {f'a{a}'} and f.evidence['vehicles_known_turn'] >= 3


def test_recorded_worlds_are_not_edited():
    from dataclasses import dataclass, field
    from intersection_estimator.fleet.edits import world_without_arm

    @dataclass
    class Recorded:
        real: dict = field(default_factory=lambda: {'tracked': object()})

    assert world_without_arm(Recorded(), np.random.default_rng(0)) == (None, None)


def _map_k(post):
    return max(post, key=lambda kp: kp[1])[0]


def test_lane_choice_concentration_is_read_from_the_other_directions():
    """Even lane choice (Table I's routes) reads as exact shares (k = 0) with most of the
    posterior; every turn on one of its lanes (SUMO's drivers, and real ones) as a small
    concentration; the judged direction's own counts are left out; nothing seen leaves the
    flat prior."""
    from intersection_estimator.fleet.changes import CONCENTRATIONS, lane_concentration
    even = {(0, 1): [np.array([5.0, 5.0]), np.array([4.0, 6.0])], (1, 1): [np.array([3.0, 3.0, 4.0])]}
    post = lane_concentration(even, skip=None)
    assert _map_k(post) == 0.0 or _map_k(post) > 100
    assert sum(w for k, w in post if 0 < k < 1) < 0.01
    lumpy = {(0, 1): [np.array([10.0, 0.0]), np.array([0.0, 8.0])], (1, 1): [np.array([7.0, 0.0, 0.0])]}
    post = lane_concentration(lumpy, skip=None)
    assert 0 < _map_k(post) < 0.5 and sum(w for k, w in post if k == 0 or k > 10) < 0.01
    assert lane_concentration({**even, (2, 1): [np.array([0.0, 30.0])]}, skip=(2, 1)) == \
        lane_concentration(even, skip=None)
    flat = lane_concentration({}, skip=None)
    assert len(flat) == len(CONCENTRATIONS) + 1 and np.allclose([w for _, w in flat], 1 / len(flat))
    assert sum(w for _, w in post) == pytest.approx(1.0, rel=1e-4)


def test_lumpy_lane_choice_leaves_an_empty_lane_unclaimed():
    """12 vehicles went through on lane 0 of two through lanes: with exact shares lane 1 is
    removed (12 ln 2 nats); where the drive shows its vehicles keep to one lane of a turn
    (k = 0.2) an empty lane is what such traffic looks like and the claim is not made; a
    posterior over k averages the likelihoods."""
    from math import exp, log
    from intersection_estimator.fleet.changes import LaneChoice, _lane_absence
    from intersection_estimator.model import ENTERING
    X = _turns_map([(0, 0, 1, 0), (0, 1, 1, 0), (0, 2, 2, 0)])
    cfg = ChangeConfig()
    exact = _lane_absence('L1', 1, 0, ENTERING, 12.0, 3, X, {1: 12.0}, cfg, LaneChoice(((0.0, 1.0),)))
    assert exact.log_lr == pytest.approx(12.0 * log(2.0)) and exact.confidence > 0.99
    lumpy = _lane_absence('L1', 1, 0, ENTERING, 12.0, 3, X, {1: 12.0}, cfg, LaneChoice(((0.2, 1.0),)))
    assert 0 < lumpy.log_lr < 1.0 and lumpy.confidence < 0.5
    assert lumpy.evidence['lane_choice_concentration'] == 0.2
    half = _lane_absence('L1', 1, 0, ENTERING, 12.0, 3, X, {1: 12.0}, cfg,
                         LaneChoice(((0.0, 0.5), (0.2, 0.5))))
    assert half.log_lr == pytest.approx(-log(0.5 * exp(-exact.log_lr) + 0.5 * exp(-lumpy.log_lr)))
    # unseen turns: the expectation runs over the lane's varying share too
    unseen = _lane_absence('L1', 1, 0, ENTERING, 12.0, 3, X, {}, cfg, LaneChoice(((0.2, 1.0),)))
    assert 0 < unseen.log_lr < _lane_absence('L1', 1, 0, ENTERING, 12.0, 3, X, {}, cfg).log_lr


def test_a_vehicle_seen_off_its_turns_lane_is_not_proof():
    """Lane 2 alone serves the right turn; one vehicle seen turning right from another lane
    would, by the map, make lane 2 impossible (~20 nats). A drive whose vehicles are seen on
    a lane the map does not give their turn in 1 of 10 cases makes it ln 10 per vehicle; the
    share is read from the other arm directions (Jeffreys: (off + 0.5) / (seen + 1))."""
    from math import log
    from types import SimpleNamespace
    from intersection_estimator.fleet.changes import LaneChoice, _choice_groups, _lane_absence, lane_choice
    from intersection_estimator.model import ENTERING, LEAVING
    X = _turns_map([(0, 0, 1, 0), (0, 1, 1, 0), (0, 2, 2, 0)])
    cfg = ChangeConfig()
    sure = _lane_absence('L2', 2, 0, ENTERING, 1.0, 3, X, {2: 1.0}, cfg, LaneChoice(((0.0, 1.0),), 0.0))
    assert sure.log_lr > 15
    slip = _lane_absence('L2', 2, 0, ENTERING, 1.0, 3, X, {2: 1.0}, cfg, LaneChoice(((0.0, 1.0),), 0.1))
    assert slip.log_lr == pytest.approx(log(10.0)) and slip.evidence['lane_off_share'] == 0.1
    # read from a drive: arm 1's leaving lane 0 is the only one mapped from arm 0, 9 vehicles
    # on it and 1 on a leaving lane 1 the map gives no turn from arm 0
    lane = lambda i: SimpleNamespace(id=i)
    arms = [SimpleNamespace(index=0, lanes=lambda d: [lane('a'), lane('b'), lane('c')] if d == ENTERING else []),
            SimpleNamespace(index=1, lanes=lambda d: [lane('x'), lane('y')] if d == LEAVING else [])]
    X.arms = arms
    traffic = SimpleNamespace(lane_turns={('x', 0): 9, ('y', 0): 1, ('c', 2): 1})
    choice = lane_choice(_choice_groups(traffic, X), skip=(0, ENTERING))
    assert choice.off == pytest.approx(1.5 / 11.0)


def test_arm_removed_edit_takes_the_lanes_only_its_turns_needed():
    """With arm 0 gone from the map, arm 1's entering lane whose one turn led into arm 0 and
    arm 2's leaving lane fed only from arm 0 go with it (a map without the arm has no lane
    into nowhere); a lane that also serves another arm stays."""
    from types import SimpleNamespace
    from intersection_estimator.fleet.edits import _arm_removed
    from intersection_estimator.model import Lanelet
    z = np.zeros((2, 2))

    def ll(i, kind, arm, succ=(), arm_to=-1):
        return Lanelet(id=i, kind=kind, arm=arm, left=z, right=z, center=z, successors=list(succ),
                       arm_to=arm_to)
    lls = [ll('in0', 'entering', 0, ['c0_2']), ll('out0', 'leaving', 0),
           ll('in1a', 'entering', 1, ['c1a_0']), ll('in1b', 'entering', 1, ['c1b_0', 'c1b_2']),
           ll('out1', 'leaving', 1), ll('in2', 'entering', 2, ['c2_1']), ll('out2', 'leaving', 2),
           ll('c0_2', 'connector', 0, ['out2'], 2), ll('c1a_0', 'connector', 1, ['out0'], 0),
           ll('c1b_0', 'connector', 1, ['out0'], 0), ll('c1b_2', 'connector', 1, ['out2'], 2),
           ll('c2_1', 'connector', 2, ['out1'], 1)]
    rng = next(np.random.default_rng(s) for s in range(50)
               if np.random.default_rng(s).integers(3) == 0)
    kept, what = _arm_removed(copy.deepcopy(lls), rng, SimpleNamespace(arms=[0, 1, 2]), None)
    assert what == {'arm': 0, 'lanes': [(1, 'entering')]}
    assert sorted(l.id for l in kept) == ['c1b_2', 'c2_1', 'in1b', 'in2', 'out1', 'out2']


def _two_lane_drive(counts):
    """Five arm directions of two entering lanes each, both lanes serving the turn to arm 5;
    ``counts[k] = (vehicles on lane A, on lane B)`` of direction ``k`` (1-4) taking it. The
    judged direction 0 has lanes L0 (3 vehicles) and L1."""
    from types import SimpleNamespace
    from intersection_estimator.model import ENTERING
    keys = [(k, j, 5, 0) for k in range(5) for j in (0, 1)]
    X = _turns_map(keys)
    lane = lambda i: SimpleNamespace(id=i)
    names = {0: ('L0', 'L1'), **{k: (f'A{k}', f'B{k}') for k in range(1, 5)}}
    X.arms = [SimpleNamespace(index=k, lanes=lambda d, k=k: [lane(n) for n in names[k]] if d == ENTERING else [])
              for k in range(5)]
    turns = {('L0', 5): 3}
    for k, (a, b) in counts.items():
        turns.update({(f'A{k}', 5): a, (f'B{k}', 5): b})
    return X, SimpleNamespace(lane_turns={k: v for k, v in turns.items() if v})


def test_an_empty_lane_weighs_what_the_drives_other_lanes_show():
    """``empty_calibration``: one vehicle passed a direction of two lanes for its turn and
    missed L1 (ln 2 nats under even shares). Where each of the drive's other two-lane
    directions had its two vehicles on both lanes (random choice would leave one of the two
    lanes empty half the time), a lane that exists is rarely left empty, and the empty L1 is
    stronger evidence by ``-ln empty_ratio``; where the other directions left a lane empty
    about as often as the model says, it is not. The judged direction's own lanes do not
    vouch for themselves; the switch off leaves the evidence as it was."""
    from math import log
    from intersection_estimator.fleet.changes import _choice_groups, _lane_absence, lane_choice
    from intersection_estimator.model import ENTERING
    on, off = ChangeConfig(), ChangeConfig(empty_calibration=0)

    def judged(counts):
        X, traffic = _two_lane_drive(counts)
        choice = lane_choice(_choice_groups(traffic, X), (0, ENTERING), on.empty_prior)
        return choice, [_lane_absence('L1', 1, 0, ENTERING, 1.0, 2, X, {5: 1.0}, c, choice) for c in (on, off)]

    choice, (f_on, f_off) = judged({k: (1, 1) for k in range(1, 5)})
    assert choice.empty_ratio < 0.5
    assert f_on.log_lr == pytest.approx(f_off.log_lr - log(choice.empty_ratio))
    assert f_on.confidence > 0.5 > f_off.confidence and f_on.evidence['empty_ratio'] == choice.empty_ratio
    # shown by vehicles whose turn was not seen only: the ratio, read on lanes with seen
    # turns, does not speak for it
    X, traffic = _two_lane_drive({k: (1, 1) for k in range(1, 5)})
    unseen = [_lane_absence('L1', 1, 0, ENTERING, 3.0, 2, X, {}, c, choice) for c in (on, off)]
    assert unseen[0].log_lr == unseen[1].log_lr > 0 and 'empty_ratio' not in unseen[0].evidence
    lumpy, (g_on, g_off) = judged({1: (2, 0), 2: (0, 2), 3: (1, 1), 4: (2, 0)})
    assert lumpy.empty_ratio > 0.8 and g_on.confidence < 0.5
    # direction 0's own lanes are left out: more vehicles on L0 change nothing
    X, traffic = _two_lane_drive({k: (1, 1) for k in range(1, 5)})
    traffic.lane_turns[('L0', 5)] = 30
    assert lane_choice(_choice_groups(traffic, X), (0, ENTERING)).empty_ratio == choice.empty_ratio
