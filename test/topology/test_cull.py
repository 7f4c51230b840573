"""The support-culled re-scoring of ``mcmc.run_chain`` (issue 18) against the kernel it
replaced (``test/reference/chain_before.py``): the same samples, columns, best state and
log posteriors bit for bit, on scenes of every input mode and on random states and
observations (hypothesis), from cold and hot chains (many accepted moves of every kind)."""

import numpy as np
from hypothesis import given, settings, strategies as st

from intersection_estimator.topology import TopologyConfig, TopologyEstimator
from intersection_estimator.topology.config import Tables
from intersection_estimator.topology.likelihood import full_loglik
from intersection_estimator.topology.mcmc import new_work, run_chain, state_log_prior
from intersection_estimator.topology.state import MAXA, pack_state
from reference.chain_before import run_chain as run_chain_before

from .scenes import easy_intersection, scene
from .strategies import random_obs, states

CFG = TopologyConfig()
TAB = Tables(CFG)


def _both(S, obs, n_steps, temp, seed, P=None):
    """Both kernels from state ``S`` on ``obs``: their outputs and mutated arrays."""
    P = TAB.P if P is None else P
    out = []
    for f in (run_chain, run_chain_before):
        C = np.zeros((MAXA, len(obs)))
        ll = float(full_loglik(S, P, *obs.kernel_args(), C))
        lp = float(state_log_prior(S, P, TAB.logPA, TAB.logPn, TAB.arm_const))
        Sc, best = S.copy(), S.copy()
        stats, work = np.zeros(16, np.int64), new_work()
        r = f(Sc, C, ll, lp, best, ll + lp, P, TAB.logPA, TAB.logPn, TAB.arm_const,
              TAB.logqn, TAB.cumqn, *obs.kernel_args(), n_steps, np.full(n_steps, temp), seed,
              stats, work, False)
        out.append((r, Sc, C, best, stats))
    return out


def _assert_same(a, b):
    (ra, Sa, Ca, Ba, sta), (rb, Sb, Cb, Bb, stb) = a, b
    assert [x.hex() for x in map(float, ra)] == [x.hex() for x in map(float, rb)]
    for x, y in ((Sa, Sb), (Ca, Cb), (Ba, Bb), (sta, stb)):
        assert np.array_equal(x, y)


def test_culled_chain_equals_the_unculled_one_on_scenes_of_every_mode():
    gt = easy_intersection(4, lanes=((1, 1), (2, 1), (1, 2), (1, 1)))
    for mode in ('raw', 'tracked', 'heading'):
        est = TopologyEstimator(CFG, seed=0)
        est.set_observations(scene(gt, mode, seed=3, clutter=30))
        S = pack_state(gt)
        S[0] += 1.0
        for temp in (0.05, 1.0, 30.0):        # cold: mostly rejected; hot: most accepted
            a, b = _both(S, est.observations, 1500, temp, seed=int(temp * 10) + 1)
            _assert_same(a, b)
            assert a[4][1::2].sum() > 0       # some moves accepted


@settings(max_examples=40, deadline=None)
@given(S=states(max_offset=3.0), n=st.integers(1, 200), seed=st.integers(0, 2 ** 31 - 2),
       temp=st.sampled_from([0.1, 3.0, 100.0]))
def test_culled_chain_equals_the_unculled_one_on_random_states(S, n, seed, temp):
    obs = random_obs(np.random.default_rng(seed), n, center=S[:2], spread=70.0)
    a, b = _both(S, obs, 300, temp, seed)
    _assert_same(a, b)
