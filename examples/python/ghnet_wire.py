"""The ghnet wire for Python: the iceoryx2 payload types and the Zenoh heading layout.

Mirrors client/README.md (tables "VelocitySample", "HeadingEstimate", "Zenoh payload").
The Zenoh payload is 64 bytes, fields concatenated little-endian, no padding, no
length prefixes: one `struct.unpack`.
"""

import ctypes
import json
import struct

# iceoryx2 service settings every party must use (client/src/settings.rs): settings of
# an existing service are minimums, so a client creating the service with smaller
# limits would make ghnetd's open fail.
MAX_PUBLISHERS, MAX_SUBSCRIBERS, MAX_NODES, SUBSCRIBER_BUFFER = 4, 8, 16, 128


def open_services(iox2, node, name: str, payload):
    """Opens (or creates) the publish-subscribe service `name` for `payload` and its
    paired event service, both with ghnet's settings. Returns (pubsub, event)."""
    service_name = iox2.ServiceName.new(name)
    pubsub = (node.service_builder(service_name).publish_subscribe(payload)
              .max_publishers(MAX_PUBLISHERS).max_subscribers(MAX_SUBSCRIBERS)
              .max_nodes(MAX_NODES).subscriber_max_buffer_size(SUBSCRIBER_BUFFER)
              .history_size(0).enable_safe_overflow(True).open_or_create())
    event = (node.service_builder(service_name).event().max_notifiers(MAX_PUBLISHERS)
             .max_listeners(MAX_SUBSCRIBERS).max_nodes(MAX_NODES).open_or_create())
    return pubsub, event


def loopback_config(zenoh, connect: str, mode: str = "peer"):
    """A Zenoh config like ghnet's `peer_config`: a peer (or a `mode="client"` of a
    router) that connects to `connect` (ghnetd's zenoh.listen, or the router), listens
    nowhere, no multicast scouting, no gossip. Zenoh's defaults would listen on every
    interface and announce themselves by multicast."""
    conf = zenoh.Config()
    conf.insert_json5("mode", json.dumps(mode))
    conf.insert_json5("connect/endpoints", json.dumps([connect]))
    conf.insert_json5("listen/endpoints", "[]")
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("scouting/gossip/enabled", "false")
    return conf


class VelocitySample(ctypes.Structure):
    """40 bytes, alignment 8; the Rust `ghnet_client::VelocitySample`."""

    _fields_ = [("timestamp_ns", ctypes.c_uint64), ("seq", ctypes.c_uint64),
                ("v_north", ctypes.c_float), ("v_east", ctypes.c_float),
                ("v_down", ctypes.c_float), ("speed_accuracy", ctypes.c_float),
                ("flags", ctypes.c_uint32), ("_reserved", ctypes.c_uint32)]

    @staticmethod
    def type_name() -> str:
        # Must equal the Rust #[type_name]; otherwise iceoryx2 says IncompatibleTypes.
        return "ghnet::VelocitySample"


assert ctypes.sizeof(VelocitySample) == 40 and ctypes.alignment(VelocitySample) == 8

# Zenoh heading payload: <Q Q Q f f f f I I 16s>, little-endian, 64 bytes.
HEADING = struct.Struct("<QQQffffII16s")
HEADING_FIELDS = ("timestamp_ns", "seq", "processing_ns", "heading_deg",
                  "heading_std_deg", "atan2_deg", "speed", "model_id", "status",
                  "model_name")
STATUS = {0: "Ok", 1: "LowSpeed", 2: "Stationary", 3: "InvalidInput", 4: "Stale", 5: "Held"}
assert HEADING.size == 64


def decode_heading(payload: bytes) -> dict:
    """Decodes one Zenoh heading payload; raises ValueError on any other length."""
    if len(payload) != HEADING.size:
        raise ValueError(f"heading payload must be 64 bytes, got {len(payload)}")
    h = dict(zip(HEADING_FIELDS, HEADING.unpack(payload)))
    h["model_name"] = h["model_name"].split(b"\0", 1)[0].decode("ascii", "replace")
    return h
