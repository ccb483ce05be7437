//! Tracks of epochs with truth, whatever made them: the drive simulator or a user's CSV
//! log. Training (`ghnet train --data`), evaluation (`ghnet eval --data`) and the tables
//! all read [`LogTrack`]s, so a simulated drive and a real one are judged the same way.
//!
//! CSV columns (a header row; other columns are ignored): `v_north`, `v_east` (m/s,
//! required); time as `t_s` (seconds) or `timestamp_ns`; `speed_acc` (1σ, m/s; empty,
//! NaN or negative = unknown); `truth_heading_deg` (required for training and
//! evaluation); `track` (rows with another value start another history; rows stay in
//! file order); optionally `true_speed` and `receiver_course_deg` (simulated files have
//! them). Rows whose velocity, time or truth does not parse are skipped and counted.

use std::path::Path;

use anyhow::{bail, Context, Result};

use crate::drive::{Platform, Track};

/// One history's epochs, in order, with truth.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct LogTrack {
    /// Value of the `track` column (or the simulator's track id).
    pub key: String,
    /// Platform, when known (simulated tracks).
    pub platform: Option<Platform>,
    /// Time, s.
    pub t_s: Vec<f64>,
    /// North velocity, m/s.
    pub v_north: Vec<f32>,
    /// East velocity, m/s.
    pub v_east: Vec<f32>,
    /// Speed accuracy, m/s; NaN unknown.
    pub speed_acc: Vec<f32>,
    /// True heading, degrees.
    pub truth_deg: Vec<f32>,
    /// True speed, m/s; NaN when the log has none (then the measured speed bins).
    pub true_speed: Vec<f32>,
    /// The receiver's frozen course, degrees; NaN when not simulated.
    pub receiver_course_deg: Vec<f32>,
}

impl LogTrack {
    /// Number of epochs.
    pub fn len(&self) -> usize {
        self.t_s.len()
    }

    /// True when empty.
    pub fn is_empty(&self) -> bool {
        self.t_s.is_empty()
    }

    /// The speed that bins this epoch: the true one where known, else the measured one.
    pub fn bin_speed(&self, i: usize) -> f32 {
        let s = self.true_speed[i];
        if s.is_finite() {
            s
        } else {
            self.v_north[i].hypot(self.v_east[i])
        }
    }

    /// A 1 Hz log heading north at `speeds` (m/s; measured as true, no sAcc), the
    /// fixture of tests that need time, speed and truth only.
    #[cfg(test)]
    pub(crate) fn north_at(speeds: &[f32]) -> LogTrack {
        let n = speeds.len();
        LogTrack {
            key: "0".into(),
            platform: None,
            t_s: (0..n).map(|i| i as f64).collect(),
            v_north: speeds.to_vec(),
            v_east: vec![0.0; n],
            speed_acc: vec![f32::NAN; n],
            truth_deg: vec![0.0; n],
            true_speed: speeds.to_vec(),
            receiver_course_deg: vec![f32::NAN; n],
        }
    }

    /// Epochs `range` as a track of their own (the same key).
    pub fn slice(&self, r: std::ops::Range<usize>) -> LogTrack {
        LogTrack {
            key: self.key.clone(),
            platform: self.platform,
            t_s: self.t_s[r.clone()].to_vec(),
            v_north: self.v_north[r.clone()].to_vec(),
            v_east: self.v_east[r.clone()].to_vec(),
            speed_acc: self.speed_acc[r.clone()].to_vec(),
            truth_deg: self.truth_deg[r.clone()].to_vec(),
            true_speed: self.true_speed[r.clone()].to_vec(),
            receiver_course_deg: self.receiver_course_deg[r].to_vec(),
        }
    }
}

impl From<&Track> for LogTrack {
    fn from(t: &Track) -> Self {
        let s = &t.samples;
        LogTrack {
            key: t.id.to_string(),
            platform: Some(t.platform),
            t_s: s.iter().map(|x| x.t_s).collect(),
            v_north: s.iter().map(|x| x.v_north).collect(),
            v_east: s.iter().map(|x| x.v_east).collect(),
            speed_acc: s.iter().map(|x| x.speed_acc).collect(),
            truth_deg: s.iter().map(|x| x.truth_heading_deg).collect(),
            true_speed: s.iter().map(|x| x.true_speed).collect(),
            receiver_course_deg: s.iter().map(|x| x.receiver_course_deg).collect(),
        }
    }
}

/// The drives `p` simulates with `seed`, as logs (test material for the fits).
#[cfg(test)]
pub(crate) fn simulated(p: &crate::drive::DriveParams, seed: u64) -> Vec<LogTrack> {
    crate::drive::simulate(p, seed)
        .iter()
        .map(LogTrack::from)
        .collect()
}

/// The columns every log this crate writes starts with, in order (what
/// [`read_csv`] needs to train and evaluate on it).
pub const LOG_COLUMNS: [&str; 6] = [
    "t_s",
    "track",
    "v_north",
    "v_east",
    "speed_acc",
    "truth_heading_deg",
];

/// Write simulated tracks as one CSV in the log format (plus `platform`, `receiver`,
/// `rate_hz`, `reversing`, `split`).
pub fn write_tracks_csv(path: &Path, tracks: &[Track]) -> Result<()> {
    let mut w = csv::Writer::from_path(path).with_context(|| format!("{}", path.display()))?;
    w.write_record(LOG_COLUMNS.iter().chain(&[
        "true_speed",
        "receiver_course_deg",
        "reversing",
        "platform",
        "receiver",
        "rate_hz",
        "split",
    ]))?;
    for t in tracks {
        let meta = [
            serde_json::to_value(t.platform)?,
            serde_json::to_value(t.receiver)?,
            serde_json::to_value(t.split)?,
        ]
        .map(|v| v.as_str().unwrap_or_default().to_owned());
        for s in &t.samples {
            w.write_record([
                format!("{:.1}", s.t_s),
                t.id.to_string(),
                s.v_north.to_string(),
                s.v_east.to_string(),
                s.speed_acc.to_string(),
                format!("{:.3}", s.truth_heading_deg),
                format!("{:.3}", s.true_speed),
                format!("{:.3}", s.receiver_course_deg),
                (s.reversing as u8).to_string(),
                meta[0].clone(),
                meta[1].clone(),
                t.rate_hz.to_string(),
                meta[2].clone(),
            ])?;
        }
    }
    w.flush()?;
    Ok(())
}

/// A CSV cell for `v`, empty when it is unknown (NaN or infinite): how the logs this
/// crate writes leave out a missing value, which [`read_csv`] reads back as NaN.
pub(crate) fn cell_or_empty(v: f32) -> String {
    if v.is_finite() {
        v.to_string()
    } else {
        String::new()
    }
}

/// Writes `tracks` as a CSV log (`t_s`, `track`, `v_north`, `v_east`, `speed_acc`
/// empty when unknown, `truth_heading_deg`, and `true_speed` when the log had it), the
/// format `ghnet eval --data` reads.
pub fn write_log_csv(path: &Path, tracks: &[LogTrack]) -> Result<()> {
    let mut w = csv::Writer::from_path(path).with_context(|| format!("{}", path.display()))?;
    let speed = tracks
        .iter()
        .any(|t| t.true_speed.iter().any(|s| s.is_finite()));
    let mut header = LOG_COLUMNS.to_vec();
    if speed {
        header.push("true_speed");
    }
    w.write_record(&header)?;
    for t in tracks {
        for i in 0..t.len() {
            let mut rec = vec![
                t.t_s[i].to_string(),
                t.key.clone(),
                t.v_north[i].to_string(),
                t.v_east[i].to_string(),
                cell_or_empty(t.speed_acc[i]),
                t.truth_deg[i].to_string(),
            ];
            if speed {
                rec.push(cell_or_empty(t.true_speed[i]));
            }
            w.write_record(&rec)?;
        }
    }
    w.flush()?;
    Ok(())
}

/// What [`read_csv`] skipped.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ReadSummary {
    /// Rows read.
    pub rows: usize,
    /// Rows skipped (velocity, time or required truth not a number).
    pub skipped: usize,
}

fn field(rec: &csv::StringRecord, i: Option<usize>) -> f64 {
    i.and_then(|i| rec.get(i))
        .and_then(|s| s.trim().parse::<f64>().ok())
        .unwrap_or(f64::NAN)
}

/// Read a log with truth, as training and evaluation do ([`read_csv`]), and say on
/// stderr how many rows were skipped: a user whose log loses rows should see it, not
/// find it in a smaller table.
pub fn read_truth_csv(path: &Path) -> Result<Vec<LogTrack>> {
    let (tracks, s) = read_csv(path, true)?;
    if s.skipped > 0 {
        eprintln!(
            "{}: skipped {} of {} rows",
            path.display(),
            s.skipped,
            s.rows
        );
    }
    Ok(tracks)
}

/// Read a log: one [`LogTrack`] per run of equal `track` values, in file order.
/// `need_truth` makes `truth_heading_deg` required (training, evaluation).
pub fn read_csv(path: &Path, need_truth: bool) -> Result<(Vec<LogTrack>, ReadSummary)> {
    let mut r = csv::ReaderBuilder::new()
        .flexible(true)
        .from_path(path)
        .with_context(|| format!("cannot open {}", path.display()))?;
    let header = r.headers()?.clone();
    let col = |n: &str| header.iter().position(|h| h.trim() == n);
    let (Some(i_n), Some(i_e)) = (col("v_north"), col("v_east")) else {
        bail!("{}: need `v_north` and `v_east` columns", path.display());
    };
    let (i_t, i_ns) = (col("t_s"), col("timestamp_ns"));
    if i_t.is_none() && i_ns.is_none() {
        bail!(
            "{}: need a time column, `t_s` or `timestamp_ns`",
            path.display()
        );
    }
    let i_truth = col("truth_heading_deg");
    if need_truth && i_truth.is_none() {
        bail!("{}: need a `truth_heading_deg` column", path.display());
    }
    let (i_acc, i_track) = (col("speed_acc"), col("track"));
    let (i_speed, i_course) = (col("true_speed"), col("receiver_course_deg"));
    let mut tracks: Vec<LogTrack> = Vec::new();
    let mut sum = ReadSummary::default();
    for rec in r.records() {
        let rec = rec?;
        sum.rows += 1;
        let t = match i_t {
            Some(_) => field(&rec, i_t),
            None => field(&rec, i_ns) * 1e-9,
        };
        let (vn, ve, truth) = (
            field(&rec, Some(i_n)),
            field(&rec, Some(i_e)),
            field(&rec, i_truth),
        );
        if !(t.is_finite() && vn.is_finite() && ve.is_finite())
            || (need_truth && !truth.is_finite())
        {
            sum.skipped += 1;
            continue;
        }
        let key = i_track
            .and_then(|i| rec.get(i))
            .unwrap_or("")
            .trim()
            .to_owned();
        if tracks.last().is_none_or(|l| l.key != key) {
            tracks.push(LogTrack {
                key,
                ..LogTrack::default()
            });
        }
        let tr = tracks.last_mut().expect("pushed");
        let acc = field(&rec, i_acc);
        tr.t_s.push(t);
        tr.v_north.push(vn as f32);
        tr.v_east.push(ve as f32);
        tr.speed_acc
            .push(if acc > 0.0 { acc as f32 } else { f32::NAN });
        tr.truth_deg.push(truth as f32);
        tr.true_speed.push(field(&rec, i_speed) as f32);
        tr.receiver_course_deg.push(field(&rec, i_course) as f32);
    }
    Ok((tracks, sum))
}

/// Split every track by time: the first `1 − val_fraction` of each track's epochs to
/// training, the rest to validation (a held-out future, never shuffled).
pub fn time_split(tracks: &[LogTrack], val_fraction: f64) -> (Vec<LogTrack>, Vec<LogTrack>) {
    let (mut tr, mut va) = (Vec::new(), Vec::new());
    for t in tracks {
        let cut = ((1.0 - val_fraction) * t.len() as f64).round() as usize;
        if cut > 0 {
            tr.push(t.slice(0..cut));
        }
        if cut < t.len() {
            va.push(t.slice(cut..t.len()));
        }
    }
    (tr, va)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// What [`write_log_csv`] writes, [`read_csv`] reads back as the same log.
    #[test]
    fn a_written_log_reads_back() {
        let n = 50;
        let tracks = vec![LogTrack {
            key: "a".into(),
            platform: None,
            t_s: (0..n).map(|i| i as f64).collect(),
            v_north: (0..n).map(|i| 0.013 * i as f32 - 0.2).collect(),
            v_east: (0..n).map(|i| 0.1 - 0.007 * i as f32).collect(),
            speed_acc: vec![f32::NAN; n],
            truth_deg: vec![90.0; n],
            true_speed: vec![f32::NAN; n],
            receiver_course_deg: vec![f32::NAN; n],
        }];
        let dir = std::env::temp_dir().join(format!("ghnet-logs-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("log.csv");
        write_log_csv(&path, &tracks).unwrap();
        let (back, summary) = read_csv(&path, true).unwrap();
        std::fs::remove_dir_all(&dir).unwrap();
        assert_eq!(summary.skipped, 0);
        assert_eq!(back[0].v_north, tracks[0].v_north);
        assert_eq!(back[0].t_s, tracks[0].t_s);
        assert!(back[0].speed_acc.iter().all(|a| a.is_nan()));
    }
}
