//! `kill -9` of the daemon or of a publisher needs no manual cleanup.

use ghnet_client::{HeadingSubscriber, VelocityPublisher};
use ghnet_tests::{wait_until, ChildPublisher, Daemon, Namespace, WATCHDOG};

use crate::TEST_PUBLISHER;

/// Receives until an answer with `seq >= min_seq` arrives; returns its seq.
fn answer_at_least(headings: &HeadingSubscriber, min_seq: u64) -> u64 {
    let t0 = std::time::Instant::now();
    loop {
        assert!(
            t0.elapsed() < WATCHDOG,
            "watchdog: no answer with seq >= {min_seq}"
        );
        if let Some(h) = headings.recv_timeout(WATCHDOG).unwrap() {
            if h.seq >= min_seq {
                return h.seq;
            }
        }
    }
}

#[test]
fn daemon_kill9_while_publishing_then_restart_resumes() {
    let ns = Namespace::new();
    let ipc = ns.ipc();
    let headings = HeadingSubscriber::new(&ipc, "veh").unwrap();
    let mut publisher = ChildPublisher::spawn(TEST_PUBLISHER, &ns, "veh", 0, 200);

    let first = Daemon::start(&ns, &[]);
    let seen = answer_at_least(&headings, 0);
    first.kill9();
    // The publisher keeps publishing into the dead daemon's buffer meanwhile.
    while let Some(h) = headings
        .recv_timeout(std::time::Duration::from_millis(100))
        .unwrap()
    {
        assert!(h.seq >= seen);
    }

    // No cleanup by hand: the new daemon removes the dead one's resources itself.
    let second = Daemon::start(&ns, &[]);
    let resumed = answer_at_least(&headings, seen + 1);
    eprintln!("answered seq {seen} before kill -9, {resumed} after restart");
    // Only the new daemon's heading publisher is left on the service.
    wait_until("dead daemon's publisher cleaned up", || {
        headings.publisher_count() == 1
    });
    answer_at_least(&headings, resumed + 1);
    assert!(publisher.is_running());

    let (status, log) = second.terminate();
    assert!(status.success(), "{status:?}\n{log}");
}

#[test]
fn publisher_kill9_daemon_goes_on_and_a_new_publisher_is_served() {
    let ns = Namespace::new();
    let ipc = ns.ipc();
    let daemon = Daemon::start(&ns, &[]);
    let headings = HeadingSubscriber::new(&ipc, "veh").unwrap();

    let publisher = ChildPublisher::spawn(TEST_PUBLISHER, &ns, "veh", 0, 200);
    answer_at_least(&headings, 0);
    daemon.wait_for_log("source added");
    publisher.kill9();
    daemon.wait_for_log("source removed"); // noticed the dead publisher
    assert!(daemon.is_running(), "ghnetd must survive a dead publisher");

    // Same name, new process: rediscovered and served.
    let _again = ChildPublisher::spawn(TEST_PUBLISHER, &ns, "veh", 1 << 32, 200);
    answer_at_least(&headings, 1 << 32);
    daemon.wait_for_log_count("source added", 2);

    // And an in-process publisher under the same name too (ghnet's slot limits allow
    // a restarted publisher next to its not-yet-cleaned predecessor).
    let gnss = VelocityPublisher::new(&ipc, "veh").unwrap();
    gnss.send(ghnet_client::VelocitySample::new(
        ghnet_tests::now_ns(),
        1 << 40,
        1.0,
        1.0,
        0.0,
    ))
    .unwrap();
    answer_at_least(&headings, 1 << 40);

    assert!(daemon.is_running());
    let (status, log) = daemon.terminate();
    assert!(status.success(), "{status:?}\n{log}");
}
