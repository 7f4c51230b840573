"""Issue 16: replay over runs that end without an intersection, drives through several
intersections, and gaps in bag time (in-process ``replay()``, small sample budgets).

Every route to "no intersection" writes a valid NO_DATA estimate.json whose stats carry
the drop counts per reason and a one-line ``why``, and exits 3; a drive keeps every
intersection it finished; a gap of an hour costs about what no gap costs.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from intersection_estimator.bagio import BAG_T0, SCENARIO_TOPICS, BagWriter, write_drive_bag
from intersection_estimator.replay import EXIT_NO_INTERSECTION, EXIT_OK, replay
from msg_adapters.odometry import odometry_msg
from msg_adapters.pointcloud2 import radar_cloud_msg
from msg_adapters.types import make_header

PARAMS = """intersection_estimator:
  ros__parameters:
    topology_samples: {topo}
    lane_samples: {lanes}
    timer_period: {period}
    max_observations: {cap}
"""
RADAR, ODOM = SCENARIO_TOPICS['radar'], SCENARIO_TOPICS['odometry']


def params(tmp_path, topo=300, lanes=300, period=1.0, cap=200000):
    p = tmp_path / 'params.yaml'
    p.write_text(PARAMS.format(topo=topo, lanes=lanes, period=period, cap=cap))
    return str(p)


def cloud(T, t, frame='radar', n=20, doppler=True):
    g = np.random.default_rng(int(t * 10))
    xy = g.uniform(-30, 30, (n, 2))
    msg = radar_cloud_msg(T, make_header(T, frame, t), xy, g.normal(0, 5, n))
    if not doppler:                       # a lidar-like cloud: x, y, z only
        msg.fields = msg.fields[:3]
    return msg


def synthetic_bag(path, *, odometry=True, **cloud_args):
    """20 s: odometry (ego standing) and a radar cloud at 10 Hz."""
    with BagWriter(path) as w:
        for k in range(200):
            t = BAG_T0 + 0.1 * k
            if odometry:
                w.write(ODOM, odometry_msg(w.types, t, 0.0, 0.0, 0.0), t)
            w.write(RADAR, cloud(w.types, t, **cloud_args), t)
    return path


ROUTES = {                      # route -> (bag arguments, params arguments, drop reason, words in why)
    'radar_without_odometry': (dict(odometry=False), {}, 'no_ego_pose', 'no ego pose'),
    'empty_frame_id': (dict(frame=''), {}, 'unknown_frame', 'frame_id'),
    'unknown_frame_id': (dict(frame='nowhere'), {}, 'unknown_frame', 'frame_id'),
    'no_doppler_field': (dict(doppler=False), {}, 'no_doppler', 'Doppler'),
    'only_oversized_clouds': (dict(n=150), dict(cap=100), 'too_large', 'max_observations'),
    'empty_clouds': (dict(n=0), {}, None, 'no detections'),
}


@pytest.mark.parametrize('route', sorted(ROUTES))
def test_a_run_without_intersection_writes_no_data_and_says_why(route, tmp_path):
    bag_args, param_args, reason, words = ROUTES[route]
    bag = synthetic_bag(tmp_path / 'bag', **bag_args)
    lines = []
    s = replay([str(bag)], tmp_path / 'out', params_file=params(tmp_path, **param_args),
               progress=False, log=lines.append)
    assert s.exit_code == EXIT_NO_INTERSECTION and s.intersections == []
    est = json.loads((tmp_path / 'out' / 'estimate.json').read_text())
    assert est['center'] is None and est['arms'] == [] and est['lanes'] == []
    assert est['stats']['state'] == 'NO_DATA' and words in est['stats']['why'], est['stats']
    assert est['stats']['received']['radar_topics'] == 200
    if reason is not None:
        assert est['stats']['dropped'][reason] == s.dropped[reason] >= 200 - 1, est['stats']
        # the warning the node would log, printed -- rate-limited per 5 s of bag time, not 200 times
        warned = [ln for ln in lines if ln.startswith('warning:')]
        assert 1 <= len(warned) <= 8, lines
    assert not (tmp_path / 'out' / 'estimate.png').exists()
    assert any(words in ln for ln in s.lines()), s.lines()


def test_pointcloud2_without_doppler_found_by_type_is_named(tmp_path):
    from intersection_estimator.bagio import BagError
    bag = synthetic_bag(tmp_path / 'bag', doppler=False)
    with pytest.raises(BagError) as err:
        replay([str(bag)], tmp_path / 'out', progress=False)
    assert err.value.reason == 'no_doppler' and RADAR in str(err.value) and 'x, y, z' in str(err.value)
    assert not (tmp_path / 'out').exists()


def drive_bag(path, seeds, gap_s=None):
    return write_drive_bag(path, seeds, gap_s=gap_s)


def test_a_drive_keeps_every_intersection(tmp_path):
    bag = drive_bag(tmp_path / 'drive', (3, 5))
    s = replay([str(bag)], tmp_path / 'out', params_file=params(tmp_path, topo=1000, lanes=500, period=0.5),
               progress=False)
    # the drive ends past the second one: the reset left NO_DATA, estimate.json is the last intersection
    assert [i.ended for i in s.intersections] == ['ego_passed', 'ego_passed'], s.lines()
    assert s.result is s.intersections[-1].result
    assert s.exit_code == EXIT_OK
    docs = [json.loads((tmp_path / 'out' / 'intersections' / f'{k:02d}' / 'estimate.json').read_text())
            for k in range(2)]
    assert all(d['arms'] and d['stats']['ended'] for d in docs)
    assert docs[0]['center'] != docs[1]['center']
    top = json.loads((tmp_path / 'out' / 'estimate.json').read_text())
    assert top['center'] == docs[1]['center'] and top['stats']['intersections'] == 2
    for k in range(2):
        assert (tmp_path / 'out' / 'intersections' / f'{k:02d}' / 'estimate.png').stat().st_size > 0
    assert sum('intersection 0' in ln for ln in s.lines()) == 2, s.lines()


def test_an_hour_gap_costs_about_what_no_gap_costs(tmp_path):
    """Two recordings an hour apart in one bag: every idle tick over the gap is free (the
    converged estimate does not sample) and the two intersections are both kept."""
    p = params(tmp_path, topo=300, lanes=300, period=0.5)
    one = replay([str(drive_bag(tmp_path / 'one', (3,), gap_s=0.0))], tmp_path / 'o1', params_file=p,
                 progress=False)
    two = replay([str(drive_bag(tmp_path / 'gap', (3, 3), gap_s=3600.0))], tmp_path / 'o2', params_file=p,
                 progress=False)
    assert [i.ended for i in two.intersections] == ['time_base_reset', 'end_of_input'], two.lines()
    # without the idle rule: 7200 ticks at the full budget across the gap
    assert two.idle_ticks > 7000 and two.ticks <= 2 * one.ticks + 2 * 25 + 10, (one.ticks, two.ticks)
    assert two.wall_s < 3 * one.wall_s + 20, (one.wall_s, two.wall_s)
