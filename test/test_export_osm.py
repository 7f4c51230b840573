"""Lanelet2 OSM export: the map loads and routes entering -> connector -> leaving (DESIGN §6)."""

from __future__ import annotations

import numpy as np
import pytest

lanelet2 = pytest.importorskip('lanelet2')
from lanelet2.routing import RoutingGraph  # noqa: E402
from lanelet2.traffic_rules import Locations, Participants, create  # noqa: E402

from intersection_estimator.export.osm import load_osm, turn_direction, write_osm  # noqa: E402
from intersection_estimator.lanes import LaneConfig, LaneCourseEstimator  # noqa: E402
from intersection_estimator.sim import simulate_scenario  # noqa: E402

SC = simulate_scenario(3)


def _routing(path):
    m = load_osm(path)
    graph = RoutingGraph(m, create(Locations.Germany, Participants.Vehicle))
    return m, graph, {ll.attributes['ie:id']: ll for ll in m.laneletLayer}


def _check_routes(lanelets, path):
    write_osm(path, lanelets)
    m, graph, by = _routing(path)
    assert len(by) == len(lanelets)
    ids = {l.id: l for l in lanelets}
    n = 0
    for e in lanelets:
        if e.kind != 'entering':
            continue
        following = {x.attributes['ie:id'] for x in graph.following(by[e.id])}
        for cid in e.successors:
            c = ids[cid]
            assert cid in following
            leave = c.successors[0]
            assert leave in {x.attributes['ie:id'] for x in graph.following(by[cid])}
            route = graph.getRoute(by[e.id], by[leave])
            assert route is not None
            path_ids = [x.attributes['ie:id'] for x in route.shortestPath()]
            assert path_ids[0] == e.id and path_ids[-1] == leave
            n += 1
    return m, n


def test_gt_map_routes_every_connection(tmp_path):
    m, n = _check_routes(SC.gt_lanelets, tmp_path / 'gt.osm')
    assert n == sum(l.kind == 'connector' for l in SC.gt_lanelets) > 0


def test_estimated_map_routes_and_keeps_metric_coordinates(tmp_path):
    est = LaneCourseEstimator(LaneConfig(), 0)
    est.initialise(SC.gt, SC.detections('tracked'))
    est.run(n_samples=2000)
    ls = est.lanelets
    m, n = _check_routes(ls, tmp_path / 'est.osm')
    assert n == sum(l.kind == 'connector' for l in ls) > 0
    # every GT connection that carried traffic is routable in the estimate
    _, graph, by = _routing(tmp_path / 'est.osm')
    ll_by = {l.id: l for l in ls}
    for g in SC.gt_lanelets:
        if g.kind == 'connector' and SC.traffic[g.id] >= 2:
            gin = next(x for x in SC.gt_lanelets if g.id in x.successors)
            e_in = f'a{gin.arm}_in{gin.lane_index}'
            e_out = 'a{}_out{}'.format(g.arm_to, g.successors[0].rsplit('out', 1)[1])
            assert e_in in ll_by and e_out in ll_by
            assert graph.getRoute(by[e_in], by[e_out]) is not None
    # coordinates survive the projection round trip; consecutive lanelets share nodes
    for l in ls:
        ll = by[l.id]
        xy = np.array([[p.x, p.y] for p in ll.leftBound])
        np.testing.assert_allclose(xy, l.left, atol=2e-3)
        for s in l.successors:
            nxt = by[s]
            assert ll.leftBound[-1].id == nxt.leftBound[0].id
            assert ll.rightBound[-1].id == nxt.rightBound[0].id


def test_attributes_and_ids(tmp_path):
    path = tmp_path / 'm.osm'
    write_osm(path, SC.gt_lanelets, origin_latlon=(48.0, 11.0))
    assert '<relation' in path.read_text()
    m = load_osm(path, origin_latlon=(48.0, 11.0))
    kinds = {}
    for ll in m.laneletLayer:
        a = ll.attributes
        assert a['type'] == 'lanelet' and a['subtype'] == 'road' and ll.id > 0
        kinds.setdefault(a['ie:kind'], []).append(ll)
        if a['ie:kind'] == 'connector':
            assert a['turn_direction'] in ('straight', 'left', 'right')
            assert ll.leftBound.attributes['type'] == 'virtual'
        else:
            assert ll.leftBound.attributes['type'] == 'line_thin'
    assert all(p.id > 0 for p in m.pointLayer) and all(ls.id > 0 for ls in m.lineStringLayer)
    # neighbouring same-direction lanes share one dashed border linestring
    dashed = [ls for ls in m.lineStringLayer if ls.attributes['type'] == 'line_thin'
              and ls.attributes['subtype'] == 'dashed']
    assert dashed


def test_turn_direction():
    assert turn_direction(np.array([[0, 0], [1, 0], [2, 0]])) == 'straight'
    assert turn_direction(np.array([[0, 0], [1, 0], [1, 1]])) == 'left'
    assert turn_direction(np.array([[0, 0], [1, 0], [1, -1]])) == 'right'
