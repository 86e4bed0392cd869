"""Run in the ROS 2 venv: ``pub TOPIC`` publishes woosh_msgs/Battery at 20 Hz until killed;
``sub TOPIC`` waits (at most 30 s) for one and prints it as JSON."""

from __future__ import annotations

import json
import sys
import time

import rclpy
from rclpy.qos import qos_profile_sensor_data
from woosh_msgs.msg import Battery


def main() -> None:
    mode, topic = sys.argv[1], sys.argv[2]
    rclpy.init()
    node = rclpy.create_node(f"lowerbase_test_{mode}")
    if mode == "pub":
        pub = node.create_publisher(Battery, topic, qos_profile_sensor_data)
        msg = Battery(batteryPercentage=87, batteryVoltage=51.5, chargeMode=Battery.autoMode,
                      bmsStatus=0xDEADBEEF)
        msg.header.frame_id = "battery"
        while True:
            msg.header.stamp = node.get_clock().now().to_msg()
            pub.publish(msg)
            rclpy.spin_once(node, timeout_sec=0.05)
    got: list[Battery] = []
    node.create_subscription(Battery, topic, got.append, qos_profile_sensor_data)
    deadline = time.monotonic() + 30.0
    while not got and time.monotonic() < deadline:
        rclpy.spin_once(node, timeout_sec=0.1)
    if not got:
        sys.exit("no woosh_msgs/Battery within 30 s")
    m = got[0]
    print(json.dumps({"percentage": m.batteryPercentage, "voltage": m.batteryVoltage,
                      "charge_mode": m.chargeMode, "bms_status": m.bmsStatus,
                      "frame_id": m.header.frame_id, "auto_mode": Battery.autoMode}))
    node.destroy_node()
    rclpy.shutdown()


if __name__ == "__main__":
    main()
