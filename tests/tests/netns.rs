//! Two "hosts" on one machine: ghnetd in one network namespace, a Zenoh subscriber in
//! another, joined by a veth pair. Every heading must cross.
//!
//! Needs root and `ip` (iproute2): ignored unless asked for (`--include-ignored`, as
//! `.ci/run` does). The namespaces and the veth pair are the kit's ([`NetNamespace`]:
//! unique names, deleted on drop), addresses are a /30 of TEST-NET-1 (192.0.2.0/24) that exists only inside
//! them, and everything is deleted on drop. iceoryx2 is untouched by network
//! namespaces (same `/dev/shm`), so this test publishes velocity from its own process.

use ghnet_client::{encode_zenoh, HeadingSubscriber, VelocityPublisher, VelocitySample};
use ghnet_testkit::{
    now_ns, ChildSubscriber, Ghnetd, Listen, NetNamespace, TestNamespace, WATCHDOG,
};

const DAEMON_ADDR: &str = "192.0.2.1";
const CONSUMER_ADDR: &str = "192.0.2.2";

#[test]
#[ignore = "needs root and ip"]
fn every_heading_crosses_to_another_network_namespace() {
    let ns = TestNamespace::new("netns");
    let daemon_host = NetNamespace::create("daemon").expect("network namespace");
    let consumer_host = NetNamespace::create("consumer").expect("network namespace");
    (daemon_host.link(
        &format!("{DAEMON_ADDR}/30"),
        &consumer_host,
        &format!("{CONSUMER_ADDR}/30"),
    ))
    .expect("veth pair");
    // The daemon's namespace is fresh: any port is free there.
    let endpoint = format!("tcp/{DAEMON_ADDR}:7447");
    // Spawned, not started: the kit's own session cannot reach the address.
    let daemon = (Ghnetd::builder(&ns).source("nn").discovery(false))
        .listen(Listen::Endpoint(endpoint.clone()))
        .wrapper(&daemon_host.exec())
        .spawn();
    let ipc = daemon.ipc().clone();

    // The consumer, in the other namespace; ready once ghnetd knows its subscription.
    let consumer = ChildSubscriber::zenoh(&consumer_host.exec(), &endpoint, ipc.prefix(), "nn");

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
