//! Two "hosts" on one machine: ghnetd in one network namespace, a Zenoh subscriber in
//! another, joined by a veth pair. Every heading must cross.
//!
//! Needs root and `ip` (iproute2): ignored unless asked for (`--include-ignored`, as
//! `.ci/run` does). The namespaces and the veth pair are created by the test (unique
//! names), addresses are a /30 of TEST-NET-1 (192.0.2.0/24) that exists only inside
//! them, and everything is deleted on drop. iceoryx2 is untouched by network
//! namespaces (same `/dev/shm`), so this test publishes velocity from its own process.

use std::process::Command;

use ghnet_client::{encode_zenoh, HeadingSubscriber, VelocityPublisher, VelocitySample};
use ghnet_testkit::{now_ns, ChildSubscriber, Ghnetd, Listen, TestNamespace, WATCHDOG};

const DAEMON_ADDR: &str = "192.0.2.1";
const CONSUMER_ADDR: &str = "192.0.2.2";

/// Two network namespaces joined by a veth pair; deleted on drop.
struct Hosts {
    daemon: String,
    consumer: String,
}

fn ip(args: &[&str]) -> Result<(), String> {
    let out = Command::new("ip")
        .args(args)
        .output()
        .map_err(|e| format!("ip: {e}"))?;
    if out.status.success() {
        Ok(())
    } else {
        Err(format!(
            "ip {}: {}",
            args.join(" "),
            String::from_utf8_lossy(&out.stderr).trim()
        ))
    }
}

impl Hosts {
    fn create(tag: &str) -> Result<Self, String> {
        let hosts = Self {
            daemon: format!("ghn{tag}d"),
            consumer: format!("ghn{tag}c"),
        };
        let (va, vb) = (format!("ghv{tag}a"), format!("ghv{tag}b"));
        ip(&["netns", "add", &hosts.daemon])?;
        ip(&["netns", "add", &hosts.consumer])?;
        ip(&["link", "add", &va, "type", "veth", "peer", "name", &vb])?;
        ip(&["link", "set", &va, "netns", &hosts.daemon])?;
        ip(&["link", "set", &vb, "netns", &hosts.consumer])?;
        for (ns, dev, addr) in [
            (&hosts.daemon, &va, DAEMON_ADDR),
            (&hosts.consumer, &vb, CONSUMER_ADDR),
        ] {
            ip(&["-n", ns, "addr", "add", &format!("{addr}/30"), "dev", dev])?;
            ip(&["-n", ns, "link", "set", dev, "up"])?;
            ip(&["-n", ns, "link", "set", "lo", "up"])?;
        }
        Ok(hosts)
    }
}

impl Drop for Hosts {
    fn drop(&mut self) {
        // Deleting a namespace deletes its end of the veth pair, and with it the peer.
        let _ = ip(&["netns", "del", &self.daemon]);
        let _ = ip(&["netns", "del", &self.consumer]);
    }
}

#[test]
#[ignore = "needs root and ip"]
fn every_heading_crosses_to_another_network_namespace() {
    let ns = TestNamespace::new("netns");
    // Interface names are at most 15 bytes: "ghv" + 6 + 3 + "a".
    let tag = format!("{:x}{}", std::process::id() % 0xff_ffff, rand_suffix());
    let hosts = Hosts::create(&tag).unwrap_or_else(|e| panic!("network namespaces: {e}"));
    // The daemon's namespace is fresh: any port is free there.
    let endpoint = format!("tcp/{DAEMON_ADDR}:7447");
    // Spawned, not started: the kit's own session cannot reach the address.
    let daemon = (Ghnetd::builder(&ns).source("nn").discovery(false))
        .listen(Listen::Endpoint(endpoint.clone()))
        .wrapper(&["ip", "netns", "exec", &hosts.daemon])
        .spawn();
    let ipc = daemon.ipc().clone();

    // The consumer, in the other namespace; ready once ghnetd knows its subscription.
    let wrapper = ["ip", "netns", "exec", hosts.consumer.as_str()];
    let consumer = ChildSubscriber::zenoh(&wrapper, &endpoint, ipc.prefix(), "nn");

    let ice = HeadingSubscriber::new(&ipc, "nn").unwrap();
    let gnss = VelocityPublisher::new(&ipc, "nn").unwrap();
    daemon.wait_serving(&gnss);
    let n = 200u64;
    let mut sent = Vec::new();
    let t0 = now_ns();
    for i in 0..n {
        gnss.send(VelocitySample::new(t0 + i, i, 2.0, i as f32 * 0.05, 0.0))
            .unwrap();
        let h = ice
            .recv_timeout(WATCHDOG)
            .unwrap()
            .expect("iceoryx2 answer");
        let hex: String = encode_zenoh(&h)
            .iter()
            .map(|b| format!("{b:02x}"))
            .collect();
        sent.push((h.seq, hex));
    }
    let mut received: Vec<(u64, String)> = (0..n)
        .map(|_| consumer.next().expect("a heading in the other namespace"))
        .map(|h| (h.seq, h.hex))
        .collect();
    received.sort();
    assert_eq!(received, sent, "every heading crosses, byte for byte");
    daemon.stop();
}

fn rand_suffix() -> String {
    use std::hash::{BuildHasher, Hasher};
    let r = std::collections::hash_map::RandomState::new()
        .build_hasher()
        .finish();
    format!("{:x}", r & 0xfff)
}
