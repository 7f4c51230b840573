"""Vehicles that stand through the recording: evidence of an arm, not of a lane (beyond the paper).

The paper's tracked observations (§II-A) are trajectory parts, and
:func:`.preprocess.moving_tracks` drops a track that is never fast: static clutter, a parked
car. A queue at a red light looks the same to a speed test -- in a recording of half a
minute its vehicles may stand from the first frame to the last -- and an arm whose only
traffic is such a queue was never found, and one whose few moving vehicles leave it
thinly supported lost to the arm-count prior. Its vehicles stand on the arm's lanes,
heading into the box, so each standing track becomes one observation here:

* its mean position and circular-mean heading (orientation known); a track without a
  heading -- the radar tracker reports a vehicle that never drove so (:mod:`..tracking`) --
  is taken to face the box, and the queue rule alone decides;
* only a vehicle that faces the box (an entering vehicle: heading towards the center) and
  stands in a queue of at least ``standing_queue`` standing vehicles one behind the other
  on a line (:func:`_in_queues`: neighbours within ``QUEUE_LATERAL_M`` across,
  ``QUEUE_GAP_M`` apart along, same heading). A parked car stands at the kerb, alone or
  in a row that does not face the box on half the kerbs; the issue asks that parked
  vehicles make no arm. A single vehicle waiting at the line is missed;
* ``sigma_track_weak`` across, like a cyclist's part (:func:`.preprocess._part_sigma`): a
  standing vehicle shows that its arm exists and which way it is driven, not a lane of its
  own;
* weight ``standing_weight`` (one passage each: the arm-support rules count it);
* only tracks that stood at least ``standing_min_s`` (a false track of clutter lives a few
  frames), in the ring ``part_outside <= r <= track_radius`` around the center (a vehicle
  standing inside the box is not on an arm), and not of ``weak_labels`` road users (a
  standing pedestrian is no evidence of a road).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components

from ..model import ENTERING, direction_class, unit_vectors
from ..observations import Detections
from .likelihood import ObservationSet

__all__ = ['standing_tracks', 'standing_observations', 'queue_groups']


def standing_tracks(dets: Detections, order, starts, ends, still, min_s: float):
    """``(mean xy (n, 2), mean heading unit vectors (n, 2), label (n,))`` of the tracks
    ``still`` (a mask over the bounds ``starts``/``ends`` into ``order``, as
    :func:`.preprocess.track_bounds` gives them) that lived at least ``min_s``; a track
    without a heading (a radar track that never moved, :mod:`..tracking`) gets NaN."""
    if len(starts) == 0 or not still.any():
        return np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0, np.int64)
    t, xy, h = dets.t[order], dets.xy[order], dets.heading[order]
    cnt = (ends - starts).astype(float)
    mean = np.stack([np.add.reduceat(xy[:, k], starts) for k in range(2)], 1) / cnt[:, None]
    ok = np.isfinite(h)
    hv = np.stack([np.add.reduceat(np.where(ok, np.cos(h), 0.0), starts),
                   np.add.reduceat(np.where(ok, np.sin(h), 0.0), starts)], 1)
    norm = np.hypot(hv[:, 0], hv[:, 1])
    keep = still & (t[ends - 1] - t[starts] >= min_s)
    with np.errstate(invalid='ignore', divide='ignore'):
        hv = np.where((norm > 1e-9)[:, None], hv / norm[:, None], np.nan)
    return mean[keep], hv[keep], dets.label[order[starts[keep]]].astype(np.int64)


#: two standing vehicles are neighbours in a queue when one stands behind the other on its
#: line: within this much across [m] ...
QUEUE_LATERAL_M = 1.5
#: ... this far apart along it [m]: a car length and a standstill gap (two parked cars 13 m
#: apart on a side street made an arm with 15 m; a truck's neighbour stands farther) ...
QUEUE_GAP_M = (4.0, 10.0)
#: ... and heading the same way within this [deg]
QUEUE_HEADING_DEG = 20.0


def queue_groups(xy: np.ndarray, hv: np.ndarray, min_len: int) -> np.ndarray:
    """Per standing vehicle its queue (module doc: the connected groups of vehicles that
    stand one behind the other on one line), -1 in a queue of fewer than ``min_len``."""
    if len(xy) == 0:
        return np.zeros(0, np.int64)
    d = xy[None, :, :] - xy[:, None, :]                     # j - i
    along = d[..., 0] * hv[:, None, 0] + d[..., 1] * hv[:, None, 1]
    across = d[..., 0] * -hv[:, None, 1] + d[..., 1] * hv[:, None, 0]
    same = hv @ hv.T >= math.cos(math.radians(QUEUE_HEADING_DEG))
    nb = (same & (np.abs(across) < QUEUE_LATERAL_M) & (np.abs(along) >= QUEUE_GAP_M[0])
          & (np.abs(along) <= QUEUE_GAP_M[1]))
    _, group = connected_components(csr_matrix(nb | nb.T), directed=False)
    return np.where(np.bincount(group)[group] >= min_len, group, -1).astype(np.int64)


def _in_queues(xy: np.ndarray, hv: np.ndarray, min_len: int):
    """The standing vehicles of queues of at least ``min_len`` (:func:`queue_groups`)."""
    if min_len <= 1 or len(xy) == 0:
        return xy, hv
    keep = queue_groups(xy, hv, min_len) >= 0
    return xy[keep], hv[keep]


def standing_observations(dets: Detections, center, order, starts, ends, still,
                          cfg) -> ObservationSet:
    """The tracks ``still`` (see :func:`standing_tracks`) as weak observations around
    ``center`` (module doc); ``cfg``: the preprocessing parameters; empty with
    ``standing_weight`` 0."""
    if cfg.standing_weight <= 0:
        return ObservationSet.empty()
    xy, hv, label = standing_tracks(dets, order, starts, ends, still, cfg.standing_min_s)
    c = np.asarray(center, float)
    r = np.hypot(xy[:, 0] - c[0], xy[:, 1] - c[1])
    on = (r >= cfg.part_outside) & (r <= cfg.track_radius)
    if len(cfg.weak_labels):
        on &= ~np.isin(label, np.asarray(cfg.weak_labels, np.int64))
    headless = ~np.isfinite(hv[:, 0])
    if headless.any():                    # faces the box: the queue rule alone decides
        to_c = c - xy[headless]
        hv[headless] = np.stack(unit_vectors(to_c[:, 0], to_c[:, 1])[:2], axis=1)
    facing = direction_class(xy[:, 0], xy[:, 1], hv[:, 0], hv[:, 1], c) == ENTERING
    xy, hv = xy[on & facing], hv[on & facing]
    xy, hv = _in_queues(xy, hv, cfg.standing_queue)
    n = len(xy)
    if n == 0:
        return ObservationSet.empty()
    d = np.ones(n)
    w = np.full(n, float(cfg.standing_weight))
    return ObservationSet(xy[:, 0].copy(), xy[:, 1].copy(), hv[:, 0].copy(), hv[:, 1].copy(),
                          np.ones(n, np.bool_), d, w, np.full(n, cfg.sigma_track_weak),
                          np.full(n, math.radians(cfg.sigma_angle_deg)), np.ones(n))
