//! A published sample comes back as the heading `ghnet_inference` computes in-process,
//! exactly once, in order, with its `seq` and timestamp echoed.
//!
//! The comparisons use the per-epoch `Predictor`, so the daemon runs the per-epoch
//! model [`PER_EPOCH`] (which is also the one that batches); the stateful default is
//! compared with the in-process `StreamPredictor` in `history.rs`.

use std::time::Duration;

use ghnet_client::{flags, HeadingStatus, HeadingSubscriber, VelocityPublisher, VelocitySample};
use ghnet_inference::{Predictor, Status, StatusPolicy};
use ghnet_lab::sim::{simulate_realistic, RealisticParams};
use ghnet_testkit::{assert_silent, now_ns, Ghnetd, OneSource, TestNamespace, WATCHDOG};

/// The model the comparisons mean: one answer per sample, no history.
const PER_EPOCH: &str = "ghnet-epoch";

fn per_epoch_model() -> std::sync::Arc<ghnet_inference::Model> {
    std::sync::Arc::new(ghnet_inference::Model::builtin(PER_EPOCH).unwrap())
}

/// `|a - b| <= 1e-6 · max(1, |b|)`, both NaN counting as equal, and headings that
/// differ by a full turn (359.9999… vs 0) counting as equal when `wrap_360`.
fn close(a: f32, b: f32, wrap_360: bool) -> bool {
    if a.is_nan() || b.is_nan() {
        return a.is_nan() && b.is_nan();
    }
    let tol = 1e-6 * b.abs().max(1.0);
    let d = (a - b).abs();
    d <= tol || (wrap_360 && (d - 360.0).abs() <= 1e-6 * 360.0)
}

/// The wire status the daemon must send for each models status (by the models' name,
/// so this table is written independently of the daemon's mapping).
fn wire(s: Status) -> HeadingStatus {
    let table = [
        ("ok", HeadingStatus::Ok),
        ("low_speed", HeadingStatus::LowSpeed),
        ("stationary", HeadingStatus::Stationary),
        ("invalid", HeadingStatus::InvalidInput),
        ("held", HeadingStatus::Held),
    ];
    let (_, w) = table
        .iter()
        .find(|(n, _)| *n == s.as_str())
        .expect("every status");
    *w
}

#[test]
fn heading_equals_in_process_model_and_echoes_seq_and_timestamp() {
    let one = OneSource::start("echo", |b| b.model(PER_EPOCH));

    // Every compass direction, the status boundaries, and a realistic track.
    let mut inputs: Vec<(f32, f32)> = vec![
        (5.0, 0.0),
        (0.0, 5.0),
        (-5.0, 0.0),
        (0.0, -5.0),
        (3.0, -4.0),
        (-0.3, 0.2),
        (0.06, 0.0),
        (0.01, 0.01),
        (0.0, 0.0),
        (60.0, 60.0),
    ];
    let params = RealisticParams {
        samples: 300,
        ..RealisticParams::default()
    };
    inputs.extend(
        simulate_realistic(&params, 11)
            .iter()
            .map(|s| (s.v_north, s.v_east)),
    );

    let model = per_epoch_model();
    let mut predictor = Predictor::new(model.clone()).with_policy(StatusPolicy::default());
    let (mut max_diff, mut statuses) = (0.0f32, std::collections::BTreeSet::new());
    let t_base = now_ns();
    for (i, &(vn, ve)) in inputs.iter().enumerate() {
        // Large values, so truncation to 32 bits would show.
        let (seq, ts) = (
            u64::from(u32::MAX) + 7 * i as u64,
            t_base + i as u64 * 1_000,
        );
        // Speed accuracy unknown (NaN, the `new` default): the model input is (vn, ve).
        one.gnss
            .send(VelocitySample::new(ts, seq, vn, ve, 0.1))
            .unwrap();
        let h = one
            .headings
            .recv_timeout(WATCHDOG)
            .unwrap()
            .expect("an answer");
        assert_eq!((h.seq, h.timestamp_ns), (seq, ts), "echo of input {i}");

        let want = predictor.predict(vn, ve);
        let ctx = format!("input {i} ({vn}, {ve}): daemon {h:?}, in-process {want:?}");
        assert_eq!(h.heading_status(), Some(wire(want.status)), "{ctx}");
        assert!(
            close(h.heading_deg, want.heading_deg, true),
            "heading: {ctx}"
        );
        assert!(close(h.heading_std_deg, want.std_deg, false), "std: {ctx}");
        assert!(close(h.atan2_deg, want.atan2_deg, true), "atan2: {ctx}");
        assert!(close(h.speed, want.speed, false), "speed: {ctx}");
        assert_eq!(h.model_id, model.id(), "{ctx}");
        let name = model.name();
        assert_eq!(h.model_name_str(), &name[..name.len().min(16)], "{ctx}");
        for (a, b) in [
            (h.heading_deg, want.heading_deg),
            (h.heading_std_deg, want.std_deg),
        ] {
            if a.is_finite() && b.is_finite() {
                max_diff = max_diff.max((a - b).abs());
            }
        }
        statuses.insert(want.status.as_str());
    }
    eprintln!(
        "{} inputs; largest |daemon − in-process| {max_diff:e}; statuses {statuses:?}",
        inputs.len()
    );
    assert!(
        statuses.contains("stationary"),
        "the boundary inputs must be covered"
    );
    // Exactly one answer per sample.
    assert_silent(&one.headings, Duration::from_millis(200));
    drop(one.daemon);
}

/// Several sources with samples waiting when ghnetd wakes (receivers on one epoch,
/// or a loop that fell behind): their samples are answered together, through one
/// batched model call per round of up to 128, and each source must still get
/// exactly its own answers, in order, equal to the in-process model's (up to the
/// batch kernel's rounding), including the invalid and stationary ones.
#[test]
fn sources_waking_together_get_their_own_answers_in_order() {
    let ns = TestNamespace::new("together");
    let ipc = ns.ipc();
    const SOURCES: usize = 5;
    const PER_SOURCE: u64 = 60; // 300 in all: more than one round of 128
    let names: Vec<String> = (0..SOURCES).map(|k| format!("burst{k}")).collect();
    let builder = Ghnetd::builder(&ns).discovery(false).model(PER_EPOCH);
    let daemon = names.iter().fold(builder, |b, n| b.source(n)).start();
    let subs: Vec<_> = names
        .iter()
        .map(|n| HeadingSubscriber::new(&ipc, n).unwrap())
        .collect();
    let pubs: Vec<_> = names
        .iter()
        .map(|n| VelocityPublisher::new(&ipc, n).unwrap())
        .collect();
    for p in &pubs {
        daemon.wait_serving(p);
    }

    // Each source its own direction and speed, so an answer given to the wrong
    // source would show; every 7th sample invalid, every 11th stationary.
    let input = |k: usize, i: u64| -> (f32, f32) {
        if i % 7 == 3 {
            (f32::NAN, 1.0)
        } else if i % 11 == 5 {
            (0.0, 0.0)
        } else {
            let angle = (k as f32 * 72.0 + i as f32 * 0.5).to_radians();
            let speed = 6.0 + k as f32 + (i % 5) as f32;
            (speed * angle.cos(), speed * angle.sin())
        }
    };
    // ghnetd stopped while the samples arrive: when it continues, every source's
    // listener has fired and it sees them all in one wake-up.
    daemon.signal(libc::SIGSTOP);
    let t0 = now_ns();
    for i in 0..PER_SOURCE {
        for (k, p) in pubs.iter().enumerate() {
            let (vn, ve) = input(k, i);
            p.publish(VelocitySample::new(t0 + i, 1_000 + i, vn, ve, 0.0))
                .unwrap();
        }
    }
    for p in &pubs {
        p.notify().unwrap();
    }
    daemon.signal(libc::SIGCONT);

    let model = per_epoch_model();
    let mut predictor = Predictor::new(model.clone()).with_policy(StatusPolicy::default());
    for (k, sub) in subs.iter().enumerate() {
        for i in 0..PER_SOURCE {
            let h = sub.recv_timeout(WATCHDOG).unwrap().unwrap_or_else(|| {
                panic!(
                    "source {k}: no answer to sample {i}; log:\n{}",
                    daemon.log()
                )
            });
            assert_eq!(
                h.seq,
                1_000 + i,
                "source {k}: answers in order, none missing"
            );
            let (vn, ve) = input(k, i);
            let want = predictor.predict(vn, ve);
            let ctx = format!("source {k} sample {i} ({vn}, {ve}): {h:?} vs {want:?}");
            assert_eq!(h.heading_status(), Some(wire(want.status)), "{ctx}");
            for (a, b) in [
                (h.heading_deg, want.heading_deg),
                (h.heading_std_deg, want.std_deg),
            ] {
                let d = (a - b).abs();
                assert!(
                    (a.is_nan() && b.is_nan()) || d < 1e-3 || (d - 360.0).abs() < 1e-3,
                    "{ctx}"
                );
            }
        }
        assert_silent(sub, Duration::from_millis(100)); // exactly one answer per sample
    }
    drop(daemon);
}

/// Ping-pong with an invalid sample every tenth, then a burst in one notification:
/// every sample answered once, in order; a gap, a duplicate and time going backwards
/// are counted.
#[test]
fn ping_pong_and_a_burst_are_answered_once_each_and_counted() {
    let one = OneSource::start("pingpong", |b| b);
    let sample = |seq: u64| {
        let mut s = VelocitySample::new(1_000_000 + seq * 100, seq, 5.0, 5.0, 0.0);
        s.speed_accuracy = 0.1;
        s
    };
    let n = 100u64;
    for seq in 0..n {
        let mut s = sample(seq);
        if seq % 10 == 9 {
            s.v_north = f32::NAN; // invalid input is answered, not dropped
        }
        one.gnss.send(s).unwrap();
        let h = one
            .headings
            .recv_timeout(WATCHDOG)
            .unwrap()
            .expect("answer");
        assert_eq!((h.seq, h.timestamp_ns), (s.seq, s.timestamp_ns));
        if seq % 10 == 9 {
            assert_eq!(h.heading_status(), Some(HeadingStatus::InvalidInput));
            assert!(h.heading_deg.is_nan(), "seq {seq}: {h:?}");
        } else {
            let moving = matches!(
                h.heading_status(),
                Some(HeadingStatus::Ok | HeadingStatus::LowSpeed)
            );
            assert!(
                moving && (h.atan2_deg - 45.0).abs() < 1e-3,
                "seq {seq}: {h:?}"
            );
            assert!((0.0..360.0).contains(&h.heading_deg), "seq {seq}: {h:?}");
        }
    }
    // A burst (below the subscriber buffer) in one notification: all answered, in order.
    for seq in n..2 * n {
        one.gnss.publish(sample(seq)).unwrap();
    }
    one.gnss.notify().unwrap();
    for seq in n..2 * n {
        let h = one
            .headings
            .recv_timeout(WATCHDOG)
            .unwrap()
            .expect("answer");
        assert_eq!(h.seq, seq);
    }
    assert_silent(&one.headings, Duration::from_millis(200));

    one.gnss.send(sample(2 * n + 5)).unwrap(); // 5 missing
    one.gnss.send(sample(2 * n + 5)).unwrap(); // a duplicate
    let mut back = sample(2 * n + 6);
    (back.timestamp_ns, back.flags) = (1, flags::SIMULATED);
    one.gnss.send(back).unwrap();
    for _ in 0..3 {
        one.headings
            .recv_timeout(WATCHDOG)
            .unwrap()
            .expect("answer");
    }
    // 203 received and answered; 10 NaN and 1 backwards invalid.
    let c = one
        .daemon
        .wait_for_counters("pingpong", |c| c["received"] == 2 * n + 3);
    let got = [
        c["answered"],
        c["invalid"],
        c["gaps"],
        c["duplicates"],
        c["backwards"],
    ];
    assert_eq!(got, [2 * n + 3, 11, 5, 1, 1], "{c:?}");
    one.daemon.stop();
}
