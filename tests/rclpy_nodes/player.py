"""A real rclpy node (run in the side environment) playing recorded sensor messages: argv are
the records file (JSON lines: topic, ROS 2 type, CDR in base64), it prints "matched" once every
publisher has a subscriber, then publishes record N for each line N on stdin and says so."""

import base64
import importlib
import json
import sys
import threading
import time

import rclpy
from rclpy.serialization import deserialize_message


def message_class(ros_type: str) -> type:
    package, kind, name = ros_type.split("/")
    return getattr(importlib.import_module(f"{package}.{kind}"), name)


def main() -> None:
    rclpy.init()
    node = rclpy.create_node("player")
    with open(sys.argv[1]) as f:
        records = [json.loads(line) for line in f]
    publishers = {}
    messages = []
    for record in records:
        cls = message_class(record["type"])
        if record["topic"] not in publishers:
            publishers[record["topic"]] = node.create_publisher(cls, record["topic"], 10)
        messages.append(
            (record["topic"], deserialize_message(base64.b64decode(record["cdr"]), cls))
        )
    while not all(p.get_subscription_count() > 0 for p in publishers.values()):
        time.sleep(0.05)
    print(json.dumps({"matched": True}), flush=True)
    spinning = threading.Thread(target=rclpy.spin, args=(node,), daemon=True)
    spinning.start()
    for line in sys.stdin:
        if not line.strip():
            break
        index = int(line)
        topic, message = messages[index]
        publishers[topic].publish(message)
        print(json.dumps({"sent": index}), flush=True)
    node.destroy_node()
    rclpy.shutdown()


if __name__ == "__main__":
    main()
