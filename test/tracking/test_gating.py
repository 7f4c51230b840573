"""Which rows a track takes, and duplicate tracks (tracking/gating.py)."""

from __future__ import annotations

import dataclasses
import math

from hypothesis import given, settings, strategies as st
import numpy as np
import pytest

from intersection_estimator.tracking import TrackerConfig
from intersection_estimator.tracking.gating import body_cov, duplicates, gate_distance

CFG = TrackerConfig()


def _track(x, y, vx, vy, pos_var=0.1):
    return np.array([[x, y, vx, vy]]), np.diag([pos_var, pos_var, 1.0, 1.0])[None]


def test_body_spread_lies_along_the_heading_and_is_round_when_standing():
    c = body_cov(np.array([[0.0, 1.0], [0.0, 0.0]]), CFG)
    assert math.isclose(c[0, 1, 1], CFG.body_along_m**2) and math.isclose(c[0, 0, 0], CFG.body_across_m**2)
    assert math.isclose(c[1, 0, 0], c[1, 1, 1]) and c[1, 0, 1] == 0


def test_a_row_ahead_joins_where_a_row_beside_does_not():
    X, P = _track(0, 0, 10, 0)
    d = gate_distance(X, P, np.array([[4.0, 0.0], [0.0, 4.0]]), CFG)[0]
    assert d[0] <= 1.0 < d[1]


@pytest.mark.parametrize('assoc', [False, True])
def test_a_row_whose_doppler_disagrees_is_not_the_tracks(assoc):
    X, P = _track(0, 0, 10, 0)
    los = np.array([[1.0, 0.0], [1.0, 0.0]])
    cfg = dataclasses.replace(CFG, doppler_assoc=assoc)
    d = gate_distance(X, P, np.zeros((2, 2)), cfg, np.array([9.8, -9.8]), los)[0]
    assert d[0] == pytest.approx(0.2 * 3 / (cfg.doppler_tol * cfg.gate_sigma) if assoc else 0.0)
    assert math.isinf(d[1])


def test_with_doppler_association_a_row_goes_to_the_track_whose_radial_speed_it_shows():
    """Two vehicles cross at 10 m/s, one east, one north; a row of the northbound one,
    seen along the line of sight (0.6, 0.8), lies a little nearer the eastbound track's
    predicted position. Both radial speeds (6 and 8 m/s) pass the Doppler gate; its
    Doppler, 8 m/s, is the northbound one's."""
    X = np.array([[0.0, 0.0, 10.0, 0.0], [0.8, 0.0, 0.0, 10.0]])
    P = np.repeat(np.diag([0.1, 0.1, 1.0, 1.0])[None], 2, axis=0)
    row, los, dop = np.array([[0.35, 0.0]]), np.array([[0.6, 0.8]]), np.array([8.0])
    plain = gate_distance(X, P, row, dataclasses.replace(CFG, doppler_assoc=False), dop, los)[:, 0]
    joint = gate_distance(X, P, row, dataclasses.replace(CFG, doppler_assoc=True), dop, los)[:, 0]
    assert np.isfinite(plain).all() and plain.argmin() == 0      # position alone: the wrong track
    assert joint.argmin() == 1 and joint[1] <= 1.0


@settings(max_examples=60, deadline=None)
@given(st.floats(-math.pi, math.pi), st.floats(-30, 30), st.floats(-30, 30),
       st.floats(-5, 5), st.floats(-5, 5))
def test_gate_distance_does_not_depend_on_the_frame(phi, ox, oy, rx, ry):
    """Rotating and shifting scene and track together changes no distance."""
    X, P = _track(1.0, 2.0, 7.0, -3.0)
    row = np.array([[1.0 + rx, 2.0 + ry]])
    c, s = math.cos(phi), math.sin(phi)
    R = np.array([[c, -s], [s, c]])
    X2 = np.concatenate([R @ X[0, :2] + [ox, oy], R @ X[0, 2:]])[None]
    P2 = np.zeros_like(P)
    P2[0, :2, :2] = R @ P[0, :2, :2] @ R.T
    P2[0, 2:, 2:] = R @ P[0, 2:, 2:] @ R.T
    d1 = gate_distance(X, P, row, CFG)[0, 0]
    d2 = gate_distance(X2, P2, row @ R.T + [ox, oy], CFG)[0, 0]
    assert math.isclose(d1, d2, rel_tol=1e-9, abs_tol=1e-9)


def test_the_younger_of_two_tracks_on_one_vehicle_ends():
    X = np.array([[0.0, 0.0, 10.0, 0.0], [0.3, 0.1, 10.5, 0.0], [0.0, 3.5, 10.0, 0.0]])
    P = np.repeat(np.diag([0.1, 0.1, 1.0, 1.0])[None], 3, axis=0)
    assert duplicates(X, P, np.array([30, 4, 30]), CFG).tolist() == [1]
    X[1, 2] = -10.0            # same place, opposite direction: two vehicles passing
    assert duplicates(X, P, np.array([30, 4, 30]), CFG).tolist() == []
