//! Invalid samples are answered `InvalidInput`, counted, and do not hurt the daemon.

use ghnet_client::{flags, HeadingStatus, VelocitySample};
use ghnet_testkit::{now_ns, OneSource, WATCHDOG};

#[test]
fn invalid_samples_are_answered_invalid_counted_and_the_daemon_goes_on() {
    let one = OneSource::start("inv", |b| b);

    let t0 = now_ns();
    let at =
        |seq: u64, vn: f32, ve: f32| VelocitySample::new(t0 + seq * 1_000_000, seq, vn, ve, 0.0);
    let mut cases: Vec<(&str, VelocitySample, bool)> = vec![
        ("valid", at(0, 3.0, 4.0), true),
        ("NaN north", at(1, f32::NAN, 4.0), false),
        ("+inf east", at(2, 3.0, f32::INFINITY), false),
        ("-inf north", at(3, f32::NEG_INFINITY, 4.0), false),
        ("absurd 150 m/s", at(4, 150.0, 0.0), false),
    ];
    let mut s = at(5, 1.0, 1.0);
    s.v_down = 120.0; // absurd 3-D speed
    cases.push(("absurd v_down", s, false));
    let mut s = at(6, 3.0, 4.0);
    s.timestamp_ns = t0; // earlier than sample 5: time going backwards
    cases.push(("time backwards", s, false));
    let mut s = at(7, 3.0, 4.0);
    s.flags = flags::INVALID;
    cases.push(("receiver flag", s, false));
    let mut s = at(8, 3.0, 4.0);
    s.speed_accuracy = -1.0;
    cases.push(("negative accuracy", s, false));
    // Valid samples afterwards are still answered normally.
    cases.extend((9..30).map(|seq| ("valid after", at(seq, 3.0, -4.0), true)));

    for (what, sample, valid) in &cases {
        one.gnss.send(*sample).unwrap();
        let h = one
            .headings
            .recv_timeout(WATCHDOG)
            .unwrap()
            .expect("an answer");
        assert_eq!(h.seq, sample.seq, "{what}");
        let status = h.heading_status();
        if *valid {
            let moving = matches!(status, Some(HeadingStatus::Ok | HeadingStatus::LowSpeed));
            let plausible = h.heading_deg.is_finite() && (h.speed - 5.0).abs() < 1e-5;
            assert!(moving && plausible, "{what}: {h:?}");
        } else {
            let nan = h.heading_deg.is_nan() && h.heading_std_deg.is_nan();
            assert!(
                status == Some(HeadingStatus::InvalidInput) && nan,
                "{what}: {h:?}"
            );
        }
    }
    let n = cases.len() as u64;
    let n_invalid = cases.iter().filter(|c| !c.2).count() as u64;

    // The daemon's counters.
    let stats = one.daemon.wait_for_counters("inv", |s| s["received"] == n);
    assert_eq!(stats["answered"], n, "{stats:?}");
    assert_eq!(stats["invalid"], n_invalid, "{stats:?}");
    assert_eq!(stats["backwards"], 1, "{stats:?}");
    assert_eq!((stats["gaps"], stats["duplicates"]), (0, 0), "{stats:?}");
    one.daemon.stop();
}
