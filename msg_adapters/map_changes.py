"""``intersection_estimator_msgs/MapChangeArray`` and the ``map_changes`` markers of a live
comparison with the prior map (:class:`intersection_estimator.fleet.live.LiveReport`).

Markers (namespace ``map_changes``, in the header's frame): the prior map's lanes that a
change concerns as thick red line strips, an added arm as an orange arrow from the mapped
center, and one text per change (kind, arm, confidence) -- the same colours as the fleet's
change PNGs. Keys published before and gone now get a DELETE (stable ids per lanelet id).
"""

from __future__ import annotations

import math

import numpy as np

from .markers import ARROW, DELETE, LINE_STRIP, TEXT_VIEW_FACING, _Builder, lanelet_marker_id

__all__ = ['NAMESPACE', 'map_changes_msg', 'map_change_markers']

NAMESPACE = 'map_changes'
_ARM_LENGTH = 40.0   # [m] drawn length of an added arm


def _change_msg(types, c):
    keys = sorted(k for k, v in c.evidence.items() if isinstance(v, (int, float)) and not isinstance(v, bool))
    return types.get('intersection_estimator_msgs/msg/MapChange')(
        kind=c.kind, key=c.key, confidence=float(c.confidence), map_arm=int(c.map_arm),
        direction=str(c.direction), map_lanelet_ids=[str(i) for i in c.map_lanes],
        evidence_keys=keys, evidence_values=[float(c.evidence[k]) for k in keys])


def map_changes_msg(types, header, report):
    """MapChangeArray of ``report`` (changes sorted by key)."""
    return types.get('intersection_estimator_msgs/msg/MapChangeArray')(
        header=header, intersection_id=report.intersection_id,
        changes=[_change_msg(types, c) for c in sorted(report.changes, key=lambda c: c.key)],
        unobserved_arms=[int(a) for a in report.unobserved], passages=float(report.passages))


def map_change_markers(types, header, report, previous_keys=frozenset()):
    """(MarkerArray, keys) of ``report``'s changes plus DELETEs for ``previous_keys`` gone."""
    from intersection_estimator.fleet.prior_map import lane_centers
    b = _Builder(types, header)
    markers = []
    X = report.mapped
    if X is not None and report.changes:
        changed = {str(i) for c in report.changes for i in c.map_lanes}
        for lid, center in lane_centers(X):
            if str(lid) in changed:
                markers.append(b.marker(NAMESPACE, lanelet_marker_id(lid), LINE_STRIP, 'changed',
                                        (0.6, 0, 0), b.points(center)))
        c0 = np.asarray(X.center, float)
        for k, c in enumerate(sorted(report.changes, key=lambda c: c.key)):
            if c.kind == 'arm_added' and 'angle_deg' in c.evidence:
                a = math.radians(float(c.evidence['angle_deg']))
                end = c0 + _ARM_LENGTH * np.array([math.cos(a), math.sin(a)])
                markers.append(b.marker(NAMESPACE, 1_000_000 + k, ARROW, 'added', (0.6, 1.5, 2.0),
                                        b.points([c0, end])))
            arm = f' arm {c.map_arm}{c.direction}' if c.map_arm >= 0 else ''
            markers.append(b.marker(NAMESPACE, 2_000_000 + k, TEXT_VIEW_FACING, 'text', (0, 0, 1.5),
                                    position=c0 + np.array([0.0, -3.0 * (k + 1)]),
                                    text=f'{c.kind}{arm} ({c.confidence:.2f})'))
    keys = frozenset((m.ns, int(m.id)) for m in markers)
    for ns, mid in sorted(set(previous_keys) - keys):
        markers.append(b.marker(ns, mid, ARROW, 'arrow', action=DELETE))
    return types.get('visualization_msgs/msg/MarkerArray')(markers=markers), keys
