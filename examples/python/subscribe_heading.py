#!/usr/bin/env python3
"""subscribe_heading.py: prints the headings ghnetd publishes on Zenoh.

Teaches: no ghnet library is needed to read headings over Zenoh: connect to ghnetd's
loopback listener (`eclipse-zenoh==1.10.2`), subscribe to `<prefix>/<source>/heading`
and unpack the documented 64-byte little-endian layout with `struct`.

Run (with ghnetd and a publisher running):
    python3 -m pip install eclipse-zenoh==1.10.2
    python3 examples/python/subscribe_heading.py --source pygnss --count 50
"""

import argparse
import json
import queue
import time

import zenoh

from ghnet_wire import STATUS, decode_heading, loopback_config


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--prefix", default="ghnet")
    p.add_argument("--source", default="gnss0")
    p.add_argument("--connect", default="tcp/127.0.0.1:7447", help="ghnetd's zenoh.listen")
    p.add_argument("--count", type=int, default=0, help="stop after N headings; 0 = never")
    p.add_argument("--timeout", type=float, default=60.0, help="give up after S s of silence")
    p.add_argument("--json", action="store_true", help="one JSON object per heading")
    args = p.parse_args()

    # Loopback only: connect to ghnetd, listen nowhere, no multicast or gossip.
    conf = loopback_config(zenoh, args.connect)

    headings: "queue.Queue[bytes]" = queue.Queue()
    key = f"{args.prefix}/{args.source}/heading"
    with zenoh.open(conf) as session:
        sub = session.declare_subscriber(key, lambda s: headings.put(s.payload.to_bytes()))
        # Barrier: ask ghnetd for its model. The query travels after the subscriber
        # declaration on the same link, so once ghnetd answers, it knows about us and
        # no heading is missed from here on. (Retried while the connection comes up.)
        model = None
        for _ in range(int(args.timeout * 10)):
            for reply in session.get(f"{args.prefix}/@ghnetd/model", timeout=1.0):
                if reply.ok is not None:
                    model = json.loads(reply.ok.payload.to_bytes())
            if model is not None:
                break
            time.sleep(0.1)
        if model is None:
            raise SystemExit(f"ghnetd at {args.connect} does not answer")
        print(f"subscribed to {key} (ghnetd model {model.get('name')})", flush=True)
        n = 0
        while args.count == 0 or n < args.count:
            try:
                payload = headings.get(timeout=args.timeout)
            except queue.Empty:
                raise SystemExit(f"no heading for {args.timeout} s")
            try:
                h = decode_heading(payload)
            except ValueError as e:
                print(f"skipping: {e}", flush=True)
                continue
            n += 1
            if args.json:
                # NaN is not JSON: null. Finite floats print exactly (shortest repr
                # that round-trips), so a reader can compare values bit for bit.
                h = {k: (None if isinstance(v, float) and v != v else v) for k, v in h.items()}
                h["payload_hex"] = payload.hex()
                print(json.dumps(h), flush=True)
            else:
                print(f"seq={h['seq']} heading={h['heading_deg']:.2f}±{h['heading_std_deg']:.2f}° "
                      f"speed={h['speed']:.2f} m/s {STATUS.get(h['status'], h['status'])} "
                      f"model={h['model_name']}", flush=True)
        sub.undeclare()


if __name__ == "__main__":
    main()
