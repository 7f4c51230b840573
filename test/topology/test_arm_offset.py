"""Arm-axis offset (beyond the paper, topology/arm_offset.py): prior, proposal, off = the
straight-ray model, and an offset arm recovered from its traffic."""

from dataclasses import replace
import math

import numpy as np
import pytest
from numba import njit
from scipy import integrate

from intersection_estimator.model import Arm, Intersection
from intersection_estimator.topology import TopologyConfig, TopologyEstimator
from intersection_estimator.topology.arm_offset import (draw_offset, offset_log_const,
                                                        offset_log_prior, offset_logq)
from intersection_estimator.topology.state import HDR, OFF, P_C_WIDTH, P_OFF_MAX, STRIDE, pack_state

from .scenes import easy_intersection, same_topology, scene

ON = TopologyConfig(arm_offset_max=6.0, arm_offset_sigma=4.0, arm_bend_max_deg=0.0)   # the offset alone


def _one_arm_state(o):
    return pack_state(Intersection(center=np.zeros(2), arms=[Arm(angle=0.3, offset=o)]))


@pytest.mark.parametrize('kind', ['normal', 'laplace'])
@pytest.mark.parametrize('sigma,bound', [(2.0, 6.0), (1.0, 1.5), (4.0, 30.0)])
def test_prior_is_a_normalised_truncated_density(sigma, bound, kind):
    P = TopologyConfig(arm_offset_max=bound, arm_offset_sigma=sigma,
                       arm_offset_prior=kind).kernel_params()
    c = offset_log_const(sigma, bound, kind == 'laplace')
    mass, _ = integrate.quad(lambda o: math.exp(c + offset_log_prior(_one_arm_state(o), P)),
                             -bound, bound)
    assert mass == pytest.approx(1.0, abs=1e-9)


@pytest.mark.parametrize('kind', ['normal', 'laplace'])
def test_new_arm_draw_follows_its_density(kind):
    """draw_offset samples the density (normal or Laplace, both with standard deviation
    sigma * (1 or sqrt 2)) whose log offset_logq returns."""
    cfg = TopologyConfig(arm_offset_max=6.0, arm_offset_sigma=4.0, arm_offset_prior=kind)
    P = cfg.kernel_params()

    @njit
    def draws(P, n, seed):
        np.random.seed(seed)
        out = np.empty(n)
        for i in range(n):
            out[i] = draw_offset(P)
        return out

    x = draws(P, 40000, 5)
    sd = cfg.arm_offset_sigma * (math.sqrt(2.0) if kind == 'laplace' else 1.0)
    assert np.std(x) == pytest.approx(sd, rel=0.02)
    assert abs(np.mean(x)) < 4.0 * sd / math.sqrt(len(x))      # 4 standard errors
    dens, _ = integrate.quad(lambda o: math.exp(offset_logq(o, P)), -400, 400, points=[0.0], limit=200)
    assert dens == pytest.approx(1.0, abs=1e-9)


def test_off_draws_nothing_and_never_picks_the_move():
    """Off (arm_offset_max 0): no random number is consumed, offsets stay 0, the move's
    cumulative probability ends at the width move, the prior adds nothing."""
    P = TopologyConfig(arm_offset_max=0.0, arm_bend_max_deg=0.0).kernel_params()
    assert P[P_C_WIDTH] == 1.0

    @njit
    def after_draw(P, seed):
        np.random.seed(seed)
        o = draw_offset(P)
        return o, np.random.random()

    @njit
    def plain(seed):
        np.random.seed(seed)
        return np.random.random()

    o, r = after_draw(P, 9)
    assert o == 0.0 and r == plain(9)
    assert offset_log_prior(_one_arm_state(0.0), P) == 0.0
    assert offset_log_const(2.0, 0.0) == 0.0


def _staggered(offset):
    """A crossing whose south arm meets the box ``offset`` metres beside the north arm's
    line (a staggered junction). Offsets are only identifiable against the center where
    an arm has a counterpart: a T's stem could equally move the center along the road."""
    lanes = ((1, 1), (1, 2), (1, 1), (2, 1))
    angles = (0.0, math.pi / 2, math.pi - 0.02, -math.pi / 2)
    arms = [Arm(angle=a, lanes_in=li, lanes_out=lo, offset=offset if k == 3 else 0.0)
            for k, (a, (li, lo)) in enumerate(zip(angles, lanes))]
    return Intersection(center=np.array([4.0, -2.0]), arms=arms)


def _estimate(cfg, dets, seed=3):
    est = TopologyEstimator(cfg, seed=seed)
    est.set_observations(dets)
    est.run(n_samples=6000)
    return est.best


def _axis_errors(gt, est, dist=30.0):
    """Lateral distance [m] of each true arm's axis from its estimate's, ``dist`` out."""
    out = []
    for a in gt.arms:
        b = min(est.arms, key=lambda b: abs(math.remainder(a.angle - b.angle, 2 * math.pi)))
        pa = gt.center + dist * a.direction + a.offset * a.normal
        pb = est.center + dist * b.direction + b.offset * b.normal
        out.append(abs(float((pb - pa) @ a.normal)))
    return np.array(out)


@pytest.mark.parametrize('seed', [2, 5])
def test_staggered_arms_are_followed_when_on(seed):
    """A 5 m stagger: with the offset on every arm's axis lies within 0.5 m of its traffic,
    the stagger carried by the offsets of the two staggered arms (north and south; the
    likelihood is tempered, so part of it is still taken by rotating them)."""
    gt = _staggered(5.0)
    best = _estimate(ON, scene(gt, 'tracked', seed=seed, clutter=10))
    assert same_topology(gt, best), best
    assert _axis_errors(gt, best).max() < 0.5
    north, south = (min(best.arms, key=lambda a: abs(math.remainder(a.angle - t, 2 * math.pi)))
                    for t in (math.pi / 2, -math.pi / 2))
    assert north.offset + south.offset > 1.0     # both move their lines towards +x


def test_arms_through_the_center_stay_on_their_traffic():
    """No stagger: the axes stay on the traffic and no offset grows beyond what the
    tempered likelihood cannot tell from a center shift (well below a lane width)."""
    gt = _staggered(0.0)
    best = _estimate(ON, scene(gt, 'tracked', seed=4, clutter=10))
    assert same_topology(gt, best), best
    assert _axis_errors(gt, best).max() < 0.5
    assert max(abs(a.offset) for a in best.arms) < 2.5


def test_estimates_off_have_zero_offsets():
    best = _estimate(TopologyConfig(arm_offset_max=0.0), scene(_staggered(3.5), 'tracked', seed=2))
    assert all(a.offset == 0.0 for a in best.arms)
    S = pack_state(best)
    assert np.all(S[HDR + OFF::STRIDE][:len(best.arms)] == 0.0)


def test_offset_is_for_tracked_windows_only_by_default():
    """``arm_offset_tracks_only``: a radar window gets the straight-ray tables (no offset
    move, no prior term); a tracked window the offset; a window that loses its tracks
    drops the chains' offsets."""
    cfg = TopologyConfig(arm_offset_max=6.0, arm_offset_prior='laplace', arm_offset_sigma=1.0)
    inter = easy_intersection()
    tracked, raw = scene(inter, 'tracked', seed=3), scene(inter, 'raw', seed=3)
    est = TopologyEstimator(cfg, seed=1)
    est.set_observations(tracked)
    assert est._tables.P[P_OFF_MAX] == 6.0
    est.run(n_samples=1500)
    for c in est._chains:                  # an offset arm, whatever the chain found
        c.S[HDR + OFF] = c.best_S[HDR + OFF] = 1.5
    assert est.best.arms[0].offset != 0.0 or any(a.offset == 1.5 for a in est.best.arms)
    est.set_observations(raw)
    assert est._tables.P[P_OFF_MAX] == 0.0
    assert all(a.offset == 0.0 for a in est.best.arms)
    est.run(n_samples=500)
    assert all(a.offset == 0.0 for a in est.best.arms)
    both = TopologyEstimator(replace(cfg, arm_offset_tracks_only=False), seed=1)
    both.set_observations(raw)
    assert both._tables.P[P_OFF_MAX] == 6.0
