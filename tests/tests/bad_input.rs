//! The bad-input table (tests/tools/README.md, "Bad input"), one test per row, each
//! through a real `ghnetd`: every sample is answered exactly once with a status and its
//! echoed `seq`, the daemon's counters say why, and the next good sample is answered
//! normally. Plus undecodable Zenoh payloads at a real `ZenohHeadingSubscriber`.
//!
//! A case is a list of samples sent after one good sample (seq 0) and followed by
//! one good sample; [`run_case`] checks every answer, then the daemon's counters
//! (`@ghnetd/stats`), then that ghnetd exits cleanly on SIGTERM.
//!
//! The table's expectations are per epoch (each answer depends on its own sample), so
//! the daemon runs the per-epoch model [`PER_EPOCH`]: with the stateful default a
//! stopped or hopelessly noisy sample after a moving one is `Held` instead
//! (`history.rs`), and arbitrary streams through the stateful path are fuzzed in
//! `daemon/tests/fuzz.rs`.

use std::time::Duration;

use ghnet_client::zenoh::Wait;
use ghnet_client::{
    flags, DecodeError, HeadingEstimate, HeadingStatus, HeadingSubscriber, VelocitySample,
    ZenohHeadingSubscriber,
};
use ghnet_testkit::{
    free_tcp_port, now_ns, recv_answer, wait_until, zenoh_barrier, Ghnetd, Listen, OneSource,
    WATCHDOG,
};

/// The model whose answers depend on one sample only.
const PER_EPOCH: &str = "ghnet-epoch";

/// What a sample's answer must be.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Want {
    /// `Ok` or `LowSpeed`, finite heading and σ in range.
    Moving,
    /// `LowSpeed` with a finite σ above the policy's 10° (an accuracy so poor the
    /// heading is noise; σ is capped, never infinite).
    LowSpeedCapped,
    /// `Stationary`, speed 0 (or below one micrometre per second).
    Stationary,
    /// `InvalidInput`, heading and σ NaN.
    Invalid,
}

/// Counters a case adds on top of its two good samples.
#[derive(Debug, Clone, Copy, Default)]
struct Adds {
    invalid: u64,
    gaps: u64,
    duplicates: u64,
    backwards: u64,
}

/// Sample `seq` at `t0 + seq` ms moving at 5 m/s (3 north, 4 east).
fn good(t0: u64, seq: u64) -> VelocitySample {
    VelocitySample::new(t0 + seq * 1_000_000, seq, 3.0, 4.0, 0.0)
}

/// The next answer that is not a `Stale` notice (ghnetd sends one when a source has
/// been silent for `sources.stale_after_ms`; a loaded machine may pause that long).
fn next_answer(headings: &HeadingSubscriber, daemon: &Ghnetd) -> HeadingEstimate {
    daemon.assert_running();
    recv_answer(headings, WATCHDOG).unwrap_or_else(|| {
        daemon.assert_running();
        panic!("watchdog: no answer; log:\n{}", daemon.log())
    })
}

fn check(want: Want, h: &HeadingEstimate, what: &str) {
    let status = h.heading_status();
    match want {
        Want::Moving => {
            assert!(
                matches!(status, Some(HeadingStatus::Ok | HeadingStatus::LowSpeed)),
                "{what}: {h:?}"
            );
            assert!(
                (0.0..360.0).contains(&h.heading_deg)
                    && h.heading_std_deg >= 0.0
                    && h.heading_std_deg.is_finite(),
                "{what}: {h:?}"
            );
        }
        Want::LowSpeedCapped => {
            assert_eq!(status, Some(HeadingStatus::LowSpeed), "{what}: {h:?}");
            assert!(
                h.heading_deg.is_finite()
                    && h.heading_std_deg.is_finite()
                    && h.heading_std_deg > 10.0,
                "{what}: σ must be capped, not NaN or infinite: {h:?}"
            );
        }
        Want::Stationary => {
            assert_eq!(status, Some(HeadingStatus::Stationary), "{what}: {h:?}");
            assert!(h.speed < 1e-6, "{what}: {h:?}");
        }
        Want::Invalid => {
            assert_eq!(status, Some(HeadingStatus::InvalidInput), "{what}: {h:?}");
            assert!(
                h.heading_deg.is_nan() && h.heading_std_deg.is_nan() && h.atan2_deg.is_nan(),
                "{what}: {h:?}"
            );
        }
    }
}

/// Runs one case through a fresh ghnetd: good sample 0, then `case(t0)`, then a good
/// sample one step after the case's last one in seq and time (so it adds no gap and
/// is not backwards). Checks every answer (status, echoed seq and timestamp), the
/// counters, and a clean exit.
fn run_case(name: &str, case: impl FnOnce(u64) -> Vec<(VelocitySample, Want)>, adds: Adds) {
    let source = "bad";
    let one = OneSource::start(source, |b| b.model(PER_EPOCH));

    let t0 = now_ns();
    let mut samples = vec![(good(t0, 0), Want::Moving)];
    samples.extend(case(t0));
    let last = samples.last().unwrap().0;
    let mut after = good(t0, last.seq + 1);
    after.timestamp_ns = last.timestamp_ns + 1_000_000;
    samples.push((after, Want::Moving));

    for (i, (sample, want)) in samples.iter().enumerate() {
        one.gnss.send(*sample).unwrap();
        let h = next_answer(&one.headings, &one.daemon);
        let what = format!("{name}, sample {i} {sample:?}");
        assert_eq!(
            (h.seq, h.timestamp_ns),
            (sample.seq, sample.timestamp_ns),
            "{what}: echo"
        );
        check(*want, &h, &what);
    }
    assert!(
        one.headings
            .recv_timeout(Duration::from_millis(100))
            .unwrap()
            .is_none_or(|h| h.heading_status() == Some(HeadingStatus::Stale)),
        "{name}: exactly one answer per sample"
    );

    let n = samples.len() as u64;
    let c = one.daemon.wait_for_counters(source, |c| c["received"] == n);
    let got = [
        c["answered"],
        c["send_errors"],
        c["invalid"],
        c["gaps"],
        c["duplicates"],
        c["backwards"],
    ];
    let want = [
        n,
        0,
        adds.invalid,
        adds.gaps,
        adds.duplicates,
        adds.backwards,
    ];
    assert_eq!(
        got, want,
        "{name}: [answered, send_errors, invalid, gaps, duplicates, backwards] of {n}: {c:?}"
    );
    one.daemon.stop();
}

/// Sample `seq` at `t0 + seq` ms with `f` applied.
fn with(t0: u64, seq: u64, f: impl FnOnce(&mut VelocitySample)) -> VelocitySample {
    let mut s = good(t0, seq);
    f(&mut s);
    s
}

/// One invalid sample per value in each of v_north, v_east, v_down.
fn each_component(t0: u64, v: f32) -> Vec<(VelocitySample, Want)> {
    vec![
        (with(t0, 1, |s| s.v_north = v), Want::Invalid),
        (with(t0, 2, |s| s.v_east = v), Want::Invalid),
        (with(t0, 3, |s| s.v_down = v), Want::Invalid),
    ]
}

fn invalid(n: u64) -> Adds {
    Adds {
        invalid: n,
        ..Adds::default()
    }
}

#[test]
fn nan_in_any_velocity_component_is_invalid() {
    run_case("NaN", |t0| each_component(t0, f32::NAN), invalid(3));
}

#[test]
fn plus_infinity_in_any_velocity_component_is_invalid() {
    run_case("+inf", |t0| each_component(t0, f32::INFINITY), invalid(3));
}

#[test]
fn minus_infinity_in_any_velocity_component_is_invalid() {
    run_case(
        "-inf",
        |t0| each_component(t0, f32::NEG_INFINITY),
        invalid(3),
    );
}

#[test]
fn huge_values_are_invalid() {
    run_case(
        "huge",
        |t0| {
            let mut v = each_component(t0, 1e30);
            v.extend([
                (with(t0, 4, |s| s.v_north = f32::MAX), Want::Invalid),
                (with(t0, 5, |s| s.v_east = -f32::MAX), Want::Invalid),
                (with(t0, 6, |s| s.v_down = f32::MAX), Want::Invalid),
                // 101 m/s: just over model.max_speed (100).
                (
                    with(t0, 7, |s| (s.v_north, s.v_east) = (101.0, 0.0)),
                    Want::Invalid,
                ),
            ]);
            v
        },
        invalid(7),
    );
}

#[test]
fn unknown_v_down_is_ignored_even_when_nan_or_huge() {
    run_case(
        "v_down unknown",
        |t0| {
            let mut v = Vec::new();
            for (seq, vd) in [(1, f32::NAN), (2, f32::INFINITY), (3, f32::MAX)] {
                let s = with(t0, seq, |s| {
                    s.v_down = vd;
                    s.flags = flags::V_DOWN_UNKNOWN;
                });
                v.push((s, Want::Moving));
            }
            v
        },
        Adds::default(),
    );
}

#[test]
fn subnormal_velocities_are_stationary_not_invalid() {
    let tiny = f32::from_bits(1); // smallest subnormal, 1.4e-45
    assert!(tiny.is_subnormal());
    run_case(
        "subnormal",
        |t0| {
            vec![
                (
                    with(t0, 1, |s| (s.v_north, s.v_east) = (tiny, 0.0)),
                    Want::Stationary,
                ),
                (
                    with(t0, 2, |s| (s.v_north, s.v_east) = (-tiny, tiny)),
                    Want::Stationary,
                ),
                (
                    with(t0, 3, |s| {
                        (s.v_north, s.v_east, s.v_down) = (1e-39, -1e-39, tiny)
                    }),
                    Want::Stationary,
                ),
                // A subnormal accuracy is a (very) good receiver, not an error. (Its σ
                // underflows to 0°, while an accuracy of exactly 0 means "unknown" and
                // gets the network's σ; see the report.)
                (with(t0, 4, |s| s.speed_accuracy = tiny), Want::Moving),
            ]
        },
        Adds::default(),
    );
}

#[test]
fn exactly_zero_velocity_is_stationary() {
    run_case(
        "zero",
        |t0| {
            vec![
                (
                    with(t0, 1, |s| (s.v_north, s.v_east) = (0.0, 0.0)),
                    Want::Stationary,
                ),
                (
                    with(t0, 2, |s| (s.v_north, s.v_east) = (-0.0, -0.0)),
                    Want::Stationary,
                ),
                (
                    with(t0, 3, |s| (s.v_north, s.v_east, s.v_down) = (0.0, 0.0, 0.0)),
                    Want::Stationary,
                ),
            ]
        },
        Adds::default(),
    );
}

/// What is sent for zero velocity, pinned: status `Stationary`, speed 0, the
/// model-based heading `atan2_deg` 0 (atan2(0, 0)), and heading and σ are whatever the
/// network computes at the origin (finite; not to be used). Nothing is held over
/// from the previous sample: each answer depends on its own sample only.
#[test]
fn zero_velocity_answer_carries_no_held_heading() {
    let one = OneSource::start("z", |b| b.listen(Listen::Off).model(PER_EPOCH));
    let t0 = now_ns();
    let mut zero_answers = Vec::new();
    // Zero velocity after heading east, then after heading west: same answer.
    for (i, (vn, ve)) in [(0.0, 5.0), (0.0, 0.0), (0.0, -5.0), (0.0, 0.0)]
        .into_iter()
        .enumerate()
    {
        let seq = i as u64;
        one.gnss
            .send(VelocitySample::new(t0 + seq, seq, vn, ve, 0.0))
            .unwrap();
        let h = next_answer(&one.headings, &one.daemon);
        if ve == 0.0 {
            check(Want::Stationary, &h, "zero");
            assert_eq!(h.atan2_deg, 0.0, "{h:?}");
            assert!(
                h.heading_deg.is_finite() && h.heading_std_deg.is_finite(),
                "{h:?}"
            );
            zero_answers.push((h.heading_deg.to_bits(), h.heading_std_deg.to_bits()));
        }
    }
    assert_eq!(zero_answers[0], zero_answers[1], "no heading held over");
}

#[test]
fn unknown_accuracy_nan_is_valid() {
    run_case(
        "NaN accuracy",
        |t0| {
            vec![
                (with(t0, 1, |s| s.speed_accuracy = f32::NAN), Want::Moving),
                (with(t0, 2, |s| s.speed_accuracy = -f32::NAN), Want::Moving),
            ]
        },
        Adds::default(),
    );
}

#[test]
fn negative_or_infinite_accuracy_is_invalid() {
    run_case(
        "bad accuracy",
        |t0| {
            vec![
                (with(t0, 1, |s| s.speed_accuracy = -0.1), Want::Invalid),
                (with(t0, 2, |s| s.speed_accuracy = -f32::MAX), Want::Invalid),
                (
                    with(t0, 3, |s| s.speed_accuracy = f32::INFINITY),
                    Want::Invalid,
                ),
                (
                    with(t0, 4, |s| s.speed_accuracy = f32::NEG_INFINITY),
                    Want::Invalid,
                ),
                // Zero and -0 are a perfect receiver (σ from the network's floor).
                (with(t0, 5, |s| s.speed_accuracy = 0.0), Want::Moving),
                (with(t0, 6, |s| s.speed_accuracy = -0.0), Want::Moving),
            ]
        },
        invalid(4),
    );
}

#[test]
fn huge_finite_accuracy_is_answered_low_speed_with_capped_sigma() {
    run_case(
        "huge accuracy",
        |t0| {
            vec![
                (
                    with(t0, 1, |s| s.speed_accuracy = 1e30),
                    Want::LowSpeedCapped,
                ),
                (
                    with(t0, 2, |s| s.speed_accuracy = f32::MAX),
                    Want::LowSpeedCapped,
                ),
            ]
        },
        Adds::default(),
    );
}

#[test]
fn receiver_invalid_flag_is_invalid_and_unknown_flag_bits_are_ignored() {
    run_case(
        "flags",
        |t0| {
            vec![
                (with(t0, 1, |s| s.flags = flags::INVALID), Want::Invalid),
                (with(t0, 2, |s| s.flags = !flags::KNOWN), Want::Moving),
                (with(t0, 3, |s| s._reserved = u32::MAX), Want::Moving),
            ]
        },
        invalid(1),
    );
}

#[test]
fn time_going_backwards_is_invalid_and_counted() {
    run_case(
        "backwards",
        |t0| {
            vec![
                (good(t0, 1), Want::Moving),
                (with(t0, 2, |s| s.timestamp_ns = t0), Want::Invalid), // before sample 1
                (good(t0, 3), Want::Moving), // forward again from the previous sample
                (with(t0, 4, |s| s.timestamp_ns = 0), Want::Invalid), // to 1970
                (with(t0, 5, |s| s.timestamp_ns = u64::MAX), Want::Moving), // far future
                (good(t0, 6), Want::Invalid), // back from the far future
            ]
        },
        Adds {
            invalid: 3,
            backwards: 3,
            ..Adds::default()
        },
    );
}

#[test]
fn equal_timestamps_are_not_backwards() {
    run_case(
        "same time",
        |t0| {
            vec![
                (
                    with(t0, 1, |s| s.timestamp_ns = t0 + 1_000_000),
                    Want::Moving,
                ),
                (
                    with(t0, 2, |s| s.timestamp_ns = t0 + 1_000_000),
                    Want::Moving,
                ),
            ]
        },
        Adds::default(),
    );
}

#[test]
fn duplicate_sequence_numbers_are_answered_and_counted() {
    run_case(
        "duplicates",
        |t0| {
            vec![
                (good(t0, 1), Want::Moving),
                (good(t0, 1), Want::Moving), // repeated (same time is not backwards)
                (good(t0, 2), Want::Moving),
                (
                    with(t0, 0, |s| s.timestamp_ns = t0 + 3_000_000),
                    Want::Moving,
                ), // older seq
            ]
        },
        Adds {
            duplicates: 2,
            ..Adds::default()
        },
    );
}

#[test]
fn skipped_sequence_numbers_are_answered_and_counted_as_gaps() {
    run_case(
        "gaps",
        |t0| {
            vec![
                (good(t0, 1), Want::Moving),
                (good(t0, 4), Want::Moving),   // 2 and 3 missing
                (good(t0, 104), Want::Moving), // 99 missing
            ]
        },
        Adds {
            gaps: 101,
            ..Adds::default()
        },
    );
}

#[test]
fn sequence_jumps_to_u64_max_and_back_saturate_the_counters() {
    run_case(
        "seq u64::MAX",
        |t0| {
            vec![
                (with(t0, 1, |s| s.seq = u64::MAX), Want::Moving), // gap of u64::MAX - 1
                (with(t0, 2, |s| s.seq = 0), Want::Moving),        // wraps: a duplicate
                (good(t0, 3), Want::Moving),                       // 2 more: saturates
            ]
        },
        Adds {
            // Saturated, not wrapped (a debug build would panic on the overflow).
            gaps: u64::MAX,
            duplicates: 1,
            ..Adds::default()
        },
    );
}

/// Undecodable Zenoh payloads on a heading key, put by a real Zenoh session over
/// TCP: the `ZenohHeadingSubscriber` returns an error value for each (never panics,
/// never skips silently) and then decodes the daemon's next valid heading.
#[test]
fn undecodable_zenoh_payloads_are_errors_and_the_subscriber_goes_on() {
    let source = "zg";
    let one = OneSource::start(source, |b| b);
    let ipc = one.daemon.ipc().clone();

    // The consumer: connected to the daemon and listening for the garbage publisher.
    let endpoint = format!("tcp/127.0.0.1:{}", free_tcp_port());
    let config = ghnet_client::peer_config(
        std::slice::from_ref(&endpoint),
        &[one.daemon.zenoh_endpoint().to_owned()],
    )
    .unwrap();
    let consumer = ghnet_client::zenoh::open(config).wait().unwrap();
    let sub = ZenohHeadingSubscriber::new(&consumer, &ipc, source).unwrap();
    zenoh_barrier(&consumer, &ipc);
    // Someone else on the network publishing on the same key.
    let rogue_config = ghnet_client::peer_config(&[], std::slice::from_ref(&endpoint)).unwrap();
    let rogue = ghnet_client::zenoh::open(rogue_config).wait().unwrap();
    let key = ipc.zenoh_heading_key(source).unwrap();
    let put = |bytes: &[u8]| rogue.put(key.as_str(), bytes.to_vec()).wait().unwrap();
    // Until the rogue session knows the consumer's subscriber, its puts go nowhere.
    wait_until("a rogue payload at the consumer", || {
        put(b"x");
        matches!(
            sub.recv_timeout(Duration::from_millis(100)),
            Err(DecodeError::Length(1))
        )
    });
    while sub.recv_timeout(Duration::from_millis(200)).is_err() {}

    let t0 = now_ns();
    let long = vec![0xa5u8; 100_000];
    let garbage: [&[u8]; 6] = [
        b"",
        b"not a heading",
        &[0u8; 63],
        &[0xffu8; 65],
        &long[..],
        "{\"heading_deg\": 12.5}".as_bytes(),
    ];
    for (i, bytes) in garbage.iter().enumerate() {
        put(bytes);
        match sub.recv_timeout(WATCHDOG) {
            Err(DecodeError::Length(n)) => assert_eq!(n, bytes.len(), "payload {i}"),
            other => panic!("payload {i} ({} bytes): {other:?}", bytes.len()),
        }
        // The next real heading from ghnetd still decodes.
        let seq = i as u64;
        one.gnss
            .send(VelocitySample::new(t0 + seq, seq, 3.0, 4.0, 0.0))
            .unwrap();
        let from_ice = next_answer(&one.headings, &one.daemon);
        let h = loop {
            let h = sub
                .recv_timeout(WATCHDOG)
                .expect("a valid heading decodes")
                .expect("watchdog: heading over Zenoh");
            if h.heading_status() != Some(HeadingStatus::Stale) {
                break h;
            }
        };
        assert_eq!(h.to_le_bytes(), from_ice.to_le_bytes(), "payload {i}");
        assert_eq!(h.seq, seq);
    }
    assert!(one.daemon.is_running());
}
