"""ROS 2 plumbing the faces share: the interface packages' build (``interfaces``), the rclpy
wire (``wire``: rclpy is imported there, only in the ROS 2 environment) and Fast DDS's
loopback profile. The faces themselves live beside their cores (``lowerbase.driver.ros2_node``)."""

from pathlib import Path

#: Fast DDS profile: UDP on 127.0.0.1 only, and shared memory (docs/ros2.md, "Loopback")
FASTDDS_LOOPBACK = Path(__file__).resolve().with_name("fastdds_loopback.xml")
