//! Faults: crashed and stuck subscribers, silent sources (`Stale`), a second
//! ghnetd on the same prefix, full services, and owner-only permissions. Real ghnetd
//! processes, real child processes, real shared memory.

use std::os::unix::fs::PermissionsExt;
use std::path::{Path, PathBuf};
use std::time::Duration;

use ghnet_client::{
    HeadingStatus, HeadingSubscriber, OpenError, ServiceSettings, VelocityPublisher,
    VelocitySubscriber, SERVICE_SETTINGS,
};
use ghnet_testkit::{
    assert_silent, list_nodes, moving_sample, recv_answer, round_trip, wait_until, ChildSubscriber,
    Ghnetd, TestNamespace, WATCHDOG,
};

#[test]
fn subscriber_kill9_daemon_goes_on_and_a_new_subscriber_is_served() {
    let ns = TestNamespace::new("subkill9");
    let daemon = Ghnetd::builder(&ns).start();
    let (veh, veh_headings) = daemon.ends("veh");
    let (other, other_headings) = daemon.ends("other");

    let child = ChildSubscriber::spawn(&ns, "veh");
    let mut seq = 0;
    // Until the child has seen a heading: it is connected and reading.
    loop {
        round_trip(&veh, &veh_headings, seq);
        round_trip(&other, &other_headings, seq);
        seq += 1;
        if seq > 3 {
            break;
        }
    }
    child.answer_at_least(0);
    let (alive_before, _) = list_nodes(&ns);

    // Mid-stream: samples keep coming while the subscriber dies.
    child.kill9();
    for _ in 0..50 {
        round_trip(&veh, &veh_headings, seq);
        round_trip(&other, &other_headings, seq);
        seq += 1;
    }
    daemon.assert_running();
    // ghnetd's housekeeping removes the dead process's node and its port.
    wait_until("the dead subscriber's node cleaned up", || {
        let (alive, dead) = list_nodes(&ns);
        dead.is_empty() && alive.len() + 1 == alive_before.len()
    });

    // A new subscriber process under the same name gets headings again.
    let again = ChildSubscriber::spawn(&ns, "veh");
    let first_new = seq;
    for _ in 0..5 {
        round_trip(&veh, &veh_headings, seq);
        seq += 1;
    }
    assert!(again.answer_at_least(first_new) >= first_new);
    drop(again);

    let stats = daemon.wait_for_counters("veh", |s| s["received"] == seq);
    assert_eq!(stats["send_errors"], 0, "{stats:?}");
    assert_eq!(stats["answered"], stats["received"], "{stats:?}");
    daemon.stop();
}

#[test]
fn a_stuck_subscriber_slows_nobody_and_its_losses_are_counted() {
    let ns = TestNamespace::new("stuck");
    let daemon = Ghnetd::builder(&ns).start();
    let stuck = HeadingSubscriber::new(daemon.ipc(), "veh").unwrap();
    let (veh, reader) = daemon.ends("veh");
    let (other, other_reader) = daemon.ends("other");

    // The stuck subscriber reads the first heading, then stops reading.
    round_trip(&veh, &reader, 0);
    assert_eq!(recv_answer(&stuck, WATCHDOG).expect("first heading").seq, 0);

    // Far more than its buffer holds; the other subscribers still get every heading,
    // in order, once.
    let n: u64 = 4 * SERVICE_SETTINGS.subscriber_buffer_size as u64;
    for seq in 1..n {
        round_trip(&veh, &reader, seq);
        round_trip(&other, &other_reader, seq);
    }
    assert_eq!((reader.missed(), other_reader.missed()), (0, 0));

    // The stuck one finally reads: the newest `subscriber_buffer_size` headings, and
    // the overwritten ones show up as `missed`.
    let mut got = 1;
    let mut last = 0;
    while let Some(h) = recv_answer(&stuck, Duration::from_millis(200)) {
        assert!(h.seq > last, "in order: {} after {last}", h.seq);
        last = h.seq;
        got += 1;
    }
    let missed = stuck.missed();
    eprintln!(
        "stuck subscriber: {got} of {n} headings received, {missed} missed (buffer {})",
        SERVICE_SETTINGS.subscriber_buffer_size
    );
    assert_eq!(last, n - 1, "the newest heading is kept");
    assert_eq!(got + missed, n, "every heading either received or counted");
    assert!(got <= 1 + SERVICE_SETTINGS.subscriber_buffer_size as u64);
    assert!(missed >= n - 1 - SERVICE_SETTINGS.subscriber_buffer_size as u64);

    let stats = daemon.wait_for_counters("veh", |s| s["answered"] >= n);
    assert_eq!((stats["received"], stats["send_errors"]), (n, 0));
}

#[test]
fn a_silent_source_gets_one_stale_message_and_is_served_again() {
    let ns = TestNamespace::new("stale");
    let ipc = ns.ipc();
    let daemon = Ghnetd::builder(&ns).arg("--stale-after-ms=300").start();
    let session = daemon.connect();
    let zen = ghnet_client::ZenohHeadingSubscriber::new(&session, &ipc, "veh").unwrap();
    ghnet_testkit::zenoh_barrier(&session, &ipc);
    let (gnss, headings) = daemon.ends("veh");

    let mut last_sent = moving_sample(0);
    for seq in 0..3 {
        last_sent = moving_sample(seq);
        gnss.send(last_sent).unwrap();
        let h = headings.recv_timeout(WATCHDOG).unwrap().expect("answer");
        assert_eq!(h.seq, seq);
        assert_ne!(h.heading_status(), Some(HeadingStatus::Stale));
    }

    // Silence: exactly one Stale message, echoing the last sample.
    let stale = headings.recv_timeout(WATCHDOG).unwrap().expect("Stale");
    assert_eq!(
        stale.heading_status(),
        Some(HeadingStatus::Stale),
        "{stale:?}"
    );
    assert_eq!(
        (stale.seq, stale.timestamp_ns),
        (last_sent.seq, last_sent.timestamp_ns)
    );
    assert!(stale.heading_deg.is_nan() && stale.heading_std_deg.is_nan());
    assert_eq!(stale.processing_ns, 0);
    // Also on Zenoh (after the three answers).
    let on_zenoh: Vec<_> = std::iter::from_fn(|| zen.recv_timeout(WATCHDOG).unwrap())
        .take(4)
        .collect();
    assert_eq!(
        on_zenoh.last().map(|h| h.to_le_bytes()),
        Some(stale.to_le_bytes())
    );
    daemon.wait_for_log("source stale");
    // Several deadlines later, still only the one.
    assert_silent(&headings, Duration::from_millis(1500));
    let stats = daemon.wait_for_counters("veh", |s| s["stale"] == 1);
    assert_eq!((stats["received"], stats["answered"]), (3, 3));

    // Samples again: answered normally, logged once.
    gnss.send(moving_sample(3)).unwrap();
    let h = headings.recv_timeout(WATCHDOG).unwrap().expect("answer");
    assert_eq!(h.seq, 3);
    assert_ne!(h.heading_status(), Some(HeadingStatus::Stale));
    daemon.wait_for_log("served again");

    // A publisher that goes away: the discovered source gets its Stale message
    // before it is dropped.
    drop(gnss);
    let stale = headings.recv_timeout(WATCHDOG).unwrap().expect("Stale");
    assert_eq!(stale.heading_status(), Some(HeadingStatus::Stale));
    assert_eq!(stale.seq, 3);
    daemon.wait_for_log("source removed");
    daemon.stop();
}

#[test]
fn stale_off_sends_nothing() {
    let ns = TestNamespace::new("staleoff");
    let daemon = Ghnetd::builder(&ns).arg("--stale-after-ms=0").start();
    let (gnss, headings) = daemon.ends("veh");
    round_trip(&gnss, &headings, 0);
    assert_silent(&headings, Duration::from_millis(1000));
    assert!(!daemon.log().contains("source stale"));
}

#[test]
fn a_second_daemon_on_the_same_prefix_exits_naming_the_first() {
    let ns = TestNamespace::new("second");
    let first = Ghnetd::builder(&ns).start();

    let second = Ghnetd::builder(&ns).spawn();
    let (status, log) = second.wait_exit();
    assert!(!status.success(), "{status:?}\n{log}");
    let want = format!(
        "another ghnetd (pid {}) already serves prefix `ghnet`",
        first.pid()
    );
    assert!(log.contains(&want), "{log}");
    assert!(log.contains("ipc.service_prefix"), "{log}");

    // Another prefix in the same namespace is another deployment: allowed.
    let elsewhere = Ghnetd::builder(&ns).prefix("site2/ghnet").start();
    elsewhere.assert_running();

    // The first one still serves.
    let (gnss, headings) = first.ends("veh");
    round_trip(&gnss, &headings, 0);

    // A kill -9 leaves no stale lock: the next one starts and serves.
    first.kill9();
    let third = Ghnetd::builder(&ns).start();
    third.wait_until("an answer from the new daemon", || {
        gnss.send(moving_sample(1)).unwrap();
        recv_answer(&headings, Duration::from_millis(100)).is_some_and(|h| h.seq == 1)
    });
    third.stop();
}

/// As many subscribers as a service has slots.
fn every_slot<T>(subscribe: impl Fn() -> T) -> Vec<T> {
    (0..SERVICE_SETTINGS.max_subscribers)
        .map(|_| subscribe())
        .collect()
}

#[test]
fn the_subscriber_over_the_limit_gets_a_message_naming_the_key() {
    let ns = TestNamespace::new("overlimit");
    let ipc = ns.ipc();
    let _full = every_slot(|| HeadingSubscriber::new(&ipc, "veh").unwrap());
    let err = HeadingSubscriber::new(&ipc, "veh")
        .err()
        .expect("over the limit");
    assert!(matches!(err, OpenError::Limit { .. }), "{err:?}");
    let max = SERVICE_SETTINGS.max_subscribers;
    assert_eq!(
        err.to_string(),
        format!(
            "service `ghnet/veh/heading`: all {max} subscriber slots in use (ServiceSettings::max_subscribers)"
        )
    );

    // Asking for more than an existing service was created with.
    let small = ns
        .ipc()
        .with_settings(ServiceSettings::with_limits(4, 2, 16, 128));
    let _created_small = HeadingSubscriber::new(&small, "tiny").unwrap();
    let err = HeadingSubscriber::new(&ipc, "tiny")
        .err()
        .expect("mismatch");
    let msg = err.to_string();
    assert!(
        msg.contains("fewer subscriber slots than the 8")
            && msg.ends_with("(ServiceSettings::max_subscribers)"),
        "{msg}"
    );
}

#[test]
fn a_source_over_the_limit_is_logged_and_the_others_are_served() {
    let ns = TestNamespace::new("fullsrc");
    let ipc = ns.ipc();
    // Every subscriber slot of `full`'s velocity service taken before ghnetd comes.
    let max = SERVICE_SETTINGS.max_subscribers;
    let _taken = every_slot(|| VelocitySubscriber::new(&ipc, "full").unwrap());
    let full = VelocityPublisher::new(&ipc, "full").unwrap();
    let daemon = Ghnetd::builder(&ns).start();
    daemon.wait_for_log("cannot serve discovered source");
    let log = daemon.log();
    let line = log
        .lines()
        .find(|l| l.contains("cannot serve discovered source"))
        .unwrap();
    assert!(line.contains("source=full"), "{line}");
    assert!(
        line.contains(&format!(
            "service `ghnet/full/velocity`: all {max} subscriber slots in use (ipc.max_subscribers)"
        )),
        "{line}"
    );

    let (gnss, headings) = daemon.ends("ok");
    round_trip(&gnss, &headings, 0);
    assert_eq!(full.subscriber_count(), max, "ghnetd did not take a slot");
    assert_eq!(
        log.matches("cannot serve discovered source").count(),
        1,
        "reported once"
    );
    daemon.stop();
}

/// Every file and directory below `dir` (inclusive).
fn walk(dir: &Path, out: &mut Vec<PathBuf>) {
    out.push(dir.to_owned());
    if let Ok(entries) = std::fs::read_dir(dir) {
        for e in entries.flatten() {
            let p = e.path();
            if p.is_dir() {
                walk(&p, out);
            } else {
                out.push(p);
            }
        }
    }
}

#[test]
fn everything_ghnetd_creates_is_owner_only() {
    let ns = TestNamespace::new("perm");
    // Static source, no client: ghnetd alone creates the services, its node and
    // the root directory.
    let daemon = (Ghnetd::builder(&ns).source("perm").discovery(false)).start();
    daemon.wait_for_log("source added");

    // The root directory is owner-only, so nothing below it is reachable by group or
    // others, even where iceoryx2 gives a directory 0750 explicitly (`services`,
    // `nodes`: it chmods after mkdir, so the umask does not reach them).
    let root_mode = std::fs::metadata(ns.root_path())
        .unwrap()
        .permissions()
        .mode()
        & 0o777;
    assert_eq!(root_mode, 0o700, "root path");
    let mut paths = Vec::new();
    walk(ns.root_path(), &mut paths);
    paths.retain(|p| !p.is_dir());
    let shm: Vec<PathBuf> = std::fs::read_dir("/dev/shm")
        .unwrap()
        .flatten()
        .filter(|e| {
            e.file_name()
                .to_string_lossy()
                .starts_with(ns.global_prefix())
        })
        .map(|e| e.path())
        .collect();
    assert!(!shm.is_empty(), "no shared memory of the namespace");
    paths.extend(shm);
    let mut report = Vec::new();
    let mut open = Vec::new();
    for p in &paths {
        let Ok(meta) = std::fs::symlink_metadata(p) else {
            continue; // removed meanwhile
        };
        let mode = meta.permissions().mode() & 0o777;
        report.push(format!("{mode:04o} {}", p.display()));
        if mode & 0o077 != 0 {
            open.push(format!("{mode:04o} {}", p.display()));
        }
    }
    eprintln!("{}", report.join("\n"));
    assert!(
        open.is_empty(),
        "group/other access on:\n{}",
        open.join("\n")
    );
    drop(daemon);
}
