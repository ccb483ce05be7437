//! How the temporal model and the Kalman filter baseline are made and judged: the
//! `ghnet-temporal` recipe (simulated drives, the Kalman filter tuned on their
//! validation tracks, the network trained on their training tracks), training on users'
//! own logs (`ghnet train --data`), and the tables `ghnet eval` prints for both.

use std::path::Path;
use std::sync::Arc;

use anyhow::{bail, Result};
use serde::{Deserialize, Serialize};

use ghnet_models::weights::ModelKind;
use ghnet_models::Model;

use crate::drive::{self, DriveParams, Platform};
use crate::logs::{self, LogTrack};
use crate::sim::Split;
use crate::streval::{self, Table};
use crate::temporal::{self, TemporalConfig, TrainedTemporal};

/// Everything that defines the shipped temporal model and `kf`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TemporalRecipe {
    /// Model name.
    pub name: String,
    /// The drives.
    pub data: DriveParams,
    /// Seed of the drives.
    pub seed: u64,
    /// Training.
    pub train: TemporalConfig,
}

impl TemporalRecipe {
    /// The shipped recipe.
    pub fn shipped() -> Self {
        Self {
            name: "ghnet-temporal".into(),
            // 300 drives, 60 of them for validation (the σ maps and the model choice
            // need many direction changes to be stable) and 60 for test.
            data: DriveParams {
                tracks: 300,
                val_fraction: 0.2,
                test_fraction: 0.2,
                ..DriveParams::default()
            },
            seed: 1,
            train: TemporalConfig::default(),
        }
    }

    /// A temporal recipe by model name: `ghnet-temporal` (the shipped default: cars and
    /// turn-in-place platforms, 70/30, one model for both), `ghnet-temporal-car` (cars
    /// only) and `ghnet-temporal-tip` (turn-in-place platforms only), for measuring what
    /// one model for both costs.
    pub fn named(name: &str) -> Option<Self> {
        let share = match name {
            "ghnet-temporal" => DriveParams::default().platform_share,
            "ghnet-temporal-car" => 0.0,
            "ghnet-temporal-tip" => 1.0,
            _ => return None,
        };
        let mut r = Self::shipped();
        r.name = name.into();
        r.data.platform_share = share;
        Some(r)
    }

    /// Simulated tracks by split.
    pub fn tracks(&self) -> [Vec<LogTrack>; 3] {
        split_tracks(&drive::simulate(&self.data, self.seed))
    }
}

/// Simulated tracks as (train, validation, test) logs.
pub fn split_tracks(tracks: &[drive::Track]) -> [Vec<LogTrack>; 3] {
    let pick = |s: Split| {
        tracks
            .iter()
            .filter(|t| t.split == s)
            .map(LogTrack::from)
            .collect::<Vec<_>>()
    };
    [pick(Split::Train), pick(Split::Val), pick(Split::Test)]
}

/// Tracks of one platform.
pub fn only(tracks: &[LogTrack], p: Platform) -> Vec<LogTrack> {
    tracks
        .iter()
        .filter(|t| t.platform == Some(p))
        .cloned()
        .collect()
}

/// The Kalman filter tuned on `val`, as a model.
pub fn tuned_kf(val: &[LogTrack], max_gap_s: f32) -> (Model, f64) {
    let (q, sv, mae) = streval::tune_kf(val, max_gap_s);
    let mut m = streval::kf_model(q, sv, max_gap_s);
    let meta = {
        let mut meta = m.meta().clone();
        meta.training = serde_json::json!({
            "tuned_on": "validation tracks of the ghnet-temporal recipe (simulated drives)",
            "val_mae_deg": mae,
            "grid": "q in 0.5..120 deg/sqrt(s), sigma_v in 0.03..4 m/s",
        });
        meta
    };
    m = Model::new(m.params().clone(), meta);
    (m, mae)
}

/// Train with `progress` lines on stderr.
pub fn train_logged(
    name: &str,
    tr: &[LogTrack],
    va: &[LogTrack],
    kf: &Arc<Model>,
    init: Option<&Model>,
    cfg: &TemporalConfig,
) -> Result<TrainedTemporal> {
    let t0 = std::time::Instant::now();
    let n: usize = tr.iter().map(LogTrack::len).sum();
    let nv: usize = va.iter().map(LogTrack::len).sum();
    eprintln!(
        "{name}: {} training tracks ({n} epochs), {} validation ({nv})",
        tr.len(),
        va.len()
    );
    temporal::train(name, tr, va, kf, init, cfg, |e, loss, mae, best| {
        eprintln!(
            "epoch {e} loss {loss:.4} val MAE {mae:.3}° best {best:.3}° ({:.0} s)",
            t0.elapsed().as_secs_f64()
        );
    })
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
            let mut answers = vec![streval::run_atan2(&g)];
            answers.extend(streval::run_receiver(&g));
            answers.push(streval::run_model(kf, &g, "kf"));
            answers.push(streval::run_model(model, &g, model.name()));
            let moved =
                start_gate(model, kf).map(|(sv, gap)| streval::after_first_motion(&g, sv, gap));
            streval::table(&title, &g, &answers, moved.as_deref())
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

/// Read several logs with truth and split them by time for training.
pub fn read_logs(
    paths: &[impl AsRef<Path>],
    val_fraction: f64,
) -> Result<(Vec<LogTrack>, Vec<LogTrack>)> {
    let mut all = Vec::new();
    for p in paths {
        let (t, s) = logs::read_csv(p.as_ref(), true)?;
        if s.skipped > 0 {
            eprintln!(
                "{}: skipped {} of {} rows",
                p.as_ref().display(),
                s.skipped,
                s.rows
            );
        }
        all.extend(t);
    }
    if all.is_empty() {
        bail!("no rows with velocity, time and truth");
    }
    Ok(logs::time_split(&all, val_fraction))
}

/// The gap limit of a stateful model (10 s for others).
pub fn max_gap(m: &Model) -> f32 {
    m.meta().kind.max_gap_s().unwrap_or(10.0)
}

/// Whether `m` is the Kalman filter.
pub fn is_kf(m: &Model) -> bool {
    matches!(m.meta().kind, ModelKind::Kf { .. })
}
