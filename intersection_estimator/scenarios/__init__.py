"""Scenario families beyond the Table I simulator (issue 15): SUMO traffic on junction
networks (:mod:`.sumo`), and the helpers they share with the real-data converters
(:mod:`intersection_estimator.realdata`): ground truth from a lane graph
(:mod:`.lanegraph`) and the traffic-following floor (:mod:`.floor`)."""

from __future__ import annotations

__all__ = ['gt_doc']


def gt_doc(scenario, *, arrays: bool = False) -> dict:
    """gt.json of a scenario: :func:`~intersection_estimator.estimate_io.gt_to_dict` plus
    the per-lane additions (``traffic_line``, ``present``) and ``info`` of a family scenario."""
    import numpy as np
    from ..estimate_io import gt_to_dict
    d = gt_to_dict(scenario, arrays=arrays)
    extra = getattr(scenario, 'extra_gt', {}) or {}
    for lane in d['lanes']:
        for k, v in extra.get(lane['id'], {}).items():
            if np.ndim(v) == 0:                  # a count (``present``)
                lane[k] = int(v)
            else:
                lane[k] = v if arrays else [[float(x), float(y)] for x, y in v]
    info = getattr(scenario, 'info', None)
    if info:
        d['source'] = info
    return d
