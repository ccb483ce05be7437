//! Live and offline answers are the same: a tricky log published row by row into a
//! real ghnetd and run through `ghnet infer`'s library entry (`ghnet_lab::replay`)
//! gets the same status, heading and σ on every row, to the bit.
//!
//! The log has what real logs have: a drive with turns and a stop, rows without
//! speed accuracy, a repeated timestamp, time going backwards once, a NaN row and a
//! 15 s gap (longer than any stateful model's gap limit).

use std::sync::Arc;

use ghnet_client::{HeadingEstimate, HeadingStatus, VelocitySample};
use ghnet_inference::{Model, Prediction, Status};
use ghnet_lab::replay::{Answer, Rows, Streams};
use ghnet_testkit::{now_ns, recv_answer, OneSource, WATCHDOG};

/// Rows in the log.
const ROWS: usize = 420;

/// One row of the log: time (ns), velocity north/east (m/s), speed accuracy (NaN when
/// the receiver does not report it).
#[derive(Debug, Clone, Copy)]
struct Row {
    t_ns: u64,
    v_north: f32,
    v_east: f32,
    speed_acc: f32,
}

/// The tricky log, from `t0`: 2 Hz, a drive that turns, a stop from row 120 to 180,
/// every 23rd row without speed accuracy, row 200 half a second before row 199,
/// row 250 at row 249's time, a 15 s gap before row 300, a NaN velocity at row 350.
fn tricky_log(t0: u64) -> Vec<Row> {
    let mut t_ns = t0;
    (0..ROWS)
        .map(|i| {
            t_ns = match i {
                0 => t0,
                200 => t_ns - 500_000_000,
                250 => t_ns,
                300 => t_ns + 15_000_000_000,
                _ => t_ns + 500_000_000,
            };
            let x = i as f32;
            let speed = if (120..180).contains(&i) {
                0.02 * (x * 0.7).sin().abs()
            } else {
                6.0 + 2.0 * (x * 0.05).sin()
            };
            // A slow weave plus a little receiver noise.
            let course = (40.0 + 35.0 * (x * 0.03).sin() + 1.5 * (x * 2.1).sin()).to_radians();
            let (s, c) = course.sin_cos();
            let v_north = if i == 350 { f32::NAN } else { speed * c };
            let speed_acc = if i % 23 == 5 { f32::NAN } else { 0.15 };
            Row {
                t_ns,
                v_north,
                v_east: speed * s,
                speed_acc,
            }
        })
        .collect()
}

/// Every row through a real ghnetd running `model`, one sample in flight.
fn live(model: &str, log: &[Row]) -> Vec<HeadingEstimate> {
    let one = OneSource::start("liveoff", |b| b.model(model));
    log.iter()
        .enumerate()
        .map(|(seq, r)| {
            let mut s = VelocitySample::new(r.t_ns, seq as u64, r.v_north, r.v_east, 0.0);
            s.speed_accuracy = r.speed_acc;
            one.gnss.send(s).unwrap();
            let h = recv_answer(&one.headings, WATCHDOG).expect("an answer");
            assert_eq!(h.seq, s.seq, "answers in order");
            h
        })
        .collect()
}

/// Every row through `ghnet infer`'s answerer for stateful models, as the CSV reader
/// hands it over (time from `timestamp_ns`, one track).
fn offline(model: Arc<Model>, log: &[Row]) -> Vec<Prediction> {
    let mut rows = Rows::default();
    for r in log {
        rows.v_north.push(r.v_north);
        rows.v_east.push(r.v_east);
        rows.speed_acc.push(r.speed_acc);
        rows.t_s.push(r.t_ns as f64 * 1e-9);
        rows.track.push(0);
    }
    let mut out = vec![Prediction::INVALID; log.len()];
    Streams::new(model).answer(&rows, &mut out);
    out
}

/// The model's status and the wire status ghnetd answers it with.
const STATUSES: [(Status, HeadingStatus); 5] = [
    (Status::Ok, HeadingStatus::Ok),
    (Status::LowSpeed, HeadingStatus::LowSpeed),
    (Status::Stationary, HeadingStatus::Stationary),
    (Status::Invalid, HeadingStatus::InvalidInput),
    (Status::Held, HeadingStatus::Held),
];

/// The rows where the two disagree, described.
fn differences(live: &[HeadingEstimate], offline: &[Prediction]) -> Vec<String> {
    let same = |a: f32, b: f32| a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan());
    live.iter()
        .zip(offline)
        .enumerate()
        .filter(|(_, (h, p))| {
            let status = STATUSES
                .iter()
                .any(|&(m, w)| m == p.status && h.heading_status() == Some(w));
            let numbers = p.status == Status::Invalid
                || (same(h.heading_deg, p.heading_deg) && same(h.heading_std_deg, p.std_deg));
            !(status && numbers)
        })
        .map(|(i, (h, p))| {
            format!(
                "row {i}: live {:?} {:.4}° σ {:.4}° / offline {:?} {:.4}° σ {:.4}°",
                h.heading_status(),
                h.heading_deg,
                h.heading_std_deg,
                p.status,
                p.heading_deg,
                p.std_deg
            )
        })
        .collect()
}

/// The tricky log gets the same answer on every row live and offline, for the
/// shipped temporal model and for `kf`.
#[test]
fn live_and_offline_answer_every_row_alike() {
    let log = tricky_log(now_ns());
    for name in ["ghnet-temporal", "kf"] {
        let model = Arc::new(Model::builtin(name).unwrap());
        let (live, offline) = (live(name, &log), offline(model, &log));
        let diff = differences(&live, &offline);
        assert!(
            diff.is_empty(),
            "{name}: {} of {ROWS} rows differ:\n{}",
            diff.len(),
            diff.join("\n")
        );
        // The log exercises what it claims to: the backwards row and the NaN row are
        // refused, the stop is held.
        assert_eq!(
            live[200].heading_status(),
            Some(HeadingStatus::InvalidInput)
        );
        assert_eq!(
            live[350].heading_status(),
            Some(HeadingStatus::InvalidInput)
        );
        if name == "ghnet-temporal" {
            assert_eq!(live[170].heading_status(), Some(HeadingStatus::Held));
        }
    }
}
