"""The one Bezier-handle formula of the lane course (lanes/init.py arc_handle)."""

import math

import numpy as np
import pytest

from intersection_estimator.lanes.init import arc_bezier, arc_handle


def test_quarter_circle_handle_is_the_classic_constant():
    """A 90 deg arc of radius r: handle r * 4/3 tan(pi/8) = 0.5523 r (chord r sqrt 2)."""
    r = 7.0
    assert arc_handle(r * math.sqrt(2.0), 0.0) == pytest.approx(r * 4 / 3 * math.tan(math.pi / 8))


def test_straight_and_hairpin_limits():
    assert arc_handle(9.0, 1.0) == pytest.approx(3.0)          # straight: chord / 3
    assert arc_handle(9.0, -1.0) == pytest.approx(4.5)         # U-turn: capped at chord / 2
    assert arc_handle(9.0, 1.5) == pytest.approx(3.0)          # rounding beyond 1 clamped


def test_arc_bezier_midpoint_lies_near_the_circle():
    r = 10.0
    p0, t0 = np.array([r, 0.0]), np.array([0.0, 1.0])
    p1, t1 = np.array([0.0, r]), np.array([-1.0, 0.0])
    mid = arc_bezier(p0, t0, p1, t1, np.array([0.5]))[0]
    assert np.hypot(*mid) == pytest.approx(r, rel=1e-3)
