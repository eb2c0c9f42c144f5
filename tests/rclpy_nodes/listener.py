"""A real rclpy node (run in the side environment): prints each std_msgs/String on the topic
given as a JSON line, and on a line "graph" on stdin the node and topic lists as rclpy sees
them; ends at "quit" or when stdin closes."""

import json
import select
import sys

import rclpy
from rclpy.qos import QoSProfile, ReliabilityPolicy
from std_msgs.msg import String


def main() -> None:
    rclpy.init()
    node = rclpy.create_node("judge")
    qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)

    def on_string(message: String) -> None:
        print(json.dumps({"data": message.data}), flush=True)

    node.create_subscription(String, sys.argv[1], on_string, qos)
    print(json.dumps({"ready": True}), flush=True)
    while True:
        rclpy.spin_once(node, timeout_sec=0.05)
        if not select.select([sys.stdin], [], [], 0)[0]:
            continue
        line = sys.stdin.readline().strip()
        if line == "graph":
            nodes = node.get_node_names_and_namespaces()
            topics = node.get_topic_names_and_types()
            print(json.dumps({"nodes": nodes, "topics": topics}), flush=True)
        elif line in ("quit", ""):
            break
    node.destroy_node()
    rclpy.shutdown()


if __name__ == "__main__":
    main()
