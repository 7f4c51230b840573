"""Argoverse 2 converter (issue 15.2): the three scenarios in ../shared/realdata/av2 ->
ground truth from the lane graph, real tracks as detections, a bag that replays."""

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from intersection_estimator.evaluate import evaluate
from intersection_estimator.realdata.av2 import Av2Error, convert, find_scenarios, load_av2
from intersection_estimator.scenarios import gt_doc

REALDATA = Path(__file__).resolve().parents[1].parent / 'shared' / 'realdata'


def _scenarios():
    root = REALDATA / 'av2'
    found = find_scenarios(root) if root.is_dir() else []
    if len(found) != 3:   # fail loudly, never skip: CI has ../shared beside the checkout
        raise AssertionError(f'expected the 3 AV2 scenarios under {root}, found {len(found)}')
    return found


SCENARIOS = _scenarios()


@pytest.fixture(scope='module', params=SCENARIOS, ids=lambda p: p.name[:8])
def scenario(request):
    return request.param, load_av2(request.param)


def test_ground_truth_is_the_lane_graph_junction(scenario):
    _, sc = scenario
    assert 3 <= len(sc.gt.arms) <= 6
    by_id = {ll.id: ll for ll in sc.gt_lanelets}
    cons = [ll for ll in sc.gt_lanelets if ll.kind == 'connector']
    assert cons
    for c in cons:     # every connector joins an entering lane's end to a leaving lane's start
        lin = next(ll for ll in sc.gt_lanelets if c.id in ll.successors)
        lout = by_id[c.successors[0]]
        assert lin.kind == 'entering' and lout.kind == 'leaving'
        assert np.allclose(c.center[0], lin.center[-1]) and np.allclose(c.center[-1], lout.center[0])
        assert lin.arm == c.arm and lout.arm == c.arm_to
    for a, arm in enumerate(sc.gt.arms):
        n_in = sum(ll.kind == 'entering' and ll.arm == a for ll in sc.gt_lanelets)
        n_out = sum(ll.kind == 'leaving' and ll.arm == a for ll in sc.gt_lanelets)
        assert (arm.lanes_in, arm.lanes_out) == (n_in, n_out)


def test_tracked_detections_are_the_real_tracks(scenario):
    folder, sc = scenario
    df = pd.read_parquet(next(folder.glob('scenario_*.parquet')))
    others = df[df['track_id'].astype(str) != 'AV']
    d = sc.detections('tracked')
    assert len(d) == len(others)
    got = np.sort(d.xy[:, 0])
    assert np.array_equal(got, np.sort(others['position_x'].to_numpy(float)))
    assert np.allclose(d.sensor_xy[:, 0], np.interp(d.t * 10, df[df.track_id == 'AV'].timestep,
                                                    df[df.track_id == 'AV'].position_x))


def test_traffic_and_floor_only_where_vehicles_drove(scenario):
    _, sc = scenario
    used = {k for k, v in sc.traffic.items() if v > 0}
    assert used and set(sc.extra_gt) <= used
    doc = gt_doc(sc, arrays=True)
    m = evaluate(doc, doc)
    assert m['topology_correct'] and m['topology_observed_correct']
    assert m['floor_lanes'] == len(sc.extra_gt) and 5.0 < m['floor_cm'] < 100.0


def test_converted_bag_replays(tmp_path):
    from intersection_estimator.replay import replay
    folder = min(SCENARIOS, key=lambda p: p.name)      # the smallest (5 s, 'test' split)
    res = convert(folder, tmp_path / 'case')
    assert res['counts']['/perception/objects'] > 0
    summary = replay([str(tmp_path / 'case' / 'bag')], tmp_path / 'out', progress=False)
    assert summary.ticks > 0 and summary.result is not None
    import json
    est = json.loads((tmp_path / 'out' / 'estimate.json').read_text())
    gt = json.loads((tmp_path / 'case' / 'gt.json').read_text())
    m = evaluate(est, gt)
    assert m['ok'], m['reason']
    assert gt['source']['source'] == 'argoverse2'


def test_bad_folder_is_one_line_error(tmp_path):
    with pytest.raises(Av2Error, match='no scenario_'):
        load_av2(tmp_path)
    with pytest.raises(Av2Error, match='not a folder'):
        load_av2(tmp_path / 'missing')
