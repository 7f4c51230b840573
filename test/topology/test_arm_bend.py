"""Arms that bend (beyond the paper, topology/arm_bend.py): the kink's geometry, off = the
straight model, the prior and the add-arm draw, and a curved approach recovered from its
traffic."""

from dataclasses import replace
import math

import numpy as np
import pytest
from numba import njit
from scipy import integrate

from intersection_estimator.model import Arm, Intersection
from intersection_estimator.observations import Detections
from intersection_estimator.topology import TopologyConfig, TopologyEstimator
from intersection_estimator.topology.arm_bend import (bend_log_prior, bend_logq, draw_bend,
                                                      unbend)
from intersection_estimator.topology.state import P_BEND_MAX, P_C_OFFSET, pack_state

from .scenes import easy_intersection, same_topology, scene

ON = TopologyConfig(arm_bend_max_deg=45.0)


def test_unbend_measures_beyond_the_kink_along_the_outer_piece():
    """Axis along +x, 30 deg left at 20 m: a point 10 m along the outer piece and 3 m to
    its left reads s = 30, t = 3; a heading along that piece reads cos 1; before the
    kink's bisector nothing changes."""
    b = math.radians(30.0)
    cb, sb = math.cos(b), math.sin(b)
    u2, n2 = np.array([cb, sb]), np.array([-sb, cb])
    p = np.array([20.0, 0.0]) + 10.0 * u2 + 3.0 * n2
    s, t, c = unbend(p[0], p[1], cb, sb, 20.0, cb, sb)     # heading u2: cos, sin vs the x axis
    assert (s, t, c) == pytest.approx((30.0, 3.0, 1.0))
    assert unbend(15.0, 2.0, 1.0, 0.0, 20.0, cb, sb) == (15.0, 2.0, 1.0)
    # inside the bend (left) the bisector leans back: 8 m to the left it crosses s = 17.86
    assert unbend(17.5, 8.0, 1.0, 0.0, 20.0, cb, sb) == (17.5, 8.0, 1.0)
    assert unbend(18.2, 8.0, 1.0, 0.0, 20.0, cb, sb)[0] != 18.2


def _one_arm_state(beta):
    return pack_state(Intersection(center=np.zeros(2), arms=[Arm(angle=0.3, bend=beta,
                                                                 bend_at=30.0)]))


def test_off_draws_nothing_and_never_picks_the_move():
    """Off (arm_bend_max_deg 0; on by default): no random number is consumed, the move's cumulative
    probability ends before it, the prior adds nothing; on, a straight arm adds nothing
    either (the prior is the unnormalised exp(-|beta| / b), module doc)."""
    P = TopologyConfig(arm_bend_max_deg=0.0).kernel_params()
    assert P[P_BEND_MAX] == 0.0 and P[P_C_OFFSET] == 1.0

    @njit
    def after_draw(P, seed):
        np.random.seed(seed)
        b = draw_bend(P)
        return b[0], b[1], np.random.random()

    @njit
    def plain(seed):
        np.random.seed(seed)
        return np.random.random()

    b, at, r = after_draw(P, 9)
    assert (b, at) == (0.0, 0.0) and r == plain(9)
    assert bend_log_prior(_one_arm_state(0.0), ON.kernel_params()) == 0.0
    assert bend_log_prior(_one_arm_state(0.2), ON.kernel_params()) == pytest.approx(
        -0.2 / math.radians(ON.arm_bend_scale_deg))


def test_new_arm_draw_follows_its_density():
    """draw_bend samples Laplace(0, b) x U[at_min, at_max], whose log bend_logq gives."""
    P = ON.kernel_params()

    @njit
    def draws(P, n, seed):
        np.random.seed(seed)
        out = np.empty((n, 2))
        for i in range(n):
            out[i] = draw_bend(P)
        return out

    x = draws(P, 40000, 3)
    b = math.radians(ON.arm_bend_scale_deg)
    assert np.std(x[:, 0]) == pytest.approx(math.sqrt(2.0) * b, rel=0.02)
    assert x[:, 1].min() >= ON.arm_bend_at_min and x[:, 1].max() <= ON.arm_bend_at_max
    dens, _ = integrate.quad(lambda v: math.exp(bend_logq(v, P)), -20, 20, points=[0.0])
    assert dens * (ON.arm_bend_at_max - ON.arm_bend_at_min) == pytest.approx(1.0, abs=1e-9)


def _curved(dets: Detections, inter: Intersection, k: int, start: float, turn: float,
            length: float) -> Detections:
    """The tracked rows of arm ``k`` bent onto a road that turns by ``turn`` (rad, left +)
    gradually between ``start`` and ``start + length`` metres out (a circular arc, then
    straight again) -- a curve, not the estimator's kink."""
    arm = inter.arms[k]
    rel = dets.xy - inter.center
    s, t = rel @ arm.direction, rel @ arm.normal
    mine = (s > start) & (np.abs(t) < 12.0)
    grid = np.arange(0.0, 200.0, 0.1)
    head = turn * np.clip((grid - start) / length, 0.0, 1.0)
    axis = np.cumsum(0.1 * np.stack([np.cos(head), np.sin(head)], axis=1), axis=0)
    h = np.interp(s[mine], grid, head)
    ax = np.stack([np.interp(s[mine], grid, axis[:, 0]), np.interp(s[mine], grid, axis[:, 1])], 1)
    local = ax + t[mine, None] * np.stack([-np.sin(h), np.cos(h)], axis=1)
    rot = np.array([[arm.direction[0], arm.normal[0]], [arm.direction[1], arm.normal[1]]])
    xy = dets.xy.copy()
    xy[mine] = inter.center + local @ rot.T
    heading = dets.heading.copy()
    heading[mine] += h
    return replace(dets, xy=xy, heading=heading)


def _estimate(cfg, dets, seed=3):
    est = TopologyEstimator(cfg, seed=seed)
    est.set_observations(dets)
    est.run(n_samples=6000)
    return est.best


#: the bend with the parts kept whole along the curve: one mean per 10 m, no straight-run
#: trim; the axis offset off, as an offset and a turned angle place a bent arm's lanes next
#: to the box nearly alike (docs/real_junctions.md) and this is the bend's own test
CURVES = replace(ON, part_piece_m=10.0, trim_turn_deg=0.0, arm_offset_max=0.0)


@pytest.mark.parametrize('seed', [1, 2, 3])
def test_a_curved_approach_is_followed_when_on(seed):
    """A crossing whose north arm turns 35 deg left between 20 and 50 m out: with the
    bend on (and the parts in 10 m pieces) the topology is right, the north arm carries a
    bend of the right sign and size and the straight arms stay (nearly) straight; the
    straight model gets none of the three right (a center metres off, or four lanes out
    of the curved arm)."""
    gt = easy_intersection(4, lanes=((1, 1), (1, 1), (2, 1), (1, 1)), angles_deg=[-90, 180, 0, 90],
                           center=(0.0, 0.0))
    north = 2                                        # arms are sorted by angle
    dets = _curved(scene(gt, 'tracked', seed=seed, per_lane=3), gt, north, 20.0,
                   math.radians(35.0), 30.0)
    best = _estimate(CURVES, dets)
    assert same_topology(gt, best, tol_deg=8.0), best
    bent = min(best.arms, key=lambda a: abs(math.remainder(a.angle - math.pi / 2, 2 * math.pi)))
    assert 15.0 < math.degrees(bent.bend) < 45.0 and 15.0 < bent.bend_at < 50.0
    assert all(abs(math.degrees(a.bend)) < 8.0 for a in best.arms if a is not bent)
    assert not same_topology(gt, _estimate(TopologyConfig(arm_bend_max_deg=0.0), dets), tol_deg=8.0)
