//! Sources that appear at run time are served; sources never cross.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Duration;

use ghnet_client::{HeadingStatus, HeadingSubscriber, VelocityPublisher, VelocitySample};
use ghnet_testkit::{assert_silent, now_ns, wait_until, Ghnetd, TestNamespace, WATCHDOG};

fn ping(gnss: &VelocityPublisher, headings: &HeadingSubscriber, seq: u64) {
    gnss.send(VelocitySample::new(now_ns(), seq, 0.0, 2.0, 0.0))
        .unwrap();
    let h = headings.recv_timeout(WATCHDOG).unwrap().expect("an answer");
    assert_eq!(h.seq, seq, "{}", headings.service_name());
    assert_ne!(h.heading_status(), Some(HeadingStatus::InvalidInput));
}

#[test]
fn source_appearing_at_run_time_is_served() {
    let ns = TestNamespace::new("late");
    let ipc = ns.ipc();
    let daemon = Ghnetd::builder(&ns).start(); // discovery on, no static sources
    assert!(!daemon.log().contains("source added"), "{}", daemon.log());

    let headings = HeadingSubscriber::new(&ipc, "late").unwrap();
    let gnss = VelocityPublisher::new(&ipc, "late").unwrap();
    daemon.wait_serving(&gnss);
    ping(&gnss, &headings, 0);
    daemon.wait_for_counters("late", |c| c["answered"] == 1);

    // A second source while the first is served (the daemon re-arms its wait set).
    let headings2 = HeadingSubscriber::new(&ipc, "later").unwrap();
    let gnss2 = VelocityPublisher::new(&ipc, "later").unwrap();
    daemon.wait_serving(&gnss2);
    for seq in 1..20 {
        ping(&gnss, &headings, seq);
        ping(&gnss2, &headings2, seq);
    }
    daemon.wait_for_log_count("source added", 2);
}

/// One source of the crossing test: its own direction and sequence range.
struct Vehicle {
    name: &'static str,
    v_north: f32,
    v_east: f32,
    atan2_deg: f32,
    first_seq: u64,
}

const COUNT: u64 = 400;
/// Samples in flight per source at most (well below the 128-sample buffers, so
/// the test cannot lose samples to overflow however slow the machine is).
const WINDOW: u64 = 32;

#[test]
fn two_sources_at_once_never_cross() {
    let ns = TestNamespace::new("cross");
    let ipc = ns.ipc();
    let daemon = Ghnetd::builder(&ns).start();
    let vehicles = [
        Vehicle {
            name: "alpha",
            v_north: 0.0,
            v_east: 5.0,
            atan2_deg: 90.0,
            first_seq: 0,
        },
        Vehicle {
            name: "beta",
            v_north: -5.0,
            v_east: 0.0,
            atan2_deg: 180.0,
            first_seq: 1 << 40,
        },
    ];
    let daemon = &daemon; // shared with the vehicle threads
    std::thread::scope(|scope| {
        for v in &vehicles {
            let ipc = ipc.clone();
            scope.spawn(move || {
                let answered = Arc::new(AtomicU64::new(0));
                let (ready_tx, ready_rx) = std::sync::mpsc::channel();
                let receiver = std::thread::scope(|inner| {
                    // Receiver: every answer must be this vehicle's, once, in order.
                    let rx = inner.spawn(|| {
                        let headings = HeadingSubscriber::new(&ipc, v.name).unwrap();
                        ready_tx.send(()).unwrap();
                        for k in 0..COUNT {
                            let h = headings.recv_timeout(WATCHDOG).unwrap().unwrap_or_else(|| {
                                panic!("watchdog: {} got {k} of {COUNT} answers", v.name)
                            });
                            assert_eq!(h.seq, v.first_seq + k, "{}: {h:?}", v.name);
                            assert!(
                                (h.atan2_deg - v.atan2_deg).abs() < 1e-3
                                    && (h.speed - 5.0).abs() < 1e-5,
                                "{} got another source's answer: {h:?}",
                                v.name
                            );
                            answered.store(k + 1, Ordering::Release);
                        }
                        assert_silent(&headings, Duration::from_millis(200));
                    });
                    ready_rx.recv().unwrap();
                    let gnss = VelocityPublisher::new(&ipc, v.name).unwrap();
                    daemon.wait_serving(&gnss); // discovered
                    for k in 0..COUNT {
                        wait_until("answers to catch up", || {
                            k < answered.load(Ordering::Acquire) + WINDOW
                        });
                        let s = VelocitySample::new(
                            now_ns(),
                            v.first_seq + k,
                            v.v_north,
                            v.v_east,
                            0.0,
                        );
                        gnss.send(s).unwrap();
                    }
                    let answers = rx.join();
                    // The daemon's side, while the source is still served: it
                    // received and answered exactly this vehicle's samples.
                    let c = daemon.wait_for_counters(v.name, |c| c["received"] >= COUNT);
                    let counts = (c["received"], c["answered"]);
                    assert_eq!(counts, (COUNT, COUNT), "{}: {c:?}", v.name);
                    answers
                });
                receiver.expect("receiver assertions");
            });
        }
    });
}
