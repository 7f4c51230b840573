"""Launch the intersection estimator beside a perception stack (machines with ROS 2 installed).

    ros2 launch intersection_estimator intersection_estimator.launch.py \
        radar_topic:=/sensing/radar/points objects_topic:=/perception/object_recognition/tracking/objects \
        odometry_topic:=/localization/kinematic_state managed:=false use_sim_time:=false

Arguments: ``params_file`` (default: the package's config/intersection_estimator.yaml),
``namespace``, ``use_sim_time``, ``managed`` (true: the lifecycle node, for
nav2_lifecycle_manager; it starts unconfigured), and the input topics, applied as
remappings of the parameter file's default topic names.
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.conditions import IfCondition, UnlessCondition
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import LifecycleNode, Node

PACKAGE = 'intersection_estimator'
PLAIN = 'intersection_estimator_node'
MANAGED = 'intersection_estimator_lifecycle_node'
#: launch argument -> the topic name in config/intersection_estimator.yaml it remaps
REMAPS = {
    'radar_topic': '/perception/radar/points',
    'objects_topic': '/perception/objects',
    'odometry_topic': '/localization/odometry',
}


def generate_launch_description():
    params = os.path.join(get_package_share_directory(PACKAGE), 'config', 'intersection_estimator.yaml')
    args = [DeclareLaunchArgument('params_file', default_value=params),
            DeclareLaunchArgument('namespace', default_value=''),
            DeclareLaunchArgument('use_sim_time', default_value='false'),
            DeclareLaunchArgument('managed', default_value='false')]
    args += [DeclareLaunchArgument(name, default_value=topic) for name, topic in REMAPS.items()]
    common = dict(package=PACKAGE, name='intersection_estimator', namespace=LaunchConfiguration('namespace'),
                  output='screen',
                  parameters=[LaunchConfiguration('params_file'),
                              {'use_sim_time': LaunchConfiguration('use_sim_time')}],
                  remappings=[(topic, LaunchConfiguration(name)) for name, topic in REMAPS.items()])
    managed = LaunchConfiguration('managed')
    return LaunchDescription(args + [
        Node(executable=PLAIN, condition=UnlessCondition(managed), **common),
        LifecycleNode(executable=MANAGED, condition=IfCondition(managed), **common),
    ])
