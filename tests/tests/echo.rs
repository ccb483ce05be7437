//! A published sample comes back as the heading `ghnet_models` computes in-process.

use ghnet_client::{HeadingStatus, HeadingSubscriber, VelocityPublisher, VelocitySample};
use ghnet_models::sim::{simulate_realistic, RealisticParams};
use ghnet_models::{Predictor, Status, StatusPolicy};
use ghnet_tests::{close, now_ns, test_model, Daemon, Namespace, WATCHDOG};

/// models' status → the wire status the daemon must send.
fn wire(s: Status) -> HeadingStatus {
    match s {
        Status::Ok => HeadingStatus::Ok,
        Status::LowSpeed => HeadingStatus::LowSpeed,
        Status::Stationary => HeadingStatus::Stationary,
        Status::Invalid => HeadingStatus::InvalidInput,
    }
}

#[test]
fn heading_equals_in_process_model_and_echoes_seq_and_timestamp() {
    let ns = Namespace::new();
    let ipc = ns.ipc();
    let daemon = Daemon::start(&ns, &["--source", "echo", "--discovery", "false"]);
    let headings = HeadingSubscriber::new(&ipc, "echo").unwrap();
    let gnss = VelocityPublisher::new(&ipc, "echo").unwrap();
    daemon.wait_serving(&gnss);

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

    let tm = test_model();
    let mut predictor = Predictor::new(tm.model.clone()).with_policy(StatusPolicy::default());
    let (mut max_diff, mut statuses) = (0.0f32, std::collections::BTreeSet::new());
    let t_base = now_ns();
    for (i, &(vn, ve)) in inputs.iter().enumerate() {
        // Large values, so truncation to 32 bits would show.
        let (seq, ts) = (
            u64::from(u32::MAX) + 7 * i as u64,
            t_base + i as u64 * 1_000,
        );
        // Speed accuracy unknown (NaN, the `new` default): the model input is (vn, ve).
        gnss.send(VelocitySample::new(ts, seq, vn, ve, 0.1))
            .unwrap();
        let h = headings.recv_timeout(WATCHDOG).unwrap().expect("an answer");
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
        assert_eq!(h.model_id, tm.model.id(), "{ctx}");
        let name = tm.model.name();
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
    assert!(headings
        .recv_timeout(std::time::Duration::from_millis(200))
        .unwrap()
        .is_none());
    drop(daemon);
}
