"""Change detection on constructed prior maps (issue 17, slice 2): each kind found, nothing
else claimed; removals only where the data can show them."""

from __future__ import annotations

import copy
from dataclasses import replace

import numpy as np
import pytest

from intersection_estimator.export.osm import write_osm
from intersection_estimator.fleet.changes import ChangeConfig, compare
from intersection_estimator.fleet.edits import EDITS, EXPECTED, apply_edit
from intersection_estimator.fleet.prior_map import load_prior_map

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
    view = compare(r.intersection, r.lanelets, X)
    assert [f.kind for f in view.findings] == [EXPECTED[edit]], (what, view.findings)
    f = view.findings[0]
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
    """A mapped arm without traffic: 'unobserved' unless the passages that missed it outweigh
    the prior; the evidence is the (1 - 1/arms)^passages absence likelihood."""
    sc, r = cases[5]
    X = _prior(tmp_path, sc.gt_lanelets)
    I, lls = _drop_arm(r, 1)
    few = compare(I, lls, X, ChangeConfig(absence_prior=1e-12))
    assert few.findings == [] and few.unobserved == [1]
    assert 'arm_removed' in [f.kind for f in few.weak]
    many = compare(I, lls, X)
    (f,) = many.findings
    assert f.kind == 'arm_removed' and many.unobserved == []
    assert f.log_lr == pytest.approx(-many.passages * np.log(1 - 1 / 3))
    assert f.evidence['passages'] == pytest.approx(many.passages)


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
