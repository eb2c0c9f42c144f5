"""Real rclpy (the side environment), the anchor: publishes the records given (JSON lines:
kind, ROS 2 type, CDR in base64) as rclpy messages. On "cpu KIND N" it publishes N of that
kind and prints the CPU seconds its process spent; on "one" it publishes one String on
/bench/said and prints the wall ns it started at."""

import base64
import importlib
import json
import sys
import time

import rclpy
from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from rclpy.serialization import deserialize_message


def cls_of(ros_type: str) -> type:
    package, kind, name = ros_type.split("/")
    return getattr(importlib.import_module(f"{package}.{kind}"), name)


def main() -> None:
    rclpy.init()
    node = rclpy.create_node("bench_publisher")
    messages: dict[str, list[object]] = {}
    publishers = {}
    reliable = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
    with open(sys.argv[1]) as f:
        for line in f:
            record = json.loads(line)
            cls = cls_of(record["type"])
            message = deserialize_message(base64.b64decode(record["cdr"]), cls)
            messages.setdefault(record["kind"], []).append(message)
            if record["kind"] not in publishers:
                topic = {"skeleton": "/bench/skeleton", "camera": "/bench/camera"}.get(
                    record["kind"], "/bench/said"
                )
                qos = reliable if record["kind"] == "description" else qos_profile_sensor_data
                publishers[record["kind"]] = node.create_publisher(cls, topic, qos)
    while not all(p.get_subscription_count() > 0 for p in publishers.values()):
        time.sleep(0.05)
    print(json.dumps({"ready": True}), flush=True)
    for line in sys.stdin:
        words = line.split()
        if words[0] == "cpu":
            kind, n = words[1], int(words[2])
            items = messages[kind]
            start = time.process_time()
            for i in range(n):
                publishers[kind].publish(items[i % len(items)])
            print(json.dumps({"cpu_s": time.process_time() - start}), flush=True)
        elif words[0] == "one":
            started = time.time_ns()
            publishers["description"].publish(messages["description"][0])
            print(json.dumps({"started": started}), flush=True)
        else:
            break
    node.destroy_node()
    rclpy.shutdown()


if __name__ == "__main__":
    main()
