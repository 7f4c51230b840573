"""Live map-change detection (issue 17): the node's estimate against a prior map gives the
change the offline fleet gives, as MapChangeArray and ``map_changes`` markers."""

from __future__ import annotations

import numpy as np
import pytest

from intersection_estimator.export.osm import write_osm
from intersection_estimator.fleet.edits import EXPECTED, apply_edit
from intersection_estimator.fleet.live import LiveChanges


@pytest.fixture
def live(tmp_path, cases):
    """seed 5's estimate and a LiveChanges of its ground truth with one lane moved by 1 m."""
    sc, r = cases[5]
    lls, what = apply_edit(sc, 'lane_moved', np.random.default_rng(5))
    return r, LiveChanges.load(write_osm(tmp_path / 'prior.osm', lls), origin=(49.0, 8.4)), what


def test_live_report_names_the_moved_lane_and_nothing_else(live):
    r, changes, what = live
    rep = changes.update(r.intersection, r.lanelets)
    assert rep.mapped is not None and rep.intersection_id == rep.mapped.id
    assert [c.kind for c in rep.changes] == [EXPECTED['lane_moved']]
    names = {l.id: l.name for a in rep.mapped.arms for l in a.lanes_in + a.lanes_out}
    assert [names[i] for i in rep.changes[0].map_lanes] == [what['lane']]
    assert rep.passages > 0


def test_unchanged_map_and_far_estimate_report_nothing(tmp_path, cases):
    sc, r = cases[1]
    changes = LiveChanges.load(write_osm(tmp_path / 'same.osm', sc.gt_lanelets), origin=(49.0, 8.4))
    assert changes.update(r.intersection, r.lanelets).changes == []
    far = type(r.intersection)(center=np.asarray(r.intersection.center) + 500.0, arms=r.intersection.arms)
    rep = changes.update(far, r.lanelets)
    assert rep.mapped is None and rep.intersection_id == '' and rep.changes == []
    assert changes.update(None, []).mapped is None


def test_messages_and_markers(live):
    from intersection_estimator.bagio import typestore
    from msg_adapters.map_changes import NAMESPACE, map_change_markers, map_changes_msg
    from msg_adapters.types import RosbagsTypes, make_header
    r, changes, _ = live
    T = RosbagsTypes(typestore())
    header = make_header(T, 'map', 100.0)
    rep = changes.update(r.intersection, r.lanelets)
    msg = map_changes_msg(T, header, rep)
    assert msg.intersection_id == rep.intersection_id and len(msg.changes) == 1
    c = msg.changes[0]
    assert c.kind == 'lane_moved' and 0.5 <= c.confidence <= 1.0 and list(c.map_lanelet_ids)
    ev = dict(zip(c.evidence_keys, c.evidence_values))
    assert 0.75 < ev['mean_offset_m'] < 1.3 and ev['passages'] > 0
    markers, keys = map_change_markers(T, header, rep)
    assert keys and {m.ns for m in markers.markers} == {NAMESPACE}
    strips = [m for m in markers.markers if m.type == 4]
    assert len(strips) == len(c.map_lanelet_ids)
    # nothing to report any more: the previous markers are deleted
    from intersection_estimator.fleet.live import LiveReport
    gone, keys2 = map_change_markers(T, header, LiveReport(None), keys)
    assert keys2 == frozenset() and all(m.action == 2 for m in gone.markers) and len(gone.markers) == len(keys)


def test_a_comparison_in_two_halves_reports_what_one_call_does(live, cases):
    """The node runs map matching and the rules in two ticks (LiveChanges.match, then update
    with it): the same report as one call with the window."""
    r, changes, _ = live
    sc, _ = cases[5]
    window = sc.detections('tracked')
    matched = changes.match(r.intersection, window)
    assert matched.mapped is not None and matched.traffic is not None and matched.traffic.vehicles
    one = changes.update(r.intersection, r.lanelets, window)
    two = changes.update(r.intersection, r.lanelets, None, matched=matched)
    assert [(c.key, c.confidence) for c in two.changes] == [(c.key, c.confidence) for c in one.changes]
    assert two.unobserved == one.unobserved and two.passages == one.passages
    assert changes.match(None).mapped is None
