"""Issue 16, what a replay writes beside the estimate: the geo origin of ``lanelets.osm``
(``--origin`` / ``geo_origin``), the plot's title and ego, and /tf + /tf_static from the bag
(sensor mounts the parameters do not know)."""

from __future__ import annotations

import json

import pytest

from intersection_estimator import params as P
from intersection_estimator.bagio import BAG_T0, BagWriter
from intersection_estimator.export.osm import read_origin
from intersection_estimator.replay import replay
from msg_adapters.odometry import odometry_msg

from test_ingest_tf import tf_msg
from test_replay_cli import run
from test_replay_routes import ODOM, RADAR, cloud, drive_bag, params


@pytest.fixture(scope='module')
def drive(tmp_path_factory):
    return drive_bag(tmp_path_factory.mktemp('drive') / 'drive', (3,))


def test_origin_option_is_written_into_every_map(drive, tmp_path):
    s = replay([str(drive)], tmp_path / 'out', params_file=params(tmp_path, topo=600, lanes=300, period=0.5),
               progress=False, origin=(52.52, 13.405))
    assert s.intersections
    for osm in [tmp_path / 'out' / 'lanelets.osm', *sorted((tmp_path / 'out').glob('intersections/*/lanelets.osm'))]:
        assert read_origin(osm) == (52.52, 13.405), osm
    assert s.intersections[-1].ego is not None and len(s.intersections[-1].ego) == 3


def test_geo_origin_parameter_is_the_default_and_checked(drive, tmp_path):
    p = tmp_path / 'params.yaml'
    p.write_text(open(params(tmp_path, topo=400, lanes=0, period=0.5)).read() + '    geo_origin: [-33.9, 18.4]\n')
    replay([str(drive)], tmp_path / 'out', params_file=str(p), progress=False)
    assert read_origin(tmp_path / 'out' / 'lanelets.osm') == (-33.9, 18.4)
    bad = dict(P.defaults(), geo_origin=[95.0, 8.4])
    assert any('geo_origin' in e and 'latitude' in e for e in P.check_all(bad))
    assert any('geo_origin' in e for e in P.check_all(dict(P.defaults(), geo_origin=[49.0])))


@pytest.mark.parametrize('origin', ['91,8', '49', 'north,east'])
def test_bad_origin_option_is_one_line_and_exit_1(drive, origin, tmp_path):
    code, _, stderr = run('replay', str(drive), '--out', tmp_path / 'x', '--origin', origin, '--quiet')
    assert code == 1 and len(stderr) == 1 and '--origin' in stderr[0], stderr
    assert not (tmp_path / 'x').exists()


def _mounted_bag(path, with_tf: bool):
    """Radar in a frame the default parameters do not mount ('radar_left'); its mount only
    on /tf_static (when ``with_tf``)."""
    with BagWriter(path) as w:
        if with_tf:
            w.write('/tf_static', tf_msg(w.types, [(BAG_T0, 'base_link', 'radar_left', (1.0, 0.5, 0.3))]), BAG_T0)
        for k in range(60):
            t = BAG_T0 + 0.1 * k
            w.write(ODOM, odometry_msg(w.types, t, 0.0, 0.0, 0.0), t)
            w.write(RADAR, cloud(w.types, t, frame='radar_left'), t)
    return path


def test_tf_static_in_the_bag_mounts_a_sensor_frame(tmp_path):
    out = {}
    for with_tf in (False, True):
        bag = _mounted_bag(tmp_path / f'bag_{with_tf}', with_tf)
        s = replay([str(bag)], tmp_path / f'out_{with_tf}', params_file=params(tmp_path, topo=100, lanes=0),
                   progress=False)
        out[with_tf] = s
    assert out[False].dropped.get('unknown_frame', 0) == 60
    assert out[True].dropped.get('unknown_frame', 0) == 0
    assert out[True].received.get('tf_static') == 1
    assert out[True].messages == out[False].messages == 120      # tf is not counted as input


def test_plot_title_names_the_intersection_and_how_it_ended(drive, tmp_path, monkeypatch):
    import intersection_estimator.export.plot as plot
    seen = []
    real = plot.plot_estimate

    def spy(path, *a, **kw):
        seen.append(kw)
        return real(path, *a, **kw)
    monkeypatch.setattr(plot, 'plot_estimate', spy)
    replay([str(drive)], tmp_path / 'out', params_file=params(tmp_path, topo=400, lanes=0, period=0.5),
           progress=False)
    assert seen and seen[0]['title'].startswith('intersection 00') and seen[0]['frame'] == 'map'
    assert seen[0]['ego'] is not None and seen[0]['stamp'] is not None
    doc = json.loads((tmp_path / 'out' / 'estimate.json').read_text())
    assert doc['stats']['ended'] in ('ego_passed', 'end_of_input')
