"""Two radars on one vehicle, recorded as a real stack writes them: each on its own topic,
in receive order, one with more latency than the other -- so a scan of the slow radar
reaches the node after a newer scan of the fast one. The radar tracker runs in the tick
on the scans queued since the last one (in stamp order) and holds the newest
``radar_track_reorder_s`` for the next; a scan later than that is dropped, counted
(``radar_scan_late``) and logged once per period (replay end to end). The slow radar's
latency here (350 ms) is more than a tick period (200 ms): within one the queue alone
would put the scans in order."""

from __future__ import annotations

import pytest

from intersection_estimator.bagio import SCENARIO_TOPICS, BagWriter, scenario_messages
from intersection_estimator.replay import replay
from intersection_estimator.sim import SimConfig, simulate_scenario

FRONT, CORNER = '/radar/front/points', '/radar/corner/points'
PARAMS = """intersection_estimator:
  ros__parameters:
    radar_topics: ['{front}', '{corner}']
    object_topics: ['']
    detection_topics: ['']
    topology_samples: 600
    lane_samples: 600
    radar_track_reorder_s: {reorder}
"""


def _two_radar_bag(path, latency_corner: float):
    """The scenario's radar scans alternately from FRONT (20 ms latency) and CORNER
    (``latency_corner``), written at their receive time (the bag's log time)."""
    sc = simulate_scenario(3, SimConfig(duration=(30.0, 30.0)))
    with BagWriter(path) as w:
        msgs, k = [], 0
        for t, topic, msg in scenario_messages(sc, w.types, sensors=('raw',)):
            if topic == SCENARIO_TOPICS['radar']:
                topic, t = (CORNER, t + latency_corner) if k % 2 else (FRONT, t + 0.02)
                k += 1
            msgs.append((t, len(msgs), topic, msg))
        for t, _, topic, msg in sorted(msgs, key=lambda m: m[:2]):
            w.write(topic, msg, t)
    return sc


@pytest.fixture(scope='module')
def bag(tmp_path_factory):
    path = tmp_path_factory.mktemp('two_radars') / 'bag'
    sc = _two_radar_bag(path, 0.35)
    return path, len(sc.gt.arms)


def _params(tmp_path, reorder: float) -> str:
    p = tmp_path / f'params_{reorder}.yaml'
    p.write_text(PARAMS.format(front=FRONT, corner=CORNER, reorder=reorder))
    return str(p)


def test_a_slow_radar_interleaves_with_a_fast_one(bag, tmp_path):
    path, n_arms = bag
    s = replay([str(path)], tmp_path / 'out', params_file=_params(tmp_path, 0.2), progress=False,
               write_outputs=False)
    assert s.received['radar_topics'] > 200
    assert 'radar_scan_late' not in s.dropped, s.dropped
    assert len(s.result.intersection.arms) == n_arms


def test_without_the_hold_the_slow_radars_scans_are_late_counted_and_logged(bag, tmp_path):
    path, _ = bag
    lines = []
    s = replay([str(path)], tmp_path / 'out', params_file=_params(tmp_path, 0.0), progress=False,
               write_outputs=False, log=lines.append)
    assert s.dropped.get('radar_scan_late', 0) > 0.3 * s.received['radar_topics'], s.dropped
    late = [x for x in lines if 'radar_track_reorder_s' in x]
    assert late and len(late) < 0.1 * s.dropped['radar_scan_late']
