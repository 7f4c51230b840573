"""Fusion of several drives (issue 17): evidence adds up, confidence grows with independent
drives, contradicting drives outvote a single one, completion order does not matter."""

from __future__ import annotations

import itertools
import json
import math

import pytest

from intersection_estimator.fleet.changes import ChangeConfig, DriveView, Finding
from intersection_estimator.fleet.fuse import fuse


def _view(findings=(), arm_conf=0.95, used=()):
    return DriveView(intersection='X1', findings=list(findings), arm_conf={0: arm_conf, 1: arm_conf},
                     counts_ok={(0, 'in'), (0, 'out'), (1, 'in'), (1, 'out')}, used=set(used),
                     total_conf=0.99, passages=10.0, unobserved=[])


def _moved(conf=0.9, offset=1.0):
    return Finding('lane_moved', 'lane_moved:7', conf, 0, 'in', ['7'], {'passages': 5.0, 'offset_m': offset})


def test_confidence_grows_with_independent_drives():
    c = [fuse([(f'd{i}', _view([_moved()])) for i in range(n)])['X1'].changes[0] for n in (1, 3, 10)]
    assert c[0].confidence == pytest.approx(0.9)
    assert c[0].confidence < c[1].confidence < c[2].confidence < 1.0
    assert [x.evidence['passages'] for x in c] == [5.0, 15.0, 50.0]
    assert c[1].evidence['drives_showing'] == 3


def test_single_drive_outvoted_by_drives_that_saw_the_lane():
    views = [('a', _view([_moved(0.9)])), ('b', _view()), ('c', _view())]
    X = fuse(views)['X1']
    assert X.changes == [] and len(X.candidates) == 1
    assert X.candidates[0].evidence['drives_contradicting'] == 2


def test_a_drive_without_the_turn_does_not_contradict_it():
    added = Finding('connector_added', 'connector_added:0.0-1.0', 0.9, 0, 'in', ['1', '2'], {'passages': 3.0})
    X = fuse([('a', _view([added])), ('b', _view()), ('c', _view())])['X1']
    assert [c.kind for c in X.changes] == ['connector_added']
    assert X.changes[0].evidence['drives_not_seeing'] == 2
    assert X.changes[0].confidence == pytest.approx(0.9)


def test_weak_arm_observation_does_not_count_against():
    views = [('a', _view([_moved(0.9)])), ('b', _view(arm_conf=0.3))]
    assert fuse(views)['X1'].changes[0].confidence == pytest.approx(0.9)


def test_weak_absences_add_up_over_drives():
    cfg = ChangeConfig()
    from intersection_estimator.fleet.changes import _absence
    gone = _absence('lane_removed', 'lane_removed:0in', 1.5, 0.5, cfg, map_arm=0, direction='in',
                    map_lanes=['9'])
    assert gone.confidence < 0.5                        # one short drive: not enough
    v = _view()
    v.counts_ok.discard((0, 'in'))
    v.weak = [gone]
    assert fuse([('a', v)])['X1'].changes == []
    X = fuse([(d, v) for d in 'abc'])['X1']             # three such drives: 3 x 1.5 passages
    (c,) = X.changes
    assert c.kind == 'lane_removed' and c.evidence['passages'] == 4.5 and c.confidence > 0.5


def test_order_independent_bitwise():
    views = [(f'd{i}', _view([_moved(0.6 + 0.037 * i, 0.8 + 0.01 * i)] if i % 3 else [])) for i in range(7)]
    ref = None
    for perm in itertools.islice(itertools.permutations(views), 0, 5040, 97):
        X = fuse(list(perm), ChangeConfig())['X1']
        got = json.dumps([(c.key, c.confidence, c.evidence) for c in X.changes + X.candidates])
        ref = ref or got
        assert got == ref


def _missing(lane, passages=4.0, post=None, share=0.5):
    """A drive's absence of mapped lane ``lane`` after ``passages`` vehicles of its turns; with
    ``post``, read under that lane-choice concentration posterior (:class:`LaneChoice`)."""
    from intersection_estimator.fleet.changes import _absence, _absence_llr, _mixed
    cfg = ChangeConfig()
    if post is None:
        return _absence('lane_removed', f'lane_removed:{lane}', passages, share, cfg, map_arm=0,
                        direction='in', map_lanes=[lane])
    llr = _mixed(post, lambda k: _absence_llr(passages, share, cfg, k))
    return _absence('lane_removed', f'lane_removed:{lane}', passages, share, cfg, llr=llr, map_arm=0,
                    direction='in', map_lanes=[lane], evidence={'lane_choice_post': list(post)})


def _absent_view(f, seen=()):
    """A drive without the mapped lane count of arm 0's entering side showing the absence
    ``f`` (a finding, or a weak one below 0.5), having driven the lanes ``seen``."""
    v = _view()
    v.counts_ok.discard((0, 'in'))
    v.findings, v.weak = ([f], []) if f.confidence > 0.5 else ([], [f])
    v.lanes_seen = set(seen)
    return v


def test_drives_missing_different_lanes_do_not_add_up():
    """Short drives each miss *another* lane of one arm: the lane one drive missed, the
    others drove (``lanes_seen``), so nothing is removed."""
    views = [(f'd{d}', _absent_view(_missing(gone), {seen}))
             for d, (gone, seen) in enumerate((('8', '9'), ('9', '8'), ('8', '9'), ('9', '8')))]
    X = fuse(views)['X1']
    assert X.changes == []
    assert {c.key for c in X.candidates} == {'lane_removed:8', 'lane_removed:9'}
    assert all(c.evidence['drives_contradicting'] == 2 for c in X.candidates)


def test_no_evidence_is_no_change():
    """Fused log odds 0 (a key only weak findings without evidence carry) is not reported;
    the old rule reported it at exactly 0.5."""
    weak = Finding('lane_moved', 'lane_moved:7', 0.3, 0, 'in', ['7'], {'passages': 1.0}, log_lr=0.0, prior=0.0)
    v = _view()
    v.weak = [weak]
    X = fuse([('a', v)])['X1']
    assert X.changes == [] and [c.confidence for c in X.candidates] == [0.5]


def test_lane_moved_contradicted_by_the_vehicles_that_saw_the_lane():
    """A drive refutes a moved lane by the vehicles it saw on it (lane_conf, logit = n / 3)."""
    import math
    few = _view()
    few.lane_conf = {'7': 1 / (1 + math.exp(-1 / 3))}          # one vehicle on the lane
    many = _view()
    many.lane_conf = {'7': 1 / (1 + math.exp(-6 / 3))}         # six
    show = _moved(1 / (1 + math.exp(-1.0)))                    # log LR 1
    assert fuse([('a', _view([show])), ('b', few)])['X1'].changes[0].evidence['log_odds'] == pytest.approx(1 - 1 / 3)
    assert fuse([('a', _view([show])), ('b', many)])['X1'].changes == []


def test_traffic_on_a_quiet_arm_or_lane_refutes_its_absence():
    """A drive that matched the mapped arm, or whose vehicles drove the mapped lane, refutes
    its removal whatever the arm's confidence (here 0.49 = 2 passages): the confidence says
    how much traffic the arm explains, not whether it is real. The old gate (arm > 0.5) let
    those drives count nothing while each drive that missed the arm or lane added its
    absence evidence."""
    from intersection_estimator.fleet.changes import _absence
    cfg = ChangeConfig()
    gone_arm = _absence('arm_removed', 'arm_removed:1', 16.0, 0.25, cfg, map_arm=1, map_lanes=['5', '6'])
    gone_lane = _missing('9', passages=6.0)
    assert gone_arm.confidence > 0.5 and gone_lane.confidence > 0.5
    views = []
    for d in range(3):                                  # three drives miss both
        v = _view()
        del v.arm_conf[1]
        v.findings = [gone_arm, gone_lane]
        views.append((f'miss{d}', v))
    for d in range(3):                                  # three drives saw them, on a quiet arm
        v = _view(arm_conf=0.49)
        v.counts_ok.discard((0, 'in'))
        v.lanes_seen = {'9'}
        views.append((f'saw{d}', v))
    X = fuse(views, cfg)['X1']
    assert X.changes == [], [(c.key, c.confidence) for c in X.changes]
    assert all(c.evidence['drives_contradicting'] == 3 for c in X.candidates)


def _empty_lane(post):
    """Lane 9 empty after 6 vehicles of its turns, under lane-choice posterior ``post``."""
    return _missing('9', passages=6.0, post=post)


def _fused_empty_lane(post, drives):
    X = fuse([(f'd{d}', _absent_view(_empty_lane(post))) for d in range(drives)])['X1']
    return (X.changes + X.candidates)[0]


def test_drivers_who_keep_to_one_lane_do_not_remove_it_drive_after_drive():
    """A lane drivers avoid out of habit stays empty in every drive: with concentrated lane
    choice the drives share one share of the lane, so ten empty drives are far less than ten
    times the evidence of one: 60 vehicles that all missed the lane leave it at even odds,
    where ten independent drives would remove it (module doc of fuse)."""
    from intersection_estimator.fleet.fuse import shared_share
    habit = ((0.5, 1.0),)
    one = _fused_empty_lane(habit, 1)
    ten = _fused_empty_lane(habit, 10)
    assert shared_share([_empty_lane(habit)], ChangeConfig()) == 1.0       # one drive: as it was
    assert one.evidence['log_odds'] == pytest.approx(_empty_lane(habit).log_lr + _empty_lane(habit).prior)
    gain = ten.evidence['log_odds'] - one.evidence['log_odds']
    assert 0.0 < ten.evidence['absence_kept'] < 0.5
    assert 0.0 < gain < 9 * _empty_lane(habit).log_lr / 2
    summed = 10 * _empty_lane(habit).log_lr + _empty_lane(habit).prior   # drives as independent
    assert 1.0 / (1.0 + math.exp(-summed)) > 0.99 and ten.confidence < 0.7


def test_evenly_spread_drivers_still_add_up_their_empty_lane():
    """Drivers who spread evenly over the lanes (exact shares, concentration 0): every drive's
    empty lane is independent evidence and the sum stands, as before."""
    even = ((0.0, 1.0),)
    ten = _fused_empty_lane(even, 10)
    assert 'absence_kept' not in ten.evidence
    assert ten.evidence['log_odds'] == pytest.approx(10 * _empty_lane(even).log_lr + _empty_lane(even).prior)
    assert ten.confidence > 0.99


def test_a_drive_that_shows_the_absence_with_no_passage_does_not_stop_the_pooling():
    """A drive can show an absence with no passage behind it (its term is 0): it adds nothing
    to either sum, so the other drives still share one share of the lane; before, one such
    drive made every drive count as independent again."""
    from intersection_estimator.fleet.fuse import shared_share
    habit = ((0.5, 1.0),)
    busy = [_empty_lane(habit) for _ in range(5)]
    idle = _missing('9', passages=0.0, post=habit)
    assert idle.log_lr == 0.0
    with_idle = shared_share(busy + [idle], ChangeConfig())
    assert with_idle == pytest.approx(shared_share(busy, ChangeConfig()))
    assert 0.0 < with_idle < 0.5
