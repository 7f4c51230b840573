"""The one input-role vocabulary: which message types feed which input of the pipeline.

An *input role* is the node parameter that names its topics (``radar_topics``, ...,
``odometry_topic``). The node subscribes to a role's topics with the role's first type
(:func:`node_type`); bags and the replay accept every type of the row (older Autoware
names, predicted/detected objects, derived_object_msgs) -- the adapters read them all
(:mod:`msg_adapters`). Used by :mod:`.ingest` (subscriptions), :mod:`.bagio` (topics of a
bag by type), :mod:`.replay` and :mod:`.soak`.
"""

from __future__ import annotations

__all__ = ['ROLE_TYPES', 'INPUT_ROLES', 'ODOMETRY', 'TRACK_TYPES', 'role_of_type', 'node_type']

#: Input role (node parameter) -> message types it accepts; the first is the node's.
ROLE_TYPES: dict[str, tuple[str, ...]] = {
    'radar_topics': ('sensor_msgs/msg/PointCloud2',),
    'radar_scan_topics': ('radar_msgs/msg/RadarScan',),
    'detection_topics': ('geometry_msgs/msg/PoseArray',),
    'object_topics': ('intersection_estimator_msgs/msg/TrackedObjectArray',
                      'derived_object_msgs/msg/ObjectArray'),
    'autoware_object_topics': ('autoware_perception_msgs/msg/TrackedObjects',
                               'autoware_auto_perception_msgs/msg/TrackedObjects',   # pre-2024 name
                               'autoware_perception_msgs/msg/PredictedObjects',
                               'autoware_auto_perception_msgs/msg/PredictedObjects',
                               'autoware_perception_msgs/msg/DetectedObjects',
                               'autoware_auto_perception_msgs/msg/DetectedObjects'),
    'odometry_topic': ('nav_msgs/msg/Odometry',),
}
#: The ego pose input (one topic, not a list).
ODOMETRY = 'odometry_topic'
#: Roles that carry observations (everything but the ego pose).
INPUT_ROLES = tuple(r for r in ROLE_TYPES if r != ODOMETRY)
#: Types carrying *tracks*: when topics are found by type, one topic of all of these is
#: used (a stack publishing the same tracks in two message families would count twice).
TRACK_TYPES = frozenset(ROLE_TYPES['object_topics'] + ROLE_TYPES['autoware_object_topics'][:4])


def role_of_type(msgtype: str) -> str | None:
    """The input role that accepts ``msgtype`` (None for any other type)."""
    for role, types in ROLE_TYPES.items():
        if msgtype in types:
            return role
    return None


def node_type(role: str) -> str:
    """The message type the node subscribes to ``role``'s topics with."""
    return ROLE_TYPES[role][0]
