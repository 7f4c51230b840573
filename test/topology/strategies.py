"""Hypothesis strategies shared by the topology tests."""

import math

import numpy as np
from hypothesis import strategies as st

from intersection_estimator.model import Arm, Intersection
from intersection_estimator.topology import TopologyConfig
from intersection_estimator.topology.likelihood import ObservationSet
from intersection_estimator.topology.state import arm_rows, pack_state

CFG = TopologyConfig()


@st.composite
def states(draw, max_offset=0.0, max_bend_deg=0.0):
    """Valid packed states: arm angles at least min_sep apart, bounds respected; arm-axis
    offsets in ``[-max_offset, max_offset]`` and bends in ``[-max_bend_deg, max_bend_deg]``
    at ``[arm_bend_at_min, arm_bend_at_max]`` (0 unless given)."""
    mb = math.radians(max_bend_deg)
    ms = math.radians(CFG.min_sep_deg)
    n = draw(st.integers(CFG.min_arms, CFG.max_arms))
    slack = 2 * math.pi - n * ms
    raw = draw(st.lists(st.floats(0.01, 1.0), min_size=n, max_size=n))
    gaps = ms + slack * np.asarray(raw) / sum(raw) * 0.999
    a0 = draw(st.floats(-math.pi, math.pi))
    angles = (a0 + np.cumsum(gaps) + math.pi) % (2 * math.pi) - math.pi
    arms = [Arm(angle=float(a),
                gap=draw(st.floats(0.0, CFG.gap_max)),
                lanes_in=draw(st.integers(CFG.min_lanes, CFG.max_lanes)),
                lanes_out=draw(st.integers(CFG.min_lanes, CFG.max_lanes)),
                lane_width=draw(st.floats(CFG.lane_width_min, CFG.lane_width_max)),
                offset=draw(st.floats(-max_offset, max_offset)) if max_offset > 0 else 0.0,
                bend=draw(st.floats(-mb, mb)) if mb > 0 else 0.0,
                bend_at=(draw(st.floats(CFG.arm_bend_at_min, CFG.arm_bend_at_max)) if mb > 0
                         else 0.0))
            for a in angles]
    c = draw(st.tuples(st.floats(-100, 100), st.floats(-100, 100)))
    S = pack_state(Intersection(center=np.asarray(c), arms=arms))
    rows = arm_rows(S)   # keep slot order random, like a chain after removals
    perm = np.asarray(draw(st.permutations(list(range(n)))))
    rows[:] = rows[perm]
    return S


def random_obs(rng, n, center=(0.0, 0.0), spread=60.0, known_direction=False):
    """``n`` observations of random place, orientation (half of them) and Doppler class (with
    ``known_direction`` never 0, the unknown class)."""
    xy = np.asarray(center) + rng.uniform(-spread, spread, (n, 2))
    h = rng.uniform(-math.pi, math.pi, n)
    has_o = rng.uniform(size=n) < 0.5
    return ObservationSet(xy[:, 0].copy(), xy[:, 1].copy(), np.where(has_o, np.cos(h), 0.0),
                          np.where(has_o, np.sin(h), 0.0), has_o,
                          rng.choice([1.0, -1.0] if known_direction else [1.0, -1.0, 0.0], n),
                          rng.uniform(0.5, 5.0, n), rng.uniform(0.3, 2.0, n),
                          rng.uniform(0.05, 0.5, n))
