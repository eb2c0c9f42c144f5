"""A real rclpy node (run in the side environment): prints each std_msgs/String on the topic
given first as a JSON line, counts the MarkerArrays on the topic given second, and on a line
"graph" on stdin prints the node and topic lists as rclpy sees them and that count; ends at
"quit" or when stdin closes."""

import json
import queue
import sys
import threading

import rclpy
from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from std_msgs.msg import String
from visualization_msgs.msg import MarkerArray


def main() -> None:
    rclpy.init()
    node = rclpy.create_node("judge")
    qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)

    def on_string(message: String) -> None:
        print(json.dumps({"data": message.data}), flush=True)

    node.create_subscription(String, sys.argv[1], on_string, qos)
    markers = [0]

    def on_markers(message: MarkerArray) -> None:
        markers[0] += 1

    node.create_subscription(MarkerArray, sys.argv[2], on_markers, qos_profile_sensor_data)
    asked: queue.Queue[str] = queue.Queue()

    def read_stdin() -> None:
        for question in sys.stdin:
            asked.put(question.strip())
        asked.put("quit")  # stdin closed: the test is gone

    threading.Thread(target=read_stdin, daemon=True).start()
    print(json.dumps({"ready": True}), flush=True)
    while True:
        rclpy.spin_once(node, timeout_sec=0.05)
        try:
            line = asked.get_nowait()
        except queue.Empty:
            continue
        if line == "graph":
            nodes = node.get_node_names_and_namespaces()
            topics = node.get_topic_names_and_types()
            print(json.dumps({"nodes": nodes, "topics": topics, "markers": markers[0]}), flush=True)
        elif line in ("quit", ""):
            break
    node.destroy_node()
    rclpy.shutdown()


if __name__ == "__main__":
    main()
