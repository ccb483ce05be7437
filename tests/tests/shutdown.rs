//! SIGTERM: answer what was received, release everything, exit 0.

use std::time::Duration;

use ghnet_client::{VelocityPublisher, VelocitySample};
use ghnet_testkit::{assert_silent, now_ns, Ghnetd, OneSource, TestNamespace, WATCHDOG};

#[test]
fn sigterm_answers_what_was_received_and_exits_zero() {
    let one = OneSource::start("term", |b| b);

    // One round trip first. It also connects our subscriber to the daemon's heading
    // publisher: iceoryx2 connects a subscriber on `receive`, and answers of a
    // publisher that is gone before a subscriber's first `receive` never reach it.
    one.gnss
        .send(VelocitySample::new(now_ns(), 0, 1.0, 2.0, 0.0))
        .unwrap();
    let first = one
        .headings
        .recv_timeout(WATCHDOG)
        .unwrap()
        .expect("answer");
    assert_eq!(first.seq, 0);

    // A burst (below the 128-sample buffers), then SIGTERM at once: whatever the
    // daemon has not answered yet is in its buffer and must be answered on the way out.
    let n = 101u64;
    for seq in 1..n {
        let s = VelocitySample::new(now_ns(), seq, 1.0, 2.0, 0.0);
        one.gnss.publish(s).unwrap();
    }
    one.gnss.notify().unwrap();
    let log = one.daemon.stop();
    assert!(log.contains("ghnetd stopped"), "{log}");

    // Every answer reached us exactly once, also after the daemon is gone.
    for seq in 1..n {
        let h = one
            .headings
            .recv_timeout(WATCHDOG)
            .unwrap()
            .unwrap_or_else(|| panic!("answer {seq} of {n} missing after shutdown\n{log}"));
        assert_eq!(h.seq, seq);
    }
    assert_silent(&one.headings, Duration::from_millis(100));
    // The daemon released its ports: no subscriber left on the velocity service.
    assert_eq!(one.gnss.subscriber_count(), 0);
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
