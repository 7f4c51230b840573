"""Arms that bend (topology/bend.py, beyond the paper): the traffic's own heading profile
straightens a curved approach; straight arms and turns in the box are left alone."""

import math

import numpy as np

from intersection_estimator.observations import Detections
from intersection_estimator.topology.bend import straighten
from intersection_estimator.topology.config import TopologyConfig
from intersection_estimator.topology.preprocess import tracked_observations

R_IN, REACH, BIN = 12.0, 85.0, 5.0


def _bent_axis(bend_deg, start=30.0, end=60.0, step=0.1, length=90.0):
    """Axis along +x, straight to ``start``, then turning left evenly to ``bend_deg`` by
    ``end`` (a shape the module's profile does not assume: it only reads headings)."""
    tau = np.arange(0.0, length, step)
    turn = np.clip((tau - start) / (end - start), 0.0, 1.0)
    beta = np.where(tau < start, 0.0, turn * math.radians(bend_deg))
    ax = np.cumsum(np.r_[0.0, step * np.cos(beta[1:])])
    ay = np.cumsum(np.r_[0.0, step * np.sin(beta[1:])])
    return ax, ay, beta


def _leaving_tracks(bend_deg, lanes=(-1.75, -5.25), per_lane=3, every=10, **axis):
    """Vehicles leaving the center along the bent axis, on lanes at normal offsets."""
    ax, ay, beta = _bent_axis(bend_deg, **axis)
    xs, ys, hs, starts, ends, lat = [], [], [], [], [], []
    n = 0
    for d in lanes:
        for _ in range(per_lane):
            i = np.arange(0, len(ax), every)
            px = np.r_[-5.0, 0.0, ax[i] - d * np.sin(beta[i])]
            py = np.r_[d, d, ay[i] + d * np.cos(beta[i])]
            starts.append(n)
            n += len(px)
            ends.append(n)
            xs.append(px)
            ys.append(py)
            hs.append(np.r_[0.0, 0.0, beta[i]])
            lat.append(np.full(len(px), d))
    return (np.concatenate(xs), np.concatenate(ys), np.concatenate(hs), np.array(starts),
            np.array(ends), np.concatenate(lat))


ARMS = np.array([0.0, math.pi / 2, math.pi])


def test_bent_approach_is_straightened():
    """A 30 deg bend: every row beyond the box keeps its lane's lateral offset within
    0.5 m on the straight axis (before: up to 20 m) and its heading within 2 deg of it."""
    x, y, h, s, e, lat = _leaving_tracks(30.0)
    nx, ny, nh, bent = straighten(x, y, h, s, e, (0.0, 0.0), ARMS, R_IN, REACH, BIN, 8.0)
    assert bent == 1
    far = x > R_IN
    assert np.max(np.abs(y[far] - lat[far])) > 10.0
    assert np.max(np.abs(ny[far] - lat[far])) < 0.5
    assert np.max(np.abs(np.degrees(nh[far]))) < 2.0


def test_straight_or_gentle_arm_is_left_bit_identical():
    """No bend, or one below ``bend_min_deg``: the very input arrays come back."""
    for deg in (0.0, 5.0):
        x, y, h, s, e, _ = _leaving_tracks(deg)
        nx, ny, nh, bent = straighten(x, y, h, s, e, (0.0, 0.0), ARMS, R_IN, REACH, BIN, 8.0)
        assert bent == 0 and nx is x and ny is y and nh is h


def test_off_switch_and_no_arms_change_nothing():
    x, y, h, s, e, _ = _leaving_tracks(30.0)
    for angles, min_deg in ((ARMS, 0.0), (np.zeros(0), 8.0)):
        nx, _, _, bent = straighten(x, y, h, s, e, (0.0, 0.0), angles, R_IN, REACH, BIN, min_deg)
        assert bent == 0 and nx is x


def _turning_tracks(n_veh=4):
    """Vehicles that drive east at y = 15, turn left on a 10 m quarter circle just outside
    the box radius and leave north on the lane x = 1.75: a turn at the junction (9 deg/m),
    then a straight arm."""
    xs, ys, hs, starts, ends = [], [], [], [], []
    n = 0
    for k in range(n_veh):
        lane = 1.75 + 0.1 * k
        th = np.linspace(-math.pi / 2, 0.0, 16)
        cx, cy = lane - 10.0, 25.0
        east = np.arange(-40.0, cx, 1.0)
        north = np.arange(26.0, 80.0, 1.0)
        px = np.r_[east, cx + 10.0 * np.cos(th), np.full(len(north), lane)]
        py = np.r_[np.full(len(east), 15.0), cy + 10.0 * np.sin(th), north]
        ph = np.r_[np.zeros(len(east)), th + math.pi / 2, np.full(len(north), math.pi / 2)]
        starts.append(n)
        n += len(px)
        ends.append(n)
        xs.append(px)
        ys.append(py)
        hs.append(ph)
    x, y, h = map(np.concatenate, (xs, ys, hs))
    return x, y, h, np.array(starts), np.array(ends)


def test_turn_at_the_junction_is_not_a_bend(monkeypatch):
    """The turn is cut from the profile (``_turn_start``), so the straight arm it leaves on
    is not bent; without the cut and the smoothness check the same rows read as a bend
    (the test can fail)."""
    import intersection_estimator.topology.bend as bend
    x, y, h, s, e = _turning_tracks()
    nx, _, _, bent = straighten(x, y, h, s, e, (0.0, 0.0), ARMS, R_IN, REACH, BIN, 8.0)
    assert bent == 0 and nx is x
    monkeypatch.setattr(bend, '_MAX_RATE_DEG', 1e6)
    monkeypatch.setattr(bend, '_MAX_JUMP', 1e6)
    assert straighten(x, y, h, s, e, (0.0, 0.0), ARMS, R_IN, REACH, BIN, 8.0)[3] >= 1


def _dets(x, y, h, starts, ends, label=1):
    tid = np.zeros(len(x), np.int64)
    for i, (a, b) in enumerate(zip(starts, ends)):
        tid[a:b] = i
    t = np.concatenate([np.arange(b - a) * 0.1 for a, b in zip(starts, ends)])
    return Detections.make(np.column_stack([x, y]), t=t, heading=h, track_id=tid,
                           speed=np.full(len(x), 10.0), label=np.full(len(x), label))


def test_tracked_parts_of_a_bent_arm_line_up():
    """Through tracked_observations: with the arm known the leaving parts' mean points sit
    at their two lanes' offsets; straight rays from the center without the step see them
    metres off (a bend that starts at the box: no straight piece for the trim to keep)."""
    x, y, h, s, e, lat = _leaving_tracks(30.0, start=12.0, end=75.0)
    dets = _dets(x, y, h, s, e)
    on = TopologyConfig(bend_min_deg=8.0).preprocess_config()
    off = TopologyConfig(bend_min_deg=0.0).preprocess_config()
    lanes = np.array([-1.75, -5.25])

    def lateral_error(obs):
        # offsets from the line through the center in the parts' own mean direction (the
        # straightened arm points along the traffic next to the box)
        b = math.atan2(np.mean(obs.hy), np.mean(obs.hx))
        lat = -obs.x * math.sin(b) + obs.y * math.cos(b)
        return np.max(np.min(np.abs(lat[:, None] - lanes[None, :]), axis=1))

    o_on = tracked_observations(dets, (0.0, 0.0), on, ARMS)
    o_off = tracked_observations(dets, (0.0, 0.0), off, ARMS)
    assert len(o_on) == len(o_off) > 0
    assert lateral_error(o_on) < 0.5 < 2.0 < lateral_error(o_off)


def test_cyclist_parts_get_the_weak_sigma():
    """A track labelled bicycle (Autoware 6) gets ``sigma_track_weak``, a car
    ``sigma_track``."""
    x, y, h, s, e, _ = _leaving_tracks(0.0, lanes=(-1.75,), per_lane=1)
    cfg = TopologyConfig(sigma_track=0.8, sigma_track_weak=2.5).preprocess_config()
    car = tracked_observations(_dets(x, y, h, s, e, label=1), (0.0, 0.0), cfg)
    bike = tracked_observations(_dets(x, y, h, s, e, label=6), (0.0, 0.0), cfg)
    assert len(car) == len(bike) > 0
    assert np.all(car.sigma == 0.8) and np.all(bike.sigma == 2.5)


def test_weak_sigma_follows_its_track_when_another_track_is_out_of_range():
    """A moving car seen only beyond ``track_radius`` leaves no part; the cyclist after it
    (higher track id) must still get ``sigma_track_weak``, the car after that ``sigma_track``
    (labels stay with their tracks when the radius drops a whole track)."""
    x, y, h, s, e, _ = _leaving_tracks(0.0, lanes=(-1.75,), per_lane=1)
    n = len(x)
    far = np.column_stack([np.arange(200.0, 200.0 + n), np.full(n, 40.0)])   # > 75 m out
    xy = np.concatenate([far, np.column_stack([x, y]), np.column_stack([x, y - 3.5])])
    tid = np.repeat([0, 1, 2], n)
    label = np.repeat([1, 6, 1], n)
    t = np.tile(np.arange(n) * 0.1, 3)
    dets = Detections.make(xy, t=t, heading=np.tile(h, 3), track_id=tid,
                           speed=np.full(3 * n, 10.0), label=label)
    cfg = TopologyConfig(sigma_track=0.8, sigma_track_weak=2.5).preprocess_config()
    obs = tracked_observations(dets, (0.0, 0.0), cfg)
    assert len(obs) == 2                                   # one leaving part per near track
    bike = np.argmax(obs.y)                                # the cyclist's lane is y = -1.75
    assert obs.sigma[bike] == 2.5 and obs.sigma[1 - bike] == 0.8
