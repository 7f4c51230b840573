"""The paper's moves on the lanelet graph (paper §III-B), compiled with numba.

Each move changes the state in place and records what it changed in an undo log
(``up_p``/``up_xy`` for point positions, ``rc_slot``/``rc_old`` for slot references)
so that the sampler can revert a rejected proposal. All moves are lateral (along the
station normal / point axis), see ``lanes/model.py``:

* ``move_center``: translate the cross section of one station (both its border
  points) by ``N(0, step_center)`` -- "modify a point m_l of the center line";
* ``move_border``: shift one border point by ``N(0, step_border)``;
* ``split``: a merged pair of neighbouring border points gets a new point for one of
  the two lanelets at distance ``Delta b ~ U[0, split_max]`` (paper: 0.6 m);
* ``merge``: a split pair gets one point, equally likely the one of either lanelet.

The proposals are symmetric except for split/merge, which we treat as symmetric
too (like the paper, the chain is annealed towards the MAP estimate).
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ['add_user', 'remove_user', 'save_and_move', 'set_ref', 'move_center', 'move_border',
           'split', 'merge', 'undo']


@njit(cache=True)
def add_user(users, nusers, p, slot):
    users[p, nusers[p]] = slot
    nusers[p] += 1


@njit(cache=True)
def remove_user(users, nusers, p, slot):
    n = nusers[p]
    for i in range(n):
        if users[p, i] == slot:
            users[p, i] = users[p, n - 1]
            users[p, n - 1] = -1
            nusers[p] = n - 1
            return


@njit(cache=True)
def save_and_move(P, p, dx, dy, up_p, up_xy, n_up):
    """Record point ``p`` in the undo log, then shift it by (dx, dy)."""
    up_p[n_up] = p
    up_xy[n_up, 0] = P[p, 0]
    up_xy[n_up, 1] = P[p, 1]
    P[p, 0] += dx
    P[p, 1] += dy
    return n_up + 1


@njit(cache=True)
def set_ref(ref, users, nusers, slot, newp, rc_slot, rc_old, n_rc):
    """Point ``slot`` at ``newp``, recording the old reference."""
    old = ref[slot]
    rc_slot[n_rc] = slot
    rc_old[n_rc] = old
    remove_user(users, nusers, old, slot)
    add_user(users, nusers, newp, slot)
    ref[slot] = newp
    return n_rc + 1


@njit(cache=True)
def move_center(P, ref, st_normal, g, step, up_p, up_xy):
    """Translate the cross section of station ``g`` laterally; returns #points logged."""
    d = np.random.normal() * step
    dx, dy = d * st_normal[g, 0], d * st_normal[g, 1]
    n = save_and_move(P, ref[2 * g], dx, dy, up_p, up_xy, 0)
    return save_and_move(P, ref[2 * g + 1], dx, dy, up_p, up_xy, n)


@njit(cache=True)
def move_border(P, ref, axis, slot, step, up_p, up_xy):
    """Shift the border point of ``slot`` along its axis."""
    p = ref[slot]
    d = np.random.normal() * step
    return save_and_move(P, p, d * axis[p, 0], d * axis[p, 1], up_p, up_xy, 0)


@njit(cache=True)
def split(P, ref, home, axis, users, nusers, a, b, split_max, up_p, up_xy, rc_slot, rc_old):
    """Split the merged pair (a, b): one slot gets its own point Delta b away.

    Returns (#points logged, #references logged)."""
    q = ref[a]
    x, y = (a, b) if np.random.random() < 0.5 else (b, a)
    db = np.random.random() * split_max * (1.0 if np.random.random() < 0.5 else -1.0)
    n_up, n_rc = 0, 0
    if home[x] != q:
        h = home[x]
        n_up = save_and_move(P, h, P[q, 0] - P[h, 0] + db * axis[q, 0],
                             P[q, 1] - P[h, 1] + db * axis[q, 1], up_p, up_xy, n_up)
        n_rc = set_ref(ref, users, nusers, x, h, rc_slot, rc_old, n_rc)
    else:
        h = home[y]
        n_up = save_and_move(P, h, P[q, 0] - P[h, 0], P[q, 1] - P[h, 1], up_p, up_xy, n_up)
        n_rc = set_ref(ref, users, nusers, y, h, rc_slot, rc_old, n_rc)
        n_up = save_and_move(P, q, db * axis[q, 0], db * axis[q, 1], up_p, up_xy, n_up)
    return n_up, n_rc


@njit(cache=True)
def merge(ref, users, nusers, a, b, rc_slot, rc_old):
    """Merge the split pair (a, b): both take the point of a or of b (p = 1/2 each)."""
    if np.random.random() < 0.5:
        return set_ref(ref, users, nusers, b, ref[a], rc_slot, rc_old, 0)
    return set_ref(ref, users, nusers, a, ref[b], rc_slot, rc_old, 0)


@njit(cache=True)
def undo(P, ref, users, nusers, up_p, up_xy, n_up, rc_slot, rc_old, n_rc):
    """Revert the logged changes in reverse order."""
    for i in range(n_up - 1, -1, -1):
        P[up_p[i], 0] = up_xy[i, 0]
        P[up_p[i], 1] = up_xy[i, 1]
    for i in range(n_rc - 1, -1, -1):
        s = rc_slot[i]
        remove_user(users, nusers, ref[s], s)
        add_user(users, nusers, rc_old[i], s)
        ref[s] = rc_old[i]
