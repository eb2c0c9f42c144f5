"""Real rclpy (the side environment): counts what arrives on /bench/skeleton, /bench/camera and
/bench/said; prints {"said": wall ns} for each String as it arrives and the counts on "count"."""

import json
import queue
import sys
import threading
import time

import rclpy
from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from sensor_msgs.msg import CompressedImage
from std_msgs.msg import String
from visualization_msgs.msg import MarkerArray


def main() -> None:
    rclpy.init()
    node = rclpy.create_node("bench_counter")
    counts = {"skeleton": 0, "camera": 0}

    def counter(kind: str):
        def count(_message: object) -> None:
            counts[kind] += 1

        return count

    node.create_subscription(MarkerArray, "/bench/skeleton", counter("skeleton"),
                             qos_profile_sensor_data)  # fmt: skip
    node.create_subscription(CompressedImage, "/bench/camera", counter("camera"),
                             qos_profile_sensor_data)  # fmt: skip
    reliable = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
    node.create_subscription(String, "/bench/said",
                             lambda _m: print(json.dumps({"said": time.time_ns()}), flush=True),
                             reliable)  # fmt: skip
    asked: queue.Queue[str] = queue.Queue()

    def read_stdin() -> None:
        for line in sys.stdin:
            asked.put(line.strip())
        asked.put("quit")

    threading.Thread(target=read_stdin, daemon=True).start()
    print(json.dumps({"ready": True}), flush=True)
    while True:
        rclpy.spin_once(node, timeout_sec=0.01)
        try:
            line = asked.get_nowait()
        except queue.Empty:
            continue
        if line == "count":
            print(json.dumps(counts), flush=True)
        elif line == "quit":
            break
    node.destroy_node()
    rclpy.shutdown()


if __name__ == "__main__":
    main()
