//! `kill -9` of the daemon or of a publisher needs no manual cleanup: the dead
//! process's iceoryx2 node and shared memory are reclaimed, the survivors go on.

use std::collections::BTreeSet;

use ghnet_client::{HeadingStatus, HeadingSubscriber, VelocityPublisher};
use ghnet_testkit::{
    list_nodes, now_ns, recv_answer, wait_until, ChildPublisher, Ghnetd, TestNamespace, WATCHDOG,
};

/// Receives until an answer (not a `Stale` message) with `seq >= min_seq` arrives;
/// returns its seq.
fn answer_at_least(headings: &HeadingSubscriber, min_seq: u64) -> u64 {
    let t0 = std::time::Instant::now();
    loop {
        assert!(
            t0.elapsed() < WATCHDOG,
            "watchdog: no answer with seq >= {min_seq}"
        );
        if let Some(h) = recv_answer(headings, WATCHDOG) {
            if h.seq >= min_seq {
                return h.seq;
            }
        }
    }
}

/// Names of the namespace's files in `/dev/shm`.
fn shm_files(ns: &TestNamespace) -> BTreeSet<String> {
    std::fs::read_dir("/dev/shm")
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with(ns.global_prefix()))
        .collect()
}

#[test]
fn daemon_kill9_while_publishing_then_restart_resumes() {
    let ns = TestNamespace::new("kill9");
    let ipc = ns.ipc();
    let headings = HeadingSubscriber::new(&ipc, "veh").unwrap();
    let publisher = ChildPublisher::spawn(&ns, "veh", 0, 200);

    let first = Ghnetd::builder(&ns).start();
    let seen = answer_at_least(&headings, 0);
    let (alive, _) = list_nodes(&ns);
    let daemon_node = alive
        .iter()
        .find(|n| n.ends_with(" ghnetd"))
        .unwrap_or_else(|| panic!("no ghnetd node in {alive:?}"))
        .clone();
    let shm_before = shm_files(&ns);
    first.kill9();
    let (_, dead) = list_nodes(&ns);
    assert_eq!(
        dead,
        vec![daemon_node.clone()],
        "the killed daemon is a dead node"
    );
    // The publisher keeps publishing into the dead daemon's buffer meanwhile.
    while let Some(h) = headings
        .recv_timeout(std::time::Duration::from_millis(100))
        .unwrap()
    {
        assert!(h.seq >= seen);
    }

    // No cleanup by hand: the new daemon removes the dead one's resources itself.
    let second = Ghnetd::builder(&ns).start();
    let resumed = answer_at_least(&headings, seen + 1);
    eprintln!("answered seq {seen} before kill -9, {resumed} after restart");
    // Only the new daemon's heading publisher is left on the service, the dead node
    // is gone from the node list, and so is its shared memory.
    wait_until("dead daemon's publisher cleaned up", || {
        headings.publisher_count() == 1
    });
    let (alive, dead) = list_nodes(&ns);
    assert!(dead.is_empty(), "dead nodes left: {dead:?}");
    assert!(!alive.contains(&daemon_node), "{alive:?}");
    let shm_after = shm_files(&ns);
    let leftover: Vec<_> = shm_before
        .iter()
        .filter(|f| f.contains("_publisher_data") || f.contains("_node"))
        .filter(|f| shm_after.contains(*f))
        .collect();
    eprintln!(
        "/dev/shm files of the namespace: {} before kill -9, {} after restart; of the dead daemon's data segments left: {leftover:?}",
        shm_before.len(),
        shm_after.len()
    );
    answer_at_least(&headings, resumed + 1);
    assert!(publisher.is_running());
    second.stop();
}

#[test]
fn publisher_kill9_daemon_goes_on_and_a_new_publisher_is_served() {
    let ns = TestNamespace::new("pubkill9");
    let ipc = ns.ipc();
    let daemon = Ghnetd::builder(&ns).start();
    let headings = HeadingSubscriber::new(&ipc, "veh").unwrap();
    let other_headings = HeadingSubscriber::new(&ipc, "other").unwrap();
    let _other = ChildPublisher::spawn(&ns, "other", 0, 100);

    let publisher = ChildPublisher::spawn(&ns, "veh", 0, 200);
    let last_before = answer_at_least(&headings, 0);
    daemon.wait_for_log("source added");
    publisher.kill9();
    // The other source is served all along.
    let mut other_seq = answer_at_least(&other_headings, 0);
    // Consumers of the dead source learn it: one Stale message with the last
    // sequence number answered, then the source is dropped.
    let stale = loop {
        let h = headings.recv_timeout(WATCHDOG).unwrap().expect("Stale");
        if h.heading_status() == Some(HeadingStatus::Stale) {
            break h;
        }
        assert!(h.seq >= last_before);
    };
    daemon.wait_for_log("source removed"); // noticed the dead publisher
    assert!(daemon.is_running(), "ghnetd must survive a dead publisher");
    other_seq = answer_at_least(&other_headings, other_seq + 1);
    eprintln!("Stale for veh at seq {}; other at {other_seq}", stale.seq);

    // Same name, new process: rediscovered and served.
    let _again = ChildPublisher::spawn(&ns, "veh", 1 << 32, 200);
    answer_at_least(&headings, 1 << 32);
    daemon.wait_for_log_count("source added", 2);

    // And an in-process publisher under the same name too (ghnet's slot limits allow
    // a restarted publisher next to its not-yet-cleaned predecessor).
    let gnss = VelocityPublisher::new(&ipc, "veh").unwrap();
    gnss.send(ghnet_client::VelocitySample::new(
        now_ns(),
        1 << 40,
        1.0,
        1.0,
        0.0,
    ))
    .unwrap();
    answer_at_least(&headings, 1 << 40);
    daemon.stop();
}
