"""An independent reader of ghnet-ros2's rmw_zenoh output: eclipse-zenoh 1.10.2 for the
transport, rosbags for the ROS side (its typestore computes the RIHS01 type hashes
from the message definitions and decodes CDR), so the Rust test that starts it checks
keys, payloads and attachments against code that shares nothing with the bridge.

Usage: zenoh_rosbags.py ROUTER DOMAIN

Prints `ready` once subscribed, then one JSON line per sample:
{"key": ..., "attachment": hex, "rihs01": the hash rosbags computes for the type
 named in the key, "cdr_header": the payload's first 4 bytes, "same_bytes": whether
 rosbags encodes the decoded message to the very payload, "msg": the decoded message
 (Imu fields as rclpy_listener.py prints them, or a DiagnosticArray)}
and on a line `tokens` on stdin, one line {"tokens": [...]} with every liveliness token
under @ros2_lv/DOMAIN. Exits when stdin closes.
"""
import json
import pathlib
import sys
import threading

import zenoh
from rosbags.typesys import Stores, get_typestore

# The examples' Zenoh config (no multicast, no listening): the Python client's, not
# the bridge's.
sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[3] / "examples" / "python"))
from ghnet_wire import loopback_config  # noqa: E402

STORE = get_typestore(Stores.ROS2_JAZZY)


def vec3(v):
    return [v.x, v.y, v.z]


def as_json(msgtype, m):
    if msgtype == "sensor_msgs/msg/Imu":
        o = m.orientation
        return {
            "stamp": [m.header.stamp.sec, m.header.stamp.nanosec],
            "frame_id": m.header.frame_id,
            "orientation": [o.x, o.y, o.z, o.w],
            "orientation_covariance": [float(x) for x in m.orientation_covariance],
            "angular_velocity": vec3(m.angular_velocity),
            "angular_velocity_covariance": [float(x) for x in m.angular_velocity_covariance],
            "linear_acceleration": vec3(m.linear_acceleration),
            "linear_acceleration_covariance": [float(x) for x in m.linear_acceleration_covariance],
        }
    return {
        "stamp": [m.header.stamp.sec, m.header.stamp.nanosec],
        "status": [{
            "level": int(s.level),
            "name": s.name,
            "hardware_id": s.hardware_id,
            "values": {kv.key: kv.value for kv in s.values},
        } for s in m.status],
    }


def msgtype_of(dds_name):
    # sensor_msgs::msg::dds_::Imu_ -> sensor_msgs/msg/Imu
    pkg, kind, _, name = dds_name.split("::")
    return f"{pkg}/{kind}/{name[:-1]}"


def main():
    router, domain = sys.argv[1], sys.argv[2]
    # A client of the router, as the bridge: a router routes to its clients.
    conf = loopback_config(zenoh, router, mode="client")
    lock = threading.Lock()

    def emit(obj):
        with lock:
            sys.stdout.write(json.dumps(obj) + "\n")
            sys.stdout.flush()

    def on_sample(s):
        key = str(s.key_expr)
        parts = key.split("/")
        msgtype = msgtype_of(parts[-2])
        payload = s.payload.to_bytes()
        m = STORE.deserialize_cdr(payload, msgtype)
        att = s.attachment.to_bytes() if s.attachment is not None else b""
        emit({
            "key": key,
            "attachment": att.hex(),
            "rihs01": STORE.hash_rihs01(msgtype),
            "cdr_header": payload[:4].hex(),
            # rosbags' own encoding of what it decoded: the same bytes, or the
            # payload is not what a ROS 2 node would write.
            "same_bytes": bytes(STORE.serialize_cdr(m, msgtype)) == payload,
            "msg": as_json(msgtype, m),
        })

    with zenoh.open(conf) as session:
        session.declare_subscriber(f"{domain}/**", on_sample)
        print("ready", flush=True)
        for line in sys.stdin:
            if line.strip() == "tokens":
                replies = session.liveliness().get(f"@ros2_lv/{domain}/**", timeout=5.0)
                tokens = [str(r.ok.key_expr) for r in replies if r.ok is not None]
                emit({"tokens": tokens})


if __name__ == "__main__":
    main()
