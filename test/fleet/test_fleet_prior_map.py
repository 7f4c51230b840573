"""Prior map: a Lanelet2 OSM map -> intersections of its lane graph (issue 17, slice 1)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from intersection_estimator.export.osm import write_osm
from intersection_estimator.fleet.changes import compare
from intersection_estimator.fleet.match import match_arms, match_intersection
from intersection_estimator.fleet.prior_map import (PriorMapError, derive_intersections, load_prior_map,
                                                    records_from_lanelets)
from intersection_estimator.sim import simulate_scenario


def _summary(X):
    return [(round(math.degrees(a.angle), 3), [l.name for l in a.lanes_in], [l.name for l in a.lanes_out])
            for a in X.arms]


@pytest.mark.parametrize('seed', [0, 3, 11])
def test_osm_intersection_is_the_ground_truth(tmp_path, seed):
    sc = simulate_scenario(seed)
    (X,) = load_prior_map(write_osm(tmp_path / 'map.osm', sc.gt_lanelets))
    assert np.hypot(*(X.center - sc.gt.center)) < 0.05
    assert X.traffic_side == 1
    assert len(X.arms) == len(sc.gt.arms)
    for a, g, (ang, ins, outs) in zip(X.arms, sc.gt.arms, _summary(X)):
        assert abs(math.remainder(a.angle - g.angle, 2 * math.pi)) < math.radians(0.5)
        i = sc.gt.arms.index(g)
        # lane index 0 = next to the median, as in the model and the simulator's ids
        assert ins == [f'a{i}_in{k}' for k in range(g.lanes_in)]
        assert outs == [f'a{i}_out{k}' for k in range(g.lanes_out)]
    gt_con = sorted(l.id for l in sc.gt_lanelets if l.kind == 'connector')
    assert sorted(c.name for c in X.connectors) == gt_con
    for c in X.connectors:        # key (arm, k_in, arm_to, k_out) is the simulator's id
        assert c.name == 'c_a%di%d_a%do%d' % c.key


def test_model_lanelets_give_the_same_intersection(tmp_path):
    sc = simulate_scenario(4)
    (A,) = load_prior_map(write_osm(tmp_path / 'map.osm', sc.gt_lanelets))
    (B,) = derive_intersections(records_from_lanelets(sc.gt_lanelets))
    assert _summary(A) == _summary(B)
    assert [c.key for c in A.connectors] == [c.key for c in B.connectors]


def test_two_intersections_in_one_map(tmp_path):
    a, b = simulate_scenario(1), simulate_scenario(2)
    shift = np.array([400.0, 0.0]) - b.gt.center + a.gt.center
    lls = list(a.gt_lanelets)
    for l in b.gt_lanelets:
        l2 = type(l)(**{**l.__dict__, 'id': 'B' + l.id, 'successors': ['B' + s for s in l.successors],
                        'left': l.left + shift, 'right': l.right + shift, 'center': l.center + shift})
        lls.append(l2)
    found = load_prior_map(write_osm(tmp_path / 'map.osm', lls))
    assert len(found) == 2
    assert match_intersection(a.gt.center, found).center == pytest.approx(a.gt.center, abs=0.05)
    assert match_intersection(b.gt.center + shift, found) is not None
    assert match_intersection(a.gt.center + [0, 200.0], found) is None


def test_bad_map_is_one_line_error(tmp_path):
    p = tmp_path / 'bad.osm'
    p.write_text('<osm version="0.6"></osm>')
    with pytest.raises(PriorMapError, match='no lanelets'):
        load_prior_map(p)
    with pytest.raises(PriorMapError, match='projector'):
        load_prior_map(p, projector='mercator')


def test_match_arms_hungarian_and_gate():
    m = match_arms([0.0, 1.6, 3.1], [math.radians(5), math.radians(-178), math.radians(90)])
    assert m == {0: 0, 1: 2, 2: 1}
    assert match_arms([0.0], [math.radians(40)]) == {}


@pytest.mark.parametrize('seed', [1, 2, 5])
def test_round_trip_no_change(tmp_path, cases, seed):
    """Our exported lanelets.osm as prior -> no change: the estimate's own export, and the
    case's ground-truth export against the estimate."""
    sc, r = cases[seed]
    for lls in (r.lanelets, sc.gt_lanelets):
        (X,) = load_prior_map(write_osm(tmp_path / 'prior.osm', lls))
        view = compare(r.intersection, r.lanelets, X)
        assert view.findings == []
        assert view.unobserved == []
        assert len(view.counts_ok) == 2 * len(X.arms)
