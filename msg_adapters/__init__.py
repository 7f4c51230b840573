"""ROS message <-> numpy conversions, one module per message family.

Every reader is duck-typed over message fields, so the same function reads a message
from rclpy and one that rosbags deserialised from a bag's embedded schema. Readers raise
only :class:`~msg_adapters.errors.AdapterError` (with a stable ``reason`` key); they never
import rclpy.

Readers (message -> numpy):

* :mod:`.pointcloud2`  ``read_pointcloud2`` radar PointCloud2 -> ``RadarCloud``
* :mod:`.radar_scan`   ``read_radar_scan`` radar_msgs/RadarScan -> ``RadarCloud``
* :mod:`.pose_array`   ``read_pose_array`` PoseArray -> ``PoseList``
* :mod:`.tracked_objects` ``read_objects`` ours / Autoware / derived_object_msgs -> ``ObjectList``
* :mod:`.odometry`     ``read_odometry``, ``read_tf_static``, ``EgoPoseBuffer`` (frames)
* :mod:`.detections`   ``to_detections`` any input + ego buffer -> ``observations.Detections``
* :mod:`.topology`, :mod:`.lanelets` ``read_topology``, ``read_lanelets`` (our outputs)

Builders (numpy -> message) take a message namespace from :mod:`.types`
(``RclpyTypes()`` for the node, ``RosbagsTypes(typestore)`` for bags): ``radar_cloud_msg``,
``radar_scan_msg``, ``pose_array_msg``, ``tracked_object_array_msg``,
``autoware_tracked_objects_msg``, ``derived_object_array_msg``, ``odometry_msg``,
``topology_msg``, ``lanelets_msg``, ``markers_msg``.

``schemas/`` holds the .msg definitions of packages without a wheel (Autoware,
radar_msgs, derived_object_msgs) for ``intersection_estimator.bagio.typestore()``.
"""
