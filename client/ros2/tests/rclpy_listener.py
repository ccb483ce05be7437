"""A real ROS 2 node (rclpy, rmw_fastrtps_cpp from the PyPI wheels) that subscribes to
ghnet-ros2's topics and prints every message it gets as one JSON line, so the Rust
test that starts it can check every field against ghnetd's own answers.

Usage: rclpy_listener.py --imu TOPIC [--imu TOPIC ...] [--diagnostics]
                         [--wait-for TOPIC ...] [--stuck]

Prints `ready` once every topic (or every --wait-for topic) has a publisher, then one
line per message:
{"topic": ..., "received_ns": the callback's wall-clock time, "stamp": [sec, nanosec],
 "frame_id": ..., "orientation": [x, y, z, w],
 "orientation_covariance": [...9], "angular_velocity": [...3],
 "angular_velocity_covariance": [...9], "linear_acceleration": [...3],
 "linear_acceleration_covariance": [...9]}
{"topic": "/diagnostics", "stamp": [...], "status": [{"level", "name", "message",
 "hardware_id", "values": {key: value}}]}
Runs until killed. QoS: reliable, volatile, keep last 1000 (nothing is lost to a
slow Python reader). --stuck: a subscriber that never reads (it never spins after
`ready`), to show it slows nobody.
"""
import argparse
import json
import sys
import time

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Imu


def emit(obj):
    sys.stdout.write(json.dumps(obj) + "\n")
    sys.stdout.flush()


def vec3(v):
    return [v.x, v.y, v.z]


def on_imu(topic):
    def callback(m):
        emit({
            "topic": topic,
            "received_ns": time.time_ns(),
            "stamp": [m.header.stamp.sec, m.header.stamp.nanosec],
            "frame_id": m.header.frame_id,
            "orientation": [m.orientation.x, m.orientation.y, m.orientation.z, m.orientation.w],
            "orientation_covariance": list(m.orientation_covariance),
            "angular_velocity": vec3(m.angular_velocity),
            "angular_velocity_covariance": list(m.angular_velocity_covariance),
            "linear_acceleration": vec3(m.linear_acceleration),
            "linear_acceleration_covariance": list(m.linear_acceleration_covariance),
        })
    return callback


def level(b):
    return b[0] if isinstance(b, (bytes, bytearray)) else int(b)


def on_diagnostics(m):
    emit({
        "topic": "/diagnostics",
        "stamp": [m.header.stamp.sec, m.header.stamp.nanosec],
        "status": [{
            "level": level(s.level),
            "name": s.name,
            "message": s.message,
            "hardware_id": s.hardware_id,
            "values": {kv.key: kv.value for kv in s.values},
        } for s in m.status],
    })


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--imu", action="append", default=[])
    parser.add_argument("--diagnostics", action="store_true")
    parser.add_argument("--wait-for", action="append", default=[])
    parser.add_argument("--stuck", action="store_true")
    args = parser.parse_args()
    rclpy.init()
    node = rclpy.create_node("ghnet_test_listener")
    qos = QoSProfile(reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.VOLATILE,
                     history=HistoryPolicy.KEEP_LAST, depth=1000)
    topics = list(args.imu)
    for t in args.imu:
        node.create_subscription(Imu, t, on_imu(t), qos)
    if args.diagnostics:
        node.create_subscription(DiagnosticArray, "/diagnostics", on_diagnostics, qos)
        topics.append("/diagnostics")
    wait_for = args.wait_for or topics
    while not all(node.count_publishers(t) > 0 for t in wait_for):
        time.sleep(0.05)
    sys.stdout.write("ready\n")
    sys.stdout.flush()
    if args.stuck:
        while True:
            time.sleep(1)
    while rclpy.ok():
        rclpy.spin_once(node, timeout_sec=0.05)


if __name__ == "__main__":
    main()
