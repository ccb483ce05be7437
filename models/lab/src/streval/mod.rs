//! Streamed evaluation on tracks: every estimator runs over each track in order, as
//! ghnetd would run it, and errors are tabulated per speed band with stops as their own
//! band. The baselines are in every table: atan2, the Kalman filter (tuned on
//! validation data, never on the data in the table), and the receiver's own frozen
//! course where the simulator recorded it.

use std::sync::Arc;

use serde::Serialize;

use ghnet_inference::stream::{Epoch, StreamPredictor};
use ghnet_inference::weights::ModelKind;
use ghnet_inference::{Model, Status};

use crate::drive::Platform;
use crate::eval::wrap_deg;
use crate::logs::LogTrack;
use crate::table::{fmt_opt, Markdown, Tally};

mod held;
use held::held_moving;
pub use held::HELD_MOVING_SPEED;

/// Name of the atan2 baseline in tables.
pub const ATAN2: &str = "atan2";
/// Name of the receiver's frozen course in tables.
pub const RECEIVER: &str = "receiver course";

/// Speed bands, m/s: `[lo, hi)`; the first is "stopped".
pub const BANDS: [(f32, f32); 7] = [
    (0.0, 0.05),
    (0.05, 0.5),
    (0.5, 1.0),
    (1.0, 2.0),
    (2.0, 5.0),
    (5.0, 10.0),
    (10.0, f32::INFINITY),
];

/// Turn-rate bands of the turn table, °/s (from the truth heading): `[lo, hi)`.
pub const TURN_BANDS: [(f32, f32); 5] = [
    (0.0, 0.5),
    (0.5, 1.5),
    (1.5, 4.0),
    (4.0, 10.0),
    (10.0, f32::INFINITY),
];

/// Speed (m/s) from which epochs enter the turn table: slower, the speed itself sets
/// the error, and the speed table shows it.
pub const TURN_MIN_SPEED: f32 = 2.0;

/// Longest epoch interval (s) over which a truth heading change is read as a turn
/// rate (longer ones are gaps).
const TURN_MAX_DT: f64 = 1.5;

/// Measured speed below which a log without true speed counts as stopped: receiver noise
/// alone reads 0.05–0.2 m/s.
pub const STOPPED_MEASURED: f32 = 0.2;

/// One estimator's answers over a set of tracks, concatenated.
#[derive(Debug, Clone, Serialize)]
pub struct Answers {
    /// Name in tables.
    pub name: String,
    /// Heading, degrees.
    pub heading_deg: Vec<f32>,
    /// 1σ, degrees (None for estimators without one).
    pub std_deg: Option<Vec<f32>>,
    /// Status per epoch (models only).
    #[serde(skip)]
    pub status: Vec<Status>,
}

/// Stream `model` over every track (a fresh history per track).
pub fn run_model(model: &Arc<Model>, tracks: &[LogTrack], name: &str) -> Answers {
    let mut sp = StreamPredictor::new(model.clone());
    let mut a = Answers {
        name: name.into(),
        heading_deg: Vec::new(),
        std_deg: Some(Vec::new()),
        status: Vec::new(),
    };
    for t in tracks {
        let mut h = sp.history();
        for i in 0..t.len() {
            let p = sp.predict(
                &mut h,
                &Epoch {
                    t_s: t.t_s[i],
                    v_north: t.v_north[i],
                    v_east: t.v_east[i],
                    speed_acc: t.speed_acc[i],
                },
            );
            a.heading_deg.push(p.heading_deg);
            a.std_deg.as_mut().expect("σ").push(p.std_deg);
            a.status.push(p.status);
        }
    }
    a
}

/// atan2 of the measured velocity.
pub fn run_atan2(tracks: &[LogTrack]) -> Answers {
    Answers {
        name: ATAN2.into(),
        heading_deg: tracks
            .iter()
            .flat_map(|t| {
                (0..t.len()).map(|i| crate::eval::atan2_heading_deg(t.v_north[i], t.v_east[i]))
            })
            .collect(),
        std_deg: None,
        status: Vec::new(),
    }
}

/// The receiver's frozen course, when every track has it.
pub fn run_receiver(tracks: &[LogTrack]) -> Option<Answers> {
    let h: Vec<f32> = tracks
        .iter()
        .flat_map(|t| t.receiver_course_deg.iter().copied())
        .collect();
    h.iter().all(|v| v.is_finite()).then(|| Answers {
        name: RECEIVER.into(),
        heading_deg: h,
        std_deg: None,
        status: Vec::new(),
    })
}

/// Mean absolute wrapped error of `a` over `tracks`, degrees.
pub fn mae(a: &Answers, tracks: &[LogTrack]) -> f64 {
    let truth = tracks.iter().flat_map(|t| t.truth_deg.iter());
    let (s, n) = a
        .heading_deg
        .iter()
        .zip(truth)
        .fold((0.0f64, 0usize), |(s, n), (h, t)| {
            (s + wrap_deg(h - t).abs() as f64, n + 1)
        });
    s / n.max(1) as f64
}

/// One estimator in one band.
#[derive(Debug, Clone, Serialize)]
pub struct Cell {
    /// Mean absolute wrapped error, degrees.
    pub mae_deg: f64,
    /// Share of errors within 1σ (estimators with σ).
    pub within_1sigma: Option<f64>,
    /// Share within 2σ.
    pub within_2sigma: Option<f64>,
}

/// One band's row.
#[derive(Debug, Clone, Serialize)]
pub struct Row {
    /// Band label.
    pub label: String,
    /// Epochs in the band.
    pub count: usize,
    /// One cell per estimator, in the table's order.
    pub cells: Vec<Cell>,
    /// The longest run of `Held` answers of the last estimator among the row's epochs
    /// at a measured speed of [`HELD_MOVING_SPEED`] or faster, seconds (each epoch
    /// counts until the next, at most its track's usual interval): a stop that outlives
    /// the motion, the failure a filter fusing held headings cannot see. `None` for an
    /// estimator without status.
    pub held_moving_s: Option<f64>,
}

/// A table: rows per band plus "all".
#[derive(Debug, Clone, Serialize)]
pub struct Table {
    /// What the table is about.
    pub title: String,
    /// Estimator names.
    pub names: Vec<String>,
    /// Bands, then "all", then (when known) "after first motion".
    pub rows: Vec<Row>,
    /// Epochs at [`TURN_MIN_SPEED`] or faster per [`TURN_BANDS`] band of the truth's
    /// turn rate: whether σ is honest in turns as well as on straights (a filter that
    /// fuses the heading trusts it most where a car turns).
    pub turn_rows: Vec<Row>,
    /// Whether bands use true speed (simulated) or measured speed (logs without it).
    pub true_speed: bool,
    /// How the last estimator's errors carry from epoch to epoch, and spread per drive
    /// (models with σ and status).
    pub memory: Option<Memory>,
}

/// How a stateful model's errors carry over time, which a filter fusing its answers
/// must know: the tables count every epoch as one, but a held stop repeats one error
/// for its whole length, and a moving answer shares part of its error with the next.
/// Also how widely one drive's σ coverage spreads around the pooled one.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Memory {
    /// Pairs of `Ok` epochs [`MEMORY_LAG_S`] apart.
    pub pairs: usize,
    /// Correlation of the signed error over σ between the two epochs of a pair.
    pub correlation: f64,
    /// Stops answered `Held`: runs of held epochs within a track.
    pub stops: usize,
    /// Epochs in those stops.
    pub held_epochs: usize,
    /// Share of stops whose (one) error is within the σ of their first held epoch.
    pub stops_within_1sigma: f64,
    /// The same within 2σ.
    pub stops_within_2sigma: f64,
    /// Per drive (track) with at least [`MIN_DRIVE_EPOCHS`] epochs, the share within
    /// 1σ: 10th, 50th and 90th percentile over drives, when there are
    /// [`MIN_DRIVES`] or more. The tables pool every drive; one user has one receiver,
    /// one antenna mounting and one route, so their share lands anywhere in this spread.
    pub drives_within_1sigma: Option<[f64; 3]>,
    /// The same within 2σ.
    pub drives_within_2sigma: Option<[f64; 3]>,
    /// Drives counted in the percentiles.
    pub drives: usize,
    /// Of those, the drives within both bars ([`DRIVE_BAR_1SIGMA`], [`DRIVE_BAR_2SIGMA`]):
    /// how often one user's log meets them, which the pooled shares do not say.
    pub drives_within_bars: usize,
}

/// The bar on a log's share within 1σ (60–76%): σ neither too wide nor too narrow.
pub const DRIVE_BAR_1SIGMA: std::ops::RangeInclusive<f64> = 0.60..=0.76;
/// The bar on a log's share within 2σ (at least 90%): the tails covered.
pub const DRIVE_BAR_2SIGMA: f64 = 0.90;

/// Fewest epochs a drive needs to count in [`Memory::drives_within_1sigma`].
pub const MIN_DRIVE_EPOCHS: usize = 100;
/// Fewest drives for the per-drive percentiles.
pub const MIN_DRIVES: usize = 10;

/// Lag (s) at which [`Memory::correlation`] is measured: the rate an INS filter is
/// usually fed at, and the shared real drive's epoch.
pub const MEMORY_LAG_S: f64 = 1.0;

impl Table {
    /// The "all" row's MAE of estimator `name`.
    pub fn overall(&self, name: &str) -> Option<f64> {
        self.row("**all**", name).map(|c| c.mae_deg)
    }

    /// The "after first motion" row's MAE of estimator `name`.
    pub fn after_motion(&self, name: &str) -> Option<f64> {
        self.row("after first motion", name).map(|c| c.mae_deg)
    }

    /// Estimator `name`'s cell in the row labelled `label`.
    pub fn row(&self, label: &str, name: &str) -> Option<&Cell> {
        let k = self.names.iter().position(|n| n == name)?;
        Some(&self.rows.iter().find(|r| r.label == label)?.cells[k])
    }
}

/// The [`Cell`] of `a` over the epochs `idx`, counted by the table engine.
fn cell(a: &Answers, truth: &[f32], idx: &[usize]) -> Cell {
    let mut t = Tally::default();
    for &i in idx {
        let err = wrap_deg(a.heading_deg[i] - truth[i]) as f64;
        t.add(err, a.std_deg.as_ref().map(|s| s[i] as f64));
    }
    let t = t.stats(&a.name, a.std_deg.is_some());
    Cell {
        mae_deg: t.mae_deg,
        within_1sigma: t.within_1sigma,
        within_2sigma: t.within_2sigma,
    }
}

/// The row `label` over the epochs `idx` (of `tracks`, concatenated): a cell per
/// estimator and the last estimator's longest `Held` run while moving.
fn row(
    label: String,
    idx: &[usize],
    tracks: &[LogTrack],
    answers: &[Answers],
    truth: &[f32],
) -> Row {
    Row {
        label,
        count: idx.len(),
        cells: answers.iter().map(|a| cell(a, truth, idx)).collect(),
        held_moving_s: answers
            .last()
            .and_then(|a| held_moving(tracks, &a.status, idx)),
    }
}

/// Per epoch of `tracks` (concatenated): whether its history has seen motion, i.e.
/// an epoch whose speed passes the Kalman filter's measurement gate (`|v|² > 2σ_v²`,
/// σ_v of the tuned `kf`), with the history rules of `max_gap_s`. Before that, nothing
/// knows a parked vehicle's heading and every stateful model answers the first
/// epoch's course (the shared start convention; the temporal model starts earlier only
/// on a long steady creep, `ghnet_inference::modes::START_S`), so tables also show the
/// MAE after it.
pub fn after_first_motion(tracks: &[LogTrack], sigma_v: f32, max_gap_s: f32) -> Vec<bool> {
    let cap = ghnet_inference::head::MAX_STD_DEG.to_radians();
    // The gate of `ghnet_inference::modes::prepare`: σ_v/ŝ under the uniform σ.
    let gate = sigma_v * sigma_v * (2.0 + 1.0 / (cap * cap));
    let mut out = Vec::new();
    for t in tracks {
        let (mut moved, mut first) = (false, true);
        for i in 0..t.len() {
            if i > 0 {
                let dt = t.t_s[i] - t.t_s[i - 1];
                if dt < 0.0 || dt > max_gap_s as f64 {
                    (moved, first) = (false, true);
                }
            }
            let s2 = t.v_north[i] * t.v_north[i] + t.v_east[i] * t.v_east[i];
            // A history's first epoch only sets the course; the gate counts after it.
            moved |= !first && s2 > gate;
            first = false;
            out.push(moved);
        }
    }
    out
}

/// Tabulate `answers` on `tracks` per band; `moved` (per epoch, from
/// [`after_first_motion`]) adds a last row over the epochs after the first motion.
pub fn table(
    title: &str,
    tracks: &[LogTrack],
    answers: &[Answers],
    moved: Option<&[bool]>,
) -> Table {
    let truth: Vec<f32> = tracks
        .iter()
        .flat_map(|t| t.truth_deg.iter().copied())
        .collect();
    let true_speed = tracks
        .iter()
        .all(|t| t.true_speed.iter().all(|s| s.is_finite()));
    let speed: Vec<f32> = tracks
        .iter()
        .flat_map(|t| (0..t.len()).map(move |i| t.bin_speed(i)))
        .collect();
    let stop = if true_speed {
        BANDS[0].1
    } else {
        STOPPED_MEASURED
    };
    let mut rows = Vec::new();
    for (b, &(lo, hi)) in BANDS.iter().enumerate() {
        let (lo, hi) = match b {
            0 => (lo, stop),
            1 => (stop, hi),
            _ => (lo, hi),
        };
        let idx: Vec<usize> = (0..speed.len())
            .filter(|&i| speed[i] >= lo && speed[i] < hi)
            .collect();
        let label = match b {
            0 => format!("stopped (<{stop})"),
            _ if hi.is_infinite() => format!("≥{lo}"),
            _ => format!("{lo}–{hi}"),
        };
        rows.push(row(label, &idx, tracks, answers, &truth));
    }
    let all: Vec<usize> = (0..truth.len()).collect();
    rows.push(row("**all**".into(), &all, tracks, answers, &truth));
    if let Some(m) = moved {
        let after: Vec<usize> = (0..truth.len()).filter(|&i| m[i]).collect();
        rows.push(row(
            "after first motion".into(),
            &after,
            tracks,
            answers,
            &truth,
        ));
    }
    Table {
        title: title.into(),
        names: answers.iter().map(|a| a.name.clone()).collect(),
        rows,
        turn_rows: turn_rows(tracks, answers, &truth, &speed),
        true_speed,
        memory: answers.last().and_then(|a| memory(tracks, a, &truth)),
    }
}

/// [`Memory`] of `a` (concatenated over `tracks`); `None` without σ or status.
fn memory(tracks: &[LogTrack], a: &Answers, truth: &[f32]) -> Option<Memory> {
    let std = a.std_deg.as_ref()?;
    if a.status.len() != truth.len() {
        return None;
    }
    let z = |i: usize| wrap_deg(a.heading_deg[i] - truth[i]) as f64 / std[i] as f64;
    let ok = |i: usize| a.status[i] == Status::Ok;
    let (mut pairs, mut start) = (Vec::new(), 0);
    // Each stop's first held epoch (its one error and σ), and the epochs held.
    let (mut stops, mut held_epochs) = (Vec::new(), 0);
    let mut drives = Vec::new();
    for t in tracks {
        if t.len() >= MIN_DRIVE_EPOCHS {
            let idx: Vec<usize> = (start..start + t.len()).collect();
            drives.push(cell(a, truth, &idx));
        }
        // The epoch `MEMORY_LAG_S` later (within a tenth of a second), if any.
        let mut j = 0;
        for i in 0..t.len() {
            while j < t.len() && t.t_s[j] < t.t_s[i] + MEMORY_LAG_S - 0.05 {
                j += 1;
            }
            let later = j < t.len() && t.t_s[j] <= t.t_s[i] + MEMORY_LAG_S + 0.05;
            if later && ok(start + i) && ok(start + j) {
                pairs.push((z(start + i), z(start + j)));
            }
            if a.status[start + i] == Status::Held {
                held_epochs += 1;
                if i == 0 || a.status[start + i - 1] != Status::Held {
                    stops.push(start + i);
                }
            }
        }
        start += t.len();
    }
    let per_stop = cell(a, truth, &stops);
    let spread =
        |share: fn(&Cell) -> Option<f64>| percentiles(drives.iter().filter_map(share).collect());
    let within_bars = |c: &Cell| match (c.within_1sigma, c.within_2sigma) {
        (Some(s1), Some(s2)) => DRIVE_BAR_1SIGMA.contains(&s1) && s2 >= DRIVE_BAR_2SIGMA,
        _ => false,
    };
    Some(Memory {
        pairs: pairs.len(),
        correlation: correlation(&pairs),
        stops: stops.len(),
        held_epochs,
        stops_within_1sigma: per_stop.within_1sigma?,
        stops_within_2sigma: per_stop.within_2sigma?,
        drives_within_1sigma: spread(|c| c.within_1sigma),
        drives_within_2sigma: spread(|c| c.within_2sigma),
        drives: drives.len(),
        drives_within_bars: drives.iter().filter(|c| within_bars(c)).count(),
    })
}

/// 10th, 50th and 90th percentile of `v`, linear between ranks (numpy's default: the
/// median of an even count is the mean of the middle two); `None` under
/// [`MIN_DRIVES`].
fn percentiles(mut v: Vec<f64>) -> Option<[f64; 3]> {
    if v.len() < MIN_DRIVES {
        return None;
    }
    v.sort_by(f64::total_cmp);
    let at = |q: f64| {
        let h = q * (v.len() - 1) as f64;
        let (lo, hi) = (h.floor() as usize, h.ceil() as usize);
        v[lo] + (h - lo as f64) * (v[hi] - v[lo])
    };
    Some([at(0.1), at(0.5), at(0.9)])
}

/// Pearson correlation of the pairs (NaN for fewer than two or no spread).
fn correlation(pairs: &[(f64, f64)]) -> f64 {
    let n = pairs.len() as f64;
    let (mx, my) = pairs
        .iter()
        .fold((0.0, 0.0), |(x, y), p| (x + p.0 / n, y + p.1 / n));
    let (mut sxy, mut sxx, mut syy) = (0.0, 0.0, 0.0);
    for (x, y) in pairs {
        sxy += (x - mx) * (y - my);
        sxx += (x - mx) * (x - mx);
        syy += (y - my) * (y - my);
    }
    if pairs.len() < 2 || sxx <= 0.0 || syy <= 0.0 {
        return f64::NAN;
    }
    sxy / (sxx * syy).sqrt()
}

/// Rows of the turn table: per [`TURN_BANDS`] band, the epochs at
/// [`TURN_MIN_SPEED`] or faster whose truth turned at that rate since the track's
/// previous epoch (at most [`TURN_MAX_DT`] earlier).
fn turn_rows(tracks: &[LogTrack], answers: &[Answers], truth: &[f32], speed: &[f32]) -> Vec<Row> {
    let mut rate = Vec::with_capacity(truth.len());
    for t in tracks {
        for i in 0..t.len() {
            let dt = if i > 0 { t.t_s[i] - t.t_s[i - 1] } else { 0.0 };
            rate.push(if dt > 0.0 && dt <= TURN_MAX_DT {
                wrap_deg(t.truth_deg[i] - t.truth_deg[i - 1]).abs() / dt as f32
            } else {
                f32::NAN
            });
        }
    }
    TURN_BANDS
        .iter()
        .map(|&(lo, hi)| {
            let idx: Vec<usize> = (0..truth.len())
                .filter(|&i| speed[i] >= TURN_MIN_SPEED && rate[i] >= lo && rate[i] < hi)
                .collect();
            let label = if hi.is_infinite() {
                format!("≥{lo}")
            } else {
                format!("{lo}–{hi}")
            };
            row(label, &idx, tracks, answers, truth)
        })
        .collect()
}

/// The tables of `model` against the baselines on `tracks` (one per platform present
/// and one for all). `kf` is the filter of every table, except the turn-in-place table
/// when `kf_platform` (a filter tuned on such platforms) is given.
pub fn tables(
    model: &Arc<Model>,
    kf: &Arc<Model>,
    kf_platform: Option<&Arc<Model>>,
    tracks: &[LogTrack],
    what: &str,
) -> Vec<Table> {
    let mut groups: Vec<(String, Vec<LogTrack>, &Arc<Model>)> = Vec::new();
    for (p, label) in [
        (Platform::Car, "cars"),
        (Platform::TurnInPlace, "turn-in-place platforms"),
    ] {
        let g = only(tracks, p);
        if !g.is_empty() && g.len() < tracks.len() {
            let f = match p {
                Platform::TurnInPlace => kf_platform.unwrap_or(kf),
                Platform::Car => kf,
            };
            groups.push((format!("{what}, {label}"), g, f));
        }
    }
    groups.push((what.to_owned(), tracks.to_vec(), kf));
    groups
        .into_iter()
        .map(|(title, g, kf)| {
            let mut answers = vec![run_atan2(&g)];
            answers.extend(run_receiver(&g));
            answers.push(run_model(kf, &g, "kf"));
            answers.push(run_model(model, &g, model.name()));
            let moved = start_gate(model, kf).map(|(sv, gap)| after_first_motion(&g, sv, gap));
            table(&title, &g, &answers, moved.as_deref())
        })
        .collect()
}

/// The start convention's gate (σ_v, gap limit) of a table: the temporal model's own
/// (the σ_v of the `kf` it was made with), else `kf`'s.
fn start_gate(model: &Model, kf: &Model) -> Option<(f32, f32)> {
    [model, kf].iter().find_map(|m| match m.meta().kind {
        ModelKind::Temporal {
            sigma_v_mps,
            max_gap_s,
            ..
        }
        | ModelKind::Kf {
            sigma_v_mps,
            max_gap_s,
            ..
        } => Some((sigma_v_mps, max_gap_s)),
        ModelKind::Epoch => None,
    })
}

/// Tracks of one platform.
pub fn only(tracks: &[LogTrack], p: Platform) -> Vec<LogTrack> {
    tracks
        .iter()
        .filter(|t| t.platform == Some(p))
        .cloned()
        .collect()
}

/// Whether `m` is the Kalman filter.
pub fn is_kf(m: &Model) -> bool {
    matches!(m.meta().kind, ModelKind::Kf { .. })
}

/// The table as Markdown: MAE per estimator, the last estimator against atan2 and
/// against the second-to-last (the Kalman filter, by convention), its σ calibration and
/// its longest `Held` run while moving ([`Row::held_moving_s`]); then the same columns
/// per turn rate (see [`Table::turn_rows`]).
pub fn to_markdown(t: &Table) -> String {
    let speed = format!(
        "{} speed [m/s]",
        if t.true_speed { "True" } else { "Measured" }
    );
    let mut s = rows_markdown(t, &speed, &t.rows);
    if t.turn_rows.iter().any(|r| r.count > 0) {
        s += "\n";
        s += &rows_markdown(
            t,
            &format!("Turn rate [°/s], {TURN_MIN_SPEED} m/s and faster"),
            &t.turn_rows,
        );
    }
    if let Some(m) = &t.memory {
        s += &memory_markdown(t.names.last().map_or("", |n| n.as_str()), m);
    }
    s
}

/// The [`Memory`] line under a table.
fn memory_markdown(name: &str, m: &Memory) -> String {
    let mut s = format!("\nError memory of {name}");
    if m.pairs > 1 {
        s += &format!(
            ": error/σ of an `Ok` answer correlates {:.2} with the answer {MEMORY_LAG_S} s later \
             ({} pairs)",
            m.correlation, m.pairs
        );
    }
    if m.stops > 0 {
        s += &format!(
            "; {} stops held ({} epochs), one error each: {:.1}% / {:.1}% of stops within \
             1σ / 2σ",
            m.stops,
            m.held_epochs,
            100.0 * m.stops_within_1sigma,
            100.0 * m.stops_within_2sigma
        );
    }
    if let (Some(a), Some(b)) = (m.drives_within_1sigma, m.drives_within_2sigma) {
        let pct = |p: [f64; 3]| {
            format!(
                "{:.0} / {:.0} / {:.0}%",
                100.0 * p[0],
                100.0 * p[1],
                100.0 * p[2]
            )
        };
        s += &format!(
            ".\n\nPer drive, {name} ({} drives, 10th / 50th / 90th percentile): {} within 1σ, {} \
             within 2σ; {} of {} drives within both bars ({:.0}–{:.0}% within 1σ, at least {:.0}% \
             within 2σ)",
            m.drives,
            pct(a),
            pct(b),
            m.drives_within_bars,
            m.drives,
            100.0 * DRIVE_BAR_1SIGMA.start(),
            100.0 * DRIVE_BAR_1SIGMA.end(),
            100.0 * DRIVE_BAR_2SIGMA
        );
    }
    s + ".\n"
}

/// One Markdown table of `rows` with the columns of `t`, first column `first`.
fn rows_markdown(t: &Table, first: &str, rows: &[Row]) -> String {
    let last = t.names.len() - 1;
    let kf = t.names.iter().position(|n| n.starts_with("kf"));
    let mut header = vec![first.to_owned(), "N".to_owned()];
    header.extend(t.names.iter().map(|n| format!("MAE {n}")));
    header.push(format!("{} vs atan2 [%]", t.names[last]));
    if kf.is_some() {
        header.push(format!("{} vs kf [%]", t.names[last]));
    }
    header.extend([
        "≤1σ [%]".to_owned(),
        "≤2σ [%]".to_owned(),
        format!("longest `Held` at ≥{HELD_MOVING_SPEED} m/s [s]"),
    ]);
    let mut table = Markdown::new(&header, true);
    for r in rows {
        let mut cells = vec![r.label.clone(), r.count.to_string()];
        cells.extend(r.cells.iter().map(|c| format!("{:.2}", c.mae_deg)));
        let m = r.cells[last].mae_deg;
        let gain = |b: f64| if b > 0.0 { 100.0 * (b - m) / b } else { 0.0 };
        cells.push(format!("{:.1}", gain(r.cells[0].mae_deg)));
        if let Some(k) = kf {
            cells.push(format!("{:.1}", gain(r.cells[k].mae_deg)));
        }
        let pct = |v: Option<f64>| v.map_or("".into(), |v| format!("{:.1}", 100.0 * v));
        cells.push(pct(r.cells[last].within_1sigma));
        cells.push(pct(r.cells[last].within_2sigma));
        cells.push(fmt_opt(r.held_moving_s, 1));
        table.row(&cells);
    }
    table.finish()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 1 Hz track of `n` epochs pointing north at 5 m/s (only time and truth matter).
    fn track(n: usize) -> LogTrack {
        LogTrack::north_at(&vec![5.0; n])
    }

    /// A held stop counts once however long it is, runs split by a track boundary are
    /// two stops, and `Ok` answers 1 s apart that err alike correlate fully.
    #[test]
    fn memory_counts_stops_once_and_correlates_successive_errors() {
        use Status::{Held, Ok};
        let tracks = [track(8), track(3)];
        // σ 2°: the first stop (3 epochs, 1° off) is within 1σ; the held run across the
        // track boundary (1 + 2 epochs, 5° off) is two stops, both outside 2σ.
        let heading = [1.0, 2.0, 3.0, 1.0, 1.0, 1.0, 3.0, 5.0, 5.0, 5.0, 5.0];
        let status = [Ok, Ok, Ok, Held, Held, Held, Ok, Held, Held, Held, Ok];
        let a = Answers {
            name: "m".into(),
            heading_deg: heading.to_vec(),
            std_deg: Some(vec![2.0; 11]),
            status: status.to_vec(),
        };
        let m = memory(&tracks, &a, &[0.0; 11]).expect("σ and status");
        assert_eq!((m.stops, m.held_epochs), (3, 6), "{m:?}");
        assert!((m.stops_within_1sigma - 1.0 / 3.0).abs() < 1e-9, "{m:?}");
        assert!((m.stops_within_2sigma - 1.0 / 3.0).abs() < 1e-9, "{m:?}");
        // Ok pairs 1 s apart: (1°, 2°) and (2°, 3°): perfectly correlated.
        assert_eq!(m.pairs, 2);
        assert!((m.correlation - 1.0).abs() < 1e-9, "{m:?}");
        let without = Answers { std_deg: None, ..a };
        assert!(memory(&tracks, &without, &[0.0; 11]).is_none());
        assert_eq!(
            (m.drives, m.drives_within_1sigma),
            (0, None),
            "short tracks"
        );
    }

    /// Per drive: the 10th / 50th / 90th percentile of each drive's share within 1σ and
    /// 2σ, over drives long enough to count.
    #[test]
    fn memory_spreads_coverage_per_drive() {
        let tracks: Vec<LogTrack> = (0..11)
            .map(|k| track(if k == 10 { 50 } else { 100 }))
            .collect();
        // Drive k errs 3° (σ 2°: outside 1σ, inside 2σ) on its first 10·k epochs; the
        // eleventh is too short to count.
        let heading: Vec<f32> = tracks
            .iter()
            .enumerate()
            .flat_map(|(k, t)| (0..t.len()).map(move |i| if i < 10 * k { 3.0 } else { 1.0 }))
            .collect();
        let n = heading.len();
        let a = Answers {
            name: "m".into(),
            heading_deg: heading,
            std_deg: Some(vec![2.0; n]),
            status: vec![Status::Ok; n],
        };
        let m = memory(&tracks, &a, &vec![0.0; n]).expect("σ and status");
        assert_eq!(m.drives, 10);
        let p = m.drives_within_1sigma.expect("ten drives");
        // Shares 0.1, 0.2, …, 1.0: ranks 0.9, 4.5 and 8.1 of 0–9.
        for (got, want) in p.iter().zip([0.19, 0.55, 0.91]) {
            assert!((got - want).abs() < 1e-9, "{p:?}");
        }
        assert_eq!(m.drives_within_2sigma, Some([1.0; 3]));
        // Shares 0.6 and 0.7 within 1σ (drives 4 and 3) meet both bars; 0.8 and over do
        // not, nor 0.5 and under.
        assert_eq!(m.drives_within_bars, 2);
    }
}
