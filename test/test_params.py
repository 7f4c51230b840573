"""Parameter table: defaults valid, YAML round trip, bad values refused with their name."""

from __future__ import annotations

import pytest

from conftest import ROOT
from intersection_estimator import params as P
from intersection_estimator.tracking import TrackerConfig


def test_defaults_are_valid_and_match_the_shipped_yaml():
    assert P.check_all(P.defaults()) == []
    assert P.load_yaml(ROOT / 'config' / 'intersection_estimator.yaml') == P.defaults()
    cfg = P.pipeline_config(P.defaults())
    assert cfg.budget_s == pytest.approx(0.150)


@pytest.mark.parametrize('name, value', [
    ('budget_ms', -5.0), ('budget_ms', float('nan')), ('timer_period', 0.0), ('lane_share', 1.0),
    ('doppler_sign', 0), ('seed', -1), ('window_s', 'long'), ('lanes_enabled', 1),
    ('min_existence_probability', 1.5), ('radar_topics', '/not/a/list'),
    ('radar_tracking', 'yes'), ('radar_track_spread_along', 0.0), ('radar_track_doppler_tol', -1.0)])
def test_bad_value_is_refused_naming_the_parameter(name, value):
    reason = P.check(name, value)
    assert reason is not None and name in reason


def test_ints_are_accepted_for_float_parameters():
    assert P.check('budget_ms', 100) is None


def test_mount_lists_must_line_up():
    values = dict(P.defaults(), mount_x=[1.0, 2.0])
    assert any('mount_x' in e for e in P.check_all(values))


def test_yaml_with_a_bad_value_names_file_and_parameter(tmp_path):
    f = tmp_path / 'p.yaml'
    f.write_text('intersection_estimator:\n  ros__parameters:\n    budget_ms: 0.0\n')
    with pytest.raises(ValueError, match='budget_ms'):
        P.load_yaml(f)


def test_unknown_parameter_is_refused(tmp_path):
    f = tmp_path / 'p.yaml'
    f.write_text('intersection_estimator:\n  ros__parameters:\n    budjet_ms: 10.0\n')
    with pytest.raises(ValueError, match='budjet_ms'):
        P.load_yaml(f)


def test_weak_labels_reach_the_topology_and_bad_ones_are_refused():
    cfg = P.pipeline_config(P.defaults())
    assert cfg.topology.weak_labels == cfg.lanes.skip_labels == (6, 7)
    none = P.pipeline_config(dict(P.defaults(), weak_labels=[]))
    assert none.topology.weak_labels == none.lanes.skip_labels == ()
    for bad in (['bike'], [6.5], [300], [True]):
        assert any('weak_labels' in e for e in P.check_all(dict(P.defaults(), weak_labels=bad)))


def test_radar_tracker_parameters_reach_the_pipeline():
    cfg = P.pipeline_config(dict(P.defaults(), radar_tracking=False, radar_track_spread_along=2.0,
                                 radar_track_spread_across=1.5, radar_track_doppler_tol=3.0,
                                 radar_track_doppler_noise=0.3, radar_track_standing_s=0.0,
                                 radar_track_doppler_assoc=False))
    t = cfg.radar_tracking
    assert (t.enabled, t.body_along_m, t.body_across_m, t.doppler_tol) == (False, 2.0, 1.5, 3.0)
    assert (t.doppler_var, t.standing_s, t.doppler_assoc) == (pytest.approx(0.09), 0.0, False)
    d = P.pipeline_config(P.defaults()).radar_tracking
    assert ((d.doppler_var, d.standing_s, d.doppler_assoc)
            == (TrackerConfig().doppler_var, TrackerConfig().standing_s, TrackerConfig().doppler_assoc))
    assert P.pipeline_config(P.defaults()).radar_tracking.enabled
