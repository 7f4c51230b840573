"""The constant-velocity model and its smoother (tracking/kalman.py)."""

from __future__ import annotations

from hypothesis import given, settings, strategies as st
import numpy as np

from intersection_estimator.tracking.kalman import predict, rts, transition, update, update_radial


def test_transitions_compose():
    Fa, _ = transition(0.3, 2.0)
    Fb, _ = transition(0.5, 2.0)
    Fab, _ = transition(0.8, 2.0)
    assert np.allclose(Fa @ Fb, Fab)


def test_process_noise_grows_with_time_and_is_symmetric_positive():
    _, q1 = transition(0.1, 2.0)
    _, q2 = transition(0.2, 2.0)
    assert np.allclose(q1, q1.T) and np.all(np.linalg.eigvalsh(q1) > 0)
    assert np.trace(q2) > np.trace(q1)


def _filtered(rng, n=80, dt=0.1, v=(8.0, 2.0), sigma=1.0):
    truth = np.array(v) * dt * np.arange(n)[:, None]
    z = truth + rng.normal(0, sigma, (n, 2))
    x, P = np.array([z[0, 0], z[0, 1], 0.0, 0.0]), np.diag([1.0, 1.0, 100.0, 100.0])
    F, Q = transition(dt, 2.0)
    xp, Pp, xf, Pf = [x], [P], [x], [P]
    for k in range(1, n):
        a, A = predict(x, P, F, Q)
        x, P = update(a, A, z[k], sigma**2)
        xp.append(a), Pp.append(A), xf.append(x), Pf.append(P)
    return truth, dt * np.arange(n), *map(np.array, (xp, Pp, xf, Pf))


def test_filter_learns_the_velocity():
    v = [_filtered(np.random.default_rng(s), n=150, sigma=0.5)[-2][-1, 2:] for s in range(5)]
    assert np.allclose(np.mean(v, axis=0), [8.0, 2.0], atol=0.5)
    assert np.allclose(v, [8.0, 2.0], atol=1.5)


def test_smoother_beats_the_filter_on_a_straight_track():
    rng = np.random.default_rng(1)
    errs = []
    for _ in range(5):
        truth, t, xp, Pp, xf, Pf = _filtered(rng)
        xs = rts(t, xp, Pp, xf, Pf, 2.0)
        errs.append((np.linalg.norm(xf[:, :2] - truth, axis=1).mean(),
                     np.linalg.norm(xs[:, :2] - truth, axis=1).mean()))
    filt, smooth = np.mean(errs, axis=0)
    assert smooth < 0.8 * filt


@settings(max_examples=50, deadline=None)
@given(st.integers(0, 2**32 - 1), st.floats(0.01, 10.0))
def test_the_compiled_update_is_the_kalman_update(seed, r):
    """Closed-form 2 x 2 inverse against K = P H' (H P H' + R)^-1 on random covariances."""
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(4, 4))
    P = A @ A.T + 0.1 * np.eye(4)
    x, z = rng.normal(size=4), rng.normal(size=2)
    H = np.eye(2, 4)
    K = P @ H.T @ np.linalg.inv(H @ P @ H.T + r * np.eye(2))
    x2, P2 = update(x, P, z, r)
    assert np.allclose(x2, x + K @ (z - H @ x), rtol=1e-9, atol=1e-9)
    assert np.allclose(P2, (np.eye(4) - K @ H) @ P, rtol=1e-9, atol=1e-9)


@settings(max_examples=50, deadline=None)
@given(st.integers(0, 2**32 - 1), st.floats(0.001, 10.0), st.floats(-3.14, 3.14))
def test_the_doppler_update_is_the_kalman_update_of_the_radial_speed(seed, r, a):
    """h = (0, 0, cos a, sin a): K = P h' / (h P h' + r) against the compiled update."""
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(4, 4))
    P = A @ A.T + 0.1 * np.eye(4)
    x, dop = rng.normal(size=4), float(rng.normal())
    h = np.array([0.0, 0.0, np.cos(a), np.sin(a)])
    K = P @ h / (h @ P @ h + r)
    x2, P2 = update_radial(x, P, h[2:].copy(), dop, r)
    assert np.allclose(x2, x + K * (dop - h @ x), rtol=1e-9, atol=1e-9)
    assert np.allclose(P2, P - np.outer(K, h @ P), rtol=1e-9, atol=1e-9)


def test_zero_doppler_pins_the_radial_speed_and_leaves_the_cross_speed():
    """A track drifting at 2 m/s along x, measured standing along x: its x speed goes to
    ~0, its uncertain y speed stays where it was (no correlation to move it)."""
    x = np.array([0.0, 0.0, 2.0, 1.0])
    P = np.diag([0.5, 0.5, 4.0, 4.0])
    for _ in range(20):
        x, P = update_radial(x, P, np.array([1.0, 0.0]), 0.0, 0.01)
    assert abs(x[2]) < 0.05 and x[3] == 1.0 and P[2, 2] < 0.01 and P[3, 3] == 4.0
