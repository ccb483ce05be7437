//! SIGTERM: answer what was received, release everything, exit 0.

use std::time::Duration;

use ghnet_client::{VelocityPublisher, VelocitySample};
use ghnet_testkit::{now_ns, Ghnetd, OneSource, TestNamespace, WATCHDOG};

#[test]
fn sigterm_answers_what_was_received_and_exits_zero() {
    let OneSource {
        ns: _ns,
        daemon,
        headings,
        gnss,
    } = OneSource::start("term", |b| b);

    // One round trip first. It also connects our subscriber to the daemon's heading
    // publisher: iceoryx2 connects a subscriber on `receive`, and answers of a
    // publisher that is gone before a subscriber's first `receive` never reach it.
    gnss.send(VelocitySample::new(now_ns(), 0, 1.0, 2.0, 0.0))
        .unwrap();
    let first = headings.recv_timeout(WATCHDOG).unwrap().expect("answer");
    assert_eq!(first.seq, 0);

    // A burst (below the 128-sample buffers), then SIGTERM at once: whatever the
    // daemon has not answered yet is in its buffer and must be answered on the way out.
    let n = 101u64;
    for seq in 1..n {
        let s = VelocitySample::new(now_ns(), seq, 1.0, 2.0, 0.0);
        gnss.publish(s).unwrap();
    }
    gnss.notify().unwrap();
    let log = daemon.stop();
    assert!(log.contains("ghnetd stopped"), "{log}");

    // Every answer reached us exactly once, also after the daemon is gone.
    for seq in 1..n {
        let h = headings
            .recv_timeout(WATCHDOG)
            .unwrap()
            .unwrap_or_else(|| panic!("answer {seq} of {n} missing after shutdown\n{log}"));
        assert_eq!(h.seq, seq);
    }
    assert!(headings
        .recv_timeout(Duration::from_millis(100))
        .unwrap()
        .is_none());
    // The daemon released its ports: no subscriber left on the velocity service.
    assert_eq!(gnss.subscriber_count(), 0);
}

#[test]
fn sigterm_when_idle_with_discovered_sources_exits_zero() {
    let ns = TestNamespace::new("idle");
    let daemon = Ghnetd::builder(&ns).start();
    let gnss = VelocityPublisher::new(&ns.ipc(), "idle").unwrap();
    daemon.wait_serving(&gnss);
    daemon.stop();
    assert_eq!(gnss.subscriber_count(), 0, "ports released on exit");
}
