//! SIGTERM: answer what was received, release everything, exit 0.

use std::time::Duration;

use ghnet_client::{HeadingSubscriber, VelocityPublisher, VelocitySample};
use ghnet_tests::{last_stats_in, now_ns, Daemon, Namespace, WATCHDOG};

#[test]
fn sigterm_answers_what_was_received_and_exits_zero() {
    let ns = Namespace::new();
    let ipc = ns.ipc();
    let daemon = Daemon::start(&ns, &["--source", "term", "--discovery", "false"]);
    let headings = HeadingSubscriber::new(&ipc, "term").unwrap();
    let gnss = VelocityPublisher::new(&ipc, "term").unwrap();
    daemon.wait_serving(&gnss);

    // One round trip first. It also connects our subscriber to the daemon's heading
    // publisher: iceoryx2 connects a subscriber on `receive`, and answers of a
    // publisher that is gone before a subscriber's first `receive` never reach it.
    gnss.send(VelocitySample::new(now_ns(), 0, 1.0, 2.0, 0.0))
        .unwrap();
    assert_eq!(
        headings
            .recv_timeout(WATCHDOG)
            .unwrap()
            .expect("answer")
            .seq,
        0
    );

    // A burst (below the 128-sample buffers), then SIGTERM at once: whatever the
    // daemon has not answered yet is in its buffer and must be answered on the way out.
    let n = 101u64;
    for seq in 1..n {
        let s = VelocitySample::new(now_ns(), seq, 1.0, 2.0, 0.0);
        gnss.publish(s).unwrap();
    }
    gnss.notify().unwrap();
    let (status, log) = daemon.terminate();
    assert_eq!(status.code(), Some(0), "{status:?}\n{log}");
    assert!(log.contains("ghnetd stopped"), "{log}");
    let stats = last_stats_in(&log, "term").expect("final stats line");
    assert_eq!((stats["received"], stats["answered"]), (n, n), "{log}");

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
    let ns = Namespace::new();
    let ipc = ns.ipc();
    let daemon = Daemon::start(&ns, &[]);
    let gnss = VelocityPublisher::new(&ipc, "idle").unwrap();
    daemon.wait_serving(&gnss);
    let (status, log) = daemon.terminate();
    assert_eq!(status.code(), Some(0), "{status:?}\n{log}");
    assert_eq!(gnss.subscriber_count(), 0, "ports released on exit");
}
