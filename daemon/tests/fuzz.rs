//! Property-based fuzzing of ghnetd's inputs (proptest, modest case counts so CI
//! stays at a few seconds per target):
//!
//! - the config TOML parser and validation: arbitrary text and arbitrary key/value
//!   trees near the real schema give `Ok` or a one-line error, never a panic;
//! - the sample rules ghnetd runs per source ([`ghnet_inference::SourceStream`] through
//!   [`ghnet_inference::Runner`], the stateful default model): arbitrary bit patterns in
//!   every `VelocitySample` field give exactly one answer with a known status, and
//!   counts that agree with a reference count (each history reset has its cause
//!   counted);
//! - the same through a real in-process ghnetd over real iceoryx2: every sample
//!   answered once, `received == answered + send_errors`, `invalid` equal to the
//!   `InvalidInput` answers seen.
//!
//! The Zenoh payload decoder is fuzzed in `client/src/codec.rs`, the CSV, model-file
//! and model-metadata parsers in `models/lab/tests/fuzz.rs`.

mod common;

use std::cell::Cell;
use std::sync::Arc;

use common::{next_answer, InProcess};
use ghnet_client::{
    flags, HeadingEstimate, HeadingStatus, HeadingSubscriber, VelocityPublisher, VelocitySample,
};
use ghnet_inference::{Prediction, Runner, Sample, Status};
use ghnetd::Config;
use proptest::prelude::*;
use proptest::test_runner::{Config as PtConfig, TestRunner};

/// A config key name: one of the schema's (so values reach validation) or junk.
fn key() -> impl Strategy<Value = String> {
    prop_oneof![
        prop::sample::select(vec![
            "service_prefix",
            "iceoryx2_global_prefix",
            "iceoryx2_root_path",
            "static",
            "discovery",
            "discovery_interval_ms",
            "max_sources",
            "name",
            "stationary_speed",
            "max_std_deg",
            "max_speed",
            "interval_s",
            "enabled",
            "mode",
            "listen",
            "connect",
            "multicast_scouting",
            "gossip",
            "config_file",
        ])
        .prop_map(str::to_owned),
        "[a-z_]{1,10}",
    ]
}

/// A TOML value of any type, biased to the edges of what validation checks.
fn value() -> impl Strategy<Value = toml::Value> {
    let leaf = prop_oneof![
        any::<bool>().prop_map(toml::Value::Boolean),
        any::<i64>().prop_map(toml::Value::Integer),
        prop_oneof![Just(0i64), Just(-1), Just(10), Just(60_001), Just(1025)]
            .prop_map(toml::Value::Integer),
        any::<f64>().prop_map(toml::Value::Float),
        prop_oneof![
            Just("peer"),
            Just("router"),
            Just("tcp/127.0.0.1:0"),
            Just("tcp/[::1]:99999"),
            Just("ghnet"),
            Just("a/b"),
            Just("/x"),
            Just(""),
            Just("paper-s1"),
            Just("@ghnetd"),
            Just("**"),
        ]
        .prop_map(|s| toml::Value::String(s.to_owned())),
        "[ -~]{0,24}".prop_map(toml::Value::String),
        "\\PC{0,8}".prop_map(toml::Value::String),
    ];
    leaf.prop_recursive(2, 8, 4, |inner| {
        prop::collection::vec(inner, 0..4).prop_map(toml::Value::Array)
    })
}

/// A whole config tree: sections (the real ones or junk) of key/value pairs, and a
/// few top-level values.
fn tree() -> impl Strategy<Value = toml::Table> {
    let section = prop_oneof![
        prop::sample::select(vec!["ipc", "sources", "model", "stats", "zenoh"])
            .prop_map(str::to_owned),
        "[a-z]{1,6}",
    ];
    let table = prop::collection::btree_map(key(), value(), 0..5)
        .prop_map(|m| toml::Value::Table(m.into_iter().collect()));
    (
        prop::collection::btree_map(section, table, 0..5),
        prop::collection::btree_map(key(), value(), 0..2),
    )
        .prop_map(|(sections, top)| sections.into_iter().chain(top).collect())
}

/// An error message is one line, and not empty.
fn one_line(e: &anyhow::Error) -> bool {
    let s = format!("{e:#}");
    !s.is_empty() && !s.contains('\n')
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 128, ..ProptestConfig::default() })]

    /// Arbitrary text: parse and validate give `Ok` or a one-line error.
    #[test]
    fn config_arbitrary_text(text in prop_oneof!["\\PC{0,200}", "[\\[\\]a-z_=\"0-9. \n]{0,200}"]) {
        match Config::from_toml(&text) {
            Ok(c) => {
                if let Err(e) = c.validate() {
                    prop_assert!(one_line(&e), "{:#}", e);
                }
            }
            Err(e) => prop_assert!(one_line(&e), "{:#}", e),
        }
    }

    /// Arbitrary trees near the schema: wrong types, unknown keys, bad values.
    #[test]
    fn config_arbitrary_trees(t in tree()) {
        let Ok(text) = toml::to_string(&t) else {
            return Ok(()); // e.g. a value toml cannot write; not an input to ghnetd
        };
        match Config::from_toml(&text) {
            Ok(c) => {
                match c.validate() {
                    // What validates also prints and reads back the same.
                    Ok(()) => prop_assert_eq!(Config::from_toml(&c.to_toml()).unwrap(), c),
                    Err(e) => prop_assert!(one_line(&e), "{:#}", e),
                }
            }
            Err(e) => prop_assert!(one_line(&e), "{}\n{:#}", text, e),
        }
    }
}

/// Any bit pattern in every field.
fn any_sample() -> impl Strategy<Value = VelocitySample> {
    let f = prop_oneof![
        any::<u32>().prop_map(f32::from_bits),
        -120.0f32..120.0,
        prop_oneof![
            Just(0.0f32),
            Just(-0.0),
            Just(f32::NAN),
            Just(f32::INFINITY),
            Just(f32::MIN_POSITIVE / 2.0),
            Just(f32::MAX),
        ],
    ];
    (
        any::<u64>(),
        any::<u64>(),
        f.clone(),
        f.clone(),
        f.clone(),
        f,
        prop_oneof![any::<u32>(), Just(0u32), Just(flags::V_DOWN_UNKNOWN)],
        any::<u32>(),
    )
        .prop_map(
            |(timestamp_ns, seq, v_north, v_east, v_down, speed_accuracy, flags, r)| {
                VelocitySample {
                    timestamp_ns,
                    seq,
                    v_north,
                    v_east,
                    v_down,
                    speed_accuracy,
                    flags,
                    _reserved: r,
                }
            },
        )
}

/// A stream: arbitrary samples, or nearly-ordered ones (small seq and time steps, some
/// back) so gaps, duplicates and backwards time all occur.
fn stream() -> impl Strategy<Value = Vec<VelocitySample>> {
    prop_oneof![
        prop::collection::vec(any_sample(), 1..24),
        prop::collection::vec((any_sample(), -2i64..4, -2i64..4), 1..24).prop_map(|v| {
            let (mut seq, mut ts) = (1000u64, 1_000_000u64);
            v.into_iter()
                .map(|(mut s, ds, dt)| {
                    seq = seq.saturating_add_signed(ds);
                    ts = ts.saturating_add_signed(dt * 1000);
                    (s.seq, s.timestamp_ns) = (seq, ts);
                    s
                })
                .collect()
        }),
    ]
}

/// Every answer: a known status, the echo, NaN fields exactly when invalid, a heading
/// in [0, 360) otherwise.
fn check_answer(s: &VelocitySample, h: &HeadingEstimate) -> Result<(), TestCaseError> {
    prop_assert_eq!((h.seq, h.timestamp_ns), (s.seq, s.timestamp_ns));
    let status = h.heading_status();
    prop_assert!(
        matches!(
            status,
            Some(
                HeadingStatus::Ok
                    | HeadingStatus::LowSpeed
                    | HeadingStatus::Stationary
                    | HeadingStatus::Held
                    | HeadingStatus::InvalidInput
            )
        ),
        "{:?}",
        h
    );
    if status == Some(HeadingStatus::InvalidInput) {
        prop_assert!(
            h.heading_deg.is_nan() && h.heading_std_deg.is_nan(),
            "{:?}",
            h
        );
    } else {
        prop_assert!((0.0..360.0).contains(&h.heading_deg), "{:?} for {:?}", h, s);
        prop_assert!(h.heading_std_deg >= 0.0 && h.speed.is_finite(), "{:?}", h);
    }
    Ok(())
}

fn model() -> Arc<ghnet_inference::Model> {
    Arc::new(ghnet_inference::Model::builtin(ghnet_inference::DEFAULT_MODEL).unwrap())
}

/// A wire sample as ghnetd hands it to the rules (`V_DOWN_UNKNOWN`: no down velocity).
fn rules_view(s: &VelocitySample) -> Sample {
    Sample {
        seq: s.seq,
        t_s: s.timestamp_ns as f64 * 1e-9,
        v_north: s.v_north,
        v_east: s.v_east,
        v_down: [s.v_down, 0.0][usize::from(s.flags & flags::V_DOWN_UNKNOWN != 0)],
        speed_acc: s.speed_accuracy,
        flagged: s.flags & flags::INVALID != 0,
    }
}

/// A prediction: invalid with NaN heading and σ, or a heading in [0, 360).
fn check_prediction(s: &VelocitySample, p: &Prediction) -> Result<(), TestCaseError> {
    if p.status == Status::Invalid {
        prop_assert!(p.heading_deg.is_nan() && p.std_deg.is_nan(), "{:?}", p);
    } else {
        prop_assert!((0.0..360.0).contains(&p.heading_deg), "{:?} for {:?}", p, s);
        prop_assert!(p.std_deg >= 0.0 && p.speed.is_finite(), "{:?}", p);
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]

    /// The sample rules against a reference count of gaps, duplicates and backwards
    /// time (saturating, like the daemon).
    #[test]
    fn sample_rules_arbitrary_samples(samples in stream()) {
        let mut runner = Runner::new(model(), Default::default(), None);
        let mut src = runner.stream(None);
        let (mut gaps, mut dups, mut back, mut invalid) = (0u64, 0u64, 0u64, 0u64);
        let mut last: Option<Sample> = None;
        for s in &samples {
            let r = rules_view(s);
            let p = runner.answer(&mut src, &r);
            check_prediction(s, &p)?;
            let mut backwards = false;
            if let Some(l) = last {
                if r.seq > l.seq {
                    gaps = gaps.saturating_add(r.seq - l.seq - 1);
                } else {
                    dups += 1;
                }
                backwards = r.t_s < l.t_s;
            }
            back += u64::from(backwards);
            invalid += u64::from(p.status == Status::Invalid);
            if backwards {
                prop_assert_eq!(p.status, Status::Invalid);
            }
            last = Some(r);
        }
        let c = *src.counts();
        prop_assert_eq!(c.received, samples.len() as u64);
        prop_assert_eq!((c.gaps, c.duplicates, c.backwards, c.invalid), (gaps, dups, back, invalid));
        // A backwards reset needs a backwards sample, a restart a lower seq (a duplicate).
        prop_assert!(c.resets_backwards <= c.backwards && c.resets_restart <= c.duplicates);
        let r = src.history().expect("a stateful model").resets();
        prop_assert_eq!((r.gap, r.backwards, r.explicit), (c.resets_gap, c.resets_backwards, c.resets_restart));
    }
}

/// Arbitrary samples through a real ghnetd (in-process, real iceoryx2): one answer
/// per sample, then the daemon's own counters agree.
#[test]
fn daemon_answers_arbitrary_samples_exactly_once() {
    let mut daemon = InProcess::start("fuzz", |c| {
        c.sources.static_sources = vec!["f".into()];
        c.sources.discovery = false;
        c.zenoh.enabled = false;
    });
    let ipc = daemon.ipc();
    let headings = HeadingSubscriber::new(&ipc, "f").unwrap();
    let gnss = VelocityPublisher::new(&ipc, "f").unwrap();
    daemon.wait_serving(&gnss);

    let (sent, invalid) = (Cell::new(0u64), Cell::new(0u64));
    let mut runner = TestRunner::new(PtConfig {
        cases: 24,
        ..PtConfig::default()
    });
    runner
        .run(&stream(), |samples| {
            for s in &samples {
                gnss.send(*s).unwrap();
                sent.set(sent.get() + 1);
                // A Stale notice is not an answer (a loaded machine may pause).
                let h = next_answer(&headings);
                check_answer(s, &h)?;
                invalid.set(
                    invalid.get()
                        + u64::from(h.heading_status() == Some(HeadingStatus::InvalidInput)),
                );
            }
            Ok(())
        })
        .unwrap();

    let stats = daemon.stop();
    let c = stats.sources["f"];
    assert_eq!(c.received, sent.get(), "{c:?}");
    assert_eq!(c.received, c.answered + c.send_errors, "{c:?}");
    assert_eq!(c.send_errors, 0, "{c:?}");
    assert_eq!(c.invalid, invalid.get(), "{c:?}");
}
