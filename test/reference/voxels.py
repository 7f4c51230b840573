"""References of the compiled voxelisation (:mod:`intersection_estimator.topology.voxels`),
plain numpy written independently of the kernels."""

from __future__ import annotations

import numpy as np

from intersection_estimator.topology.config import PreprocessConfig
from intersection_estimator.topology.voxels import passages


def arm_voxels_reference(xy, cls, arm, s, t, stamp, cfg: PreprocessConfig, vec=None):
    """Plain numpy voxelisation, written independently of the compiled kernel.

    Returns mean position, class, weight in vehicle passages (and summed ``vec``)."""
    si = np.floor(s / cfg.voxel_length).astype(np.int64)
    ti = np.floor(t / cfg.voxel_width).astype(np.int64)
    key = ((arm * 1024 + si + 512) * 4096 + ti + 2048) * 4 + cls
    uk, inv, cnt = np.unique(key, return_inverse=True, return_counts=True)
    inv = inv.reshape(-1)
    p = xy
    mean = np.stack([np.bincount(inv, p[:, 0], len(uk)), np.bincount(inv, p[:, 1], len(uk))],
                    axis=1) / cnt[:, None]
    if cfg.straight_run:   # occupied neighbour (lateral band +-1) before and after
        step = 4096 * 4
        before = np.zeros(len(uk), bool)
        after = np.zeros(len(uk), bool)
        for dt in (-4, 0, 4):
            before |= np.isin(uk - step + dt, uk, assume_unique=True)
            after |= np.isin(uk + step + dt, uk, assume_unique=True)
        keepv = before & after
    else:
        keepv = np.ones(len(uk), bool)
    # detections per vehicle passage of an along-arm bin (all lateral bins together)
    band = (arm * 1024 + si + 512) * 4 + cls
    ub, binv = np.unique(band, return_inverse=True)
    n_pass = passages(binv.reshape(-1), stamp, len(ub), cfg.passage_gap).sum()
    per_pass = len(xy) / max(n_pass, 1.0) if cfg.passage_gap > 0 else 1.0
    sv = np.zeros((len(uk), 2))
    if vec is not None:
        sv = np.stack([np.bincount(inv, vec[:, 0], len(uk)),
                       np.bincount(inv, vec[:, 1], len(uk))], axis=1)
    uk, mean, cnt, sv = uk[keepv], mean[keepv], cnt[keepv].astype(np.float64), sv[keepv]
    if cfg.voxel_merge > 1:   # fewer, longer voxels for the sampler (filter ran at full res.)
        si_k = (uk // (4096 * 4)) % 1024
        arm_k = uk // (4096 * 4 * 1024)
        rest = uk % (4096 * 4)
        key2 = (arm_k * 1024 + si_k // cfg.voxel_merge) * (4096 * 4) + rest
        u2, inv2 = np.unique(key2, return_inverse=True)
        inv2 = inv2.reshape(-1)
        c2 = np.bincount(inv2, cnt, len(u2))
        mean = np.stack([np.bincount(inv2, cnt * mean[:, 0], len(u2)),
                         np.bincount(inv2, cnt * mean[:, 1], len(u2))], axis=1) / c2[:, None]
        sv = np.stack([np.bincount(inv2, sv[:, 0], len(u2)), np.bincount(inv2, sv[:, 1], len(u2))],
                      axis=1)
        uk, cnt = u2, c2
    if vec is not None:
        return mean, uk % 4, cnt / per_pass, sv
    return mean, uk % 4, cnt / per_pass


def voxelise_reference(xy, cls, size, vec):
    """np.unique voxels: sorted (x bin, y bin, class) keys, means, first class, counts."""
    ij = np.floor(xy / size).astype(np.int64)
    key = (((ij[:, 0] + (1 << 20)) << 22) + (ij[:, 1] + (1 << 20))) * 64 + cls
    uk, inv, cnt = np.unique(key, return_inverse=True, return_counts=True)
    inv = inv.reshape(-1)
    mean = np.stack([np.bincount(inv, xy[:, 0]), np.bincount(inv, xy[:, 1])], axis=1) / cnt[:, None]
    sv = np.stack([np.bincount(inv, vec[:, 0], len(uk)), np.bincount(inv, vec[:, 1], len(uk))], 1)
    return mean, uk % 64, cnt.astype(np.float64), sv
