"""``python -m lowerbase.ros2.latency TOPIC SECONDS``: how late a topic's messages reach an
rclpy subscriber (benchmarks/bench_ros2.py runs it in the ROS 2 venv beside the driver).

It subscribes to ``TOPIC`` (nav_msgs/Odometry, the QoS :func:`lowerbase.ros2.wire.qos_for`
gives it, depth 200), waits (at most 120 s) for the first message, then takes messages for
``SECONDS``. Latency is the subscriber's callback time minus the DDS source timestamp (the
publisher's ``publish`` call), both this host's system clock; lost is the number of
publication sequence numbers skipped. Prints one JSON line: count, rate [Hz], p50/p99/max
latency [ms], lost, how many took over 10 ms and when the
worst came (seconds into the window).
"""

from __future__ import annotations

import json
import statistics
import sys
import time
from typing import Any


def main(argv: list[str]) -> int:
    import rclpy
    from nav_msgs.msg import Odometry

    from lowerbase.ros2.wire import qos_for

    topic, seconds = argv[0], float(argv[1])
    rclpy.init()
    node = rclpy.create_node("lowerbase_latency")
    latencies: list[float] = []
    sequence: list[int] = []

    def take(_msg: Any, info: Any) -> None:
        latencies.append((time.time_ns() - info["source_timestamp"]) / 1e6)
        sequence.append(int(info["publication_sequence_number"]))

    node.create_subscription(Odometry, topic, take, qos_for(topic, 200))
    deadline = time.monotonic() + 120.0
    while not latencies:
        if time.monotonic() > deadline:
            print(f"lowerbase.ros2.latency: no {topic} within 120 s", file=sys.stderr)
            return 1
        rclpy.spin_once(node, timeout_sec=0.1)
    latencies.clear()
    sequence.clear()
    start = time.monotonic()
    while time.monotonic() - start < seconds:
        rclpy.spin_once(node, timeout_sec=0.1)
    elapsed = time.monotonic() - start
    node.destroy_node()
    rclpy.shutdown()
    ordered = sorted(latencies)
    n = len(ordered)
    lost = (sequence[-1] - sequence[0] + 1 - n) if n else 0
    print(json.dumps({
        "count": n, "rate": n / elapsed,
        "p50_ms": statistics.median(ordered) if n else float("nan"),
        "p99_ms": ordered[min(n - 1, int(0.99 * n))] if n else float("nan"),
        "max_ms": ordered[-1] if n else float("nan"), "lost": lost,
        "over_10ms": sum(v > 10.0 for v in ordered),
        "worst_at_s": (latencies.index(ordered[-1]) / n * elapsed) if n else float("nan")}))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
