#!/usr/bin/env python3
"""publish_velocity.py: sends VelocitySamples to ghnetd over iceoryx2 shared memory.

Teaches: the Python binding `iceoryx2==0.10.0` talks to the Rust 0.10.0 services when
the ctypes Structure has the same fields and `type_name()` returns the Rust type name;
create services with ghnet's settings; notify the paired event service after sending
(ghnetd sleeps on it).

Run (with ghnetd running):
    python3 -m pip install iceoryx2==0.10.0
    python3 examples/python/publish_velocity.py --source pygnss --count 50
"""

import argparse
import math
import time

import iceoryx2 as iox2

from ghnet_wire import VelocitySample, open_services


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--prefix", default="ghnet", help="ghnetd's ipc.service_prefix")
    p.add_argument("--source", default="gnss0")
    p.add_argument("--count", type=int, default=100, help="samples to send")
    p.add_argument("--rate", type=float, default=10.0, help="samples per second")
    p.add_argument("--first-seq", type=int, default=0)
    p.add_argument("--iceoryx2-global-prefix", help="isolated iceoryx2 instance (tests)")
    p.add_argument("--iceoryx2-root-path", help="isolated iceoryx2 instance (tests)")
    args = p.parse_args()

    config = iox2.config.default()
    if args.iceoryx2_global_prefix:
        config.global_cfg.prefix = iox2.FileName.new(args.iceoryx2_global_prefix)
    if args.iceoryx2_root_path:
        root = args.iceoryx2_root_path.rstrip("/") + "/"
        config.global_cfg.root_path = iox2.Path.new(root)
    node = iox2.NodeBuilder.new().config(config).create(iox2.ServiceType.Ipc)

    # ghnet's service settings: another party opening with other limits would fail.
    service, event = open_services(iox2, node, f"{args.prefix}/{args.source}/velocity",
                                   VelocitySample)
    publisher = service.publisher_builder().create()
    notifier = event.notifier_builder().create()

    # No history: wait until ghnetd subscribed, or the first samples go nowhere.
    deadline = time.monotonic() + 30
    while service.dynamic_config.number_of_subscribers == 0:
        if time.monotonic() > deadline:
            raise SystemExit("no subscriber on the velocity service after 30 s: is ghnetd running?")
        time.sleep(0.01)

    for i in range(args.count):
        angle = 2 * math.pi * i / 40  # a circle, 5 m/s
        sample = VelocitySample(timestamp_ns=time.time_ns(), seq=args.first_seq + i,
                                v_north=5 * math.cos(angle), v_east=5 * math.sin(angle),
                                v_down=0.0, speed_accuracy=math.nan, flags=0)
        publisher.loan_uninit().write_payload(sample).send()
        notifier.notify()
        print(f"sent seq={sample.seq} v_north={sample.v_north:.6f} v_east={sample.v_east:.6f}",
              flush=True)
        time.sleep(1.0 / args.rate)


if __name__ == "__main__":
    main()
