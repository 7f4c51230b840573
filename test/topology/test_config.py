"""TopologyConfig: defaults, one table of ranges and meanings, the derived PreprocessConfig."""

from dataclasses import fields
import math

import numpy as np
import pytest

from intersection_estimator.topology import PreprocessConfig, TopologyConfig, TopologyEstimator
from intersection_estimator.topology.config import PREPROCESS_FIELDS, RANGES, Tables
from intersection_estimator.topology.state import (NPARAM, P_C_LANE, P_FOCUS_P, P_LANE_SUM,
                                                   P_MIN_SEP, P_SAMPLE_W)


def test_config_defaults_follow_the_paper_and_validate():
    cfg = TopologyConfig().validate()
    assert (cfg.p_rotate, cfg.p_shift, cfg.p_gap, cfg.p_arm, cfg.p_lane) == (0.4, 0.2, 0.1, 0.15, 0.15)
    assert (cfg.rotate_max_deg, cfg.shift_max, cfg.gap_step) == (6.0, 6.0, 1.8)


@pytest.mark.parametrize('field,value', [('p_rotate', -0.1), ('min_sep_deg', 0.0),
                                         ('max_arms', 99), ('sigma_track', 0.0),
                                         ('lane_width', 9.0), ('t_end', 100.0),
                                         ('traffic_side', 0), ('voxel_size', 0.0),
                                         ('chains', 0), ('chains_tracked', 17)])
def test_config_validate_names_the_parameter(field, value):
    with pytest.raises(ValueError, match=field):
        TopologyConfig(**{field: value}).validate()
    with pytest.raises(ValueError, match=field):
        TopologyEstimator(TopologyConfig(**{field: value}))


@pytest.mark.parametrize('field,value', [('rotate_max_deg', 0.0), ('clutter_floor', 1.0),
                                         ('lane_width_min', 4.0), ('min_radial_cos', 1.0),
                                         ('recenter_threshold', 0.0), ('refit_every', -1),
                                         ('lane_sum', 1), ('straight_run', 0.0),
                                         ('keep_unknown_direction', 'yes'), ('min_rcs', math.nan)])
def test_open_bounds_and_flags_are_refused(field, value):
    """Open interval ends exclude the bound; flags must be booleans, not 0/1."""
    with pytest.raises(ValueError, match=field):
        TopologyConfig(**{field: value}).validate()


def test_every_parameter_has_a_range_and_a_meaning():
    names = [f.name for f in fields(TopologyConfig)]
    assert sorted(RANGES) == sorted(names)
    for name, (interval, what) in RANGES.items():
        assert len(what) > 10, name
    # units are stated where a parameter has one
    for name in ('shift_max', 'gap_max', 'voxel_size', 'min_center_dist', 'passage_gap',
                 'min_doppler', 'rotate_max_deg'):
        assert '[' in RANGES[name][1], name


def test_preprocess_config_is_derived_not_copied():
    """Same names, defaults and ranges as TopologyConfig's preprocessing fields."""
    top = {f.name: f.default for f in fields(TopologyConfig)}
    pre = {f.name: f.default for f in fields(PreprocessConfig)}
    assert sorted(pre) == sorted(PREPROCESS_FIELDS)
    assert all(pre[n] == top[n] for n in pre)
    cfg = TopologyConfig(voxel_size=1.5, min_center_dist=7.0)
    assert cfg.preprocess_config() == PreprocessConfig(voxel_size=1.5, min_center_dist=7.0)
    with pytest.raises(ValueError, match='PreprocessConfig.voxel_size'):
        PreprocessConfig(voxel_size=0.0).validate()


def test_kernel_parameters_and_tables():
    cfg = TopologyConfig()
    P = cfg.kernel_params()
    assert P.shape == (NPARAM,) and math.isclose(P[P_MIN_SEP], math.radians(cfg.min_sep_deg))
    assert P[P_SAMPLE_W] == 1.0 and P[P_LANE_SUM] == 0.0 and P[P_FOCUS_P] == 0.0
    assert TopologyConfig(p_width=0.0, lane_sum=True).kernel_params()[[P_SAMPLE_W, P_LANE_SUM]].tolist() == [0.0, 1.0]
    tab = Tables(cfg)
    assert tab.P_polish[P_C_LANE] == pytest.approx(tab.P_polish[P_C_LANE - 2])   # no arm/lane moves
    Pf = tab.focused(2, 0.8)
    assert Pf[P_FOCUS_P] == 0.8 and tab.P_polish[P_FOCUS_P] == 0.0
    assert np.isclose(np.exp(tab.logPn[cfg.min_lanes:]).sum(), 1.0)
