"""ROS message <-> numpy conversions, one module per message family.

Every reader is duck-typed over message fields, so the same function reads a message
from rclpy and one that rosbags deserialised from a bag's embedded schema.
"""
