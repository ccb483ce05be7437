//! The temporal model's recipe: simulated drives, the Kalman filter tuned on their
//! validation tracks, the network trained on their training tracks and judged on their
//! test tracks; and refitting a temporal model's σ maps on its recipe's tracks.

use std::path::Path;
use std::sync::Arc;

use anyhow::{Context, Result};
use serde::{Deserialize, Serialize};

use ghnet_inference::weights::{ModelKind, ModelMeta};
use ghnet_inference::Model;

use super::kf::tuned_kf;
use crate::drive::{self, DriveParams, Platform};
use crate::logs::LogTrack;
use crate::sim::Split;
use crate::streval::{self, only};
use crate::temporal::{self, MapName, TemporalConfig, TrainedTemporal};

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
    /// The recipe a temporal model was trained from, as its metadata names it
    /// (`training_data`): its tracks regenerate the model's held-out split.
    pub fn of(model: &Model) -> Result<Self> {
        serde_json::from_value(model.meta().training_data.clone())
            .context("the model's metadata names no temporal recipe")
    }

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

/// `ghnet train --recipe ghnet-temporal`: simulate, tune `kf` on validation tracks
/// (written beside the output as `kf.safetensors`), train, judge on test tracks.
pub fn train_temporal_recipe(
    name: &str,
    output: &Path,
    seed: Option<u64>,
    epochs: Option<usize>,
    config: Option<&str>,
) -> Result<()> {
    let t0 = std::time::Instant::now();
    let mut r = TemporalRecipe::named(name).context("not a temporal recipe")?;
    if let Some(c) = config {
        r.train = merged(&r.train, c)?;
    }
    if let Some(s) = seed {
        r.train.seed = s;
    }
    if let Some(e) = epochs {
        r.train.epochs = e;
    }
    let [tr, va, te] = r.tracks();
    // The shipped kf is tuned on all validation tracks of the recipe (one filter for
    // every platform, like the model); platform tables also show a filter tuned on their
    // own kind of validation tracks.
    let cars = only(&va, Platform::Car);
    let tips = only(&va, Platform::TurnInPlace);
    let (kf, kf_mae) = tuned_kf(&va, r.train.max_gap_s);
    eprintln!(
        "kf tuned on all validation tracks: {:?} (val MAE {kf_mae:.2}°)",
        kf.meta().kind
    );
    let (kf_p, kf_p_mae) = tuned_kf(
        if tips.is_empty() { &cars } else { &tips },
        r.train.max_gap_s,
    );
    eprintln!(
        "kf tuned on platform validation tracks: {:?} (val MAE {kf_p_mae:.2}°)",
        kf_p.meta().kind
    );
    let kf = Arc::new(with_data(&kf, &r)?);
    let kf_path = output.with_file_name("kf.safetensors");
    std::fs::write(&kf_path, kf.to_safetensors())
        .with_context(|| format!("writing {}", kf_path.display()))?;
    let trained = train_logged(&r.name, &tr, &va, &kf, None, &r.train)?;
    let model = Arc::new(with_data(&trained.model, &r)?);
    let tables = streval::tables(
        &model,
        &kf,
        Some(&Arc::new(kf_p)),
        &te,
        "held-out simulated tracks",
    );
    for t in &tables {
        println!("### {}\n\n{}", t.title, streval::to_markdown(t));
    }
    let meta = shipped_meta(
        &model,
        &trained,
        &tables,
        &r.train,
        t0.elapsed().as_secs_f64(),
    );
    let out = Model::new(model.params().clone(), meta);
    std::fs::write(output, out.to_safetensors())
        .with_context(|| format!("writing {}", output.display()))?;
    eprintln!(
        "{}: best epoch {} of {}, {:.0} s -> {} and {}",
        r.name,
        trained.best_epoch,
        trained.epochs_run,
        t0.elapsed().as_secs_f64(),
        output.display(),
        kf_path.display()
    );
    Ok(())
}

/// `ghnet calibrate`: refit the σ maps of a temporal model (those in `maps`, keeping
/// the others) on the training and validation tracks of the recipe it names, headings
/// unchanged (what training does last, without training again).
pub fn calibrate_recipe_model(model: &str, output: &Path, maps: &[MapName]) -> Result<()> {
    let m = Model::from_name_or_path(model)?;
    let [tr, va, _] = TemporalRecipe::of(&m)?.tracks();
    let both: Vec<_> = tr.into_iter().chain(va).collect();
    let out = crate::temporal::calibrate_maps(m.params().clone(), m.meta().clone(), &both, maps);
    std::fs::write(output, out.to_safetensors())
        .with_context(|| format!("writing {}", output.display()))?;
    eprintln!("wrote {}", output.display());
    Ok(())
}

/// The trained model's metadata with its training run and its test metrics (overall and
/// after the first motion) written in.
fn shipped_meta(
    model: &Model,
    trained: &crate::temporal::TrainedTemporal,
    tables: &[streval::Table],
    cfg: &TemporalConfig,
    seconds: f64,
) -> ModelMeta {
    let mut meta = model.meta().clone();
    meta.training = serde_json::json!({
        "config": cfg,
        "best_epoch": trained.best_epoch,
        "epochs_run": trained.epochs_run,
        "best_val_mae_deg": trained.best_val_mae_deg,
        "seconds": seconds,
    });
    meta.metrics = held_out_metrics(model, tables);
    meta
}

/// The held-out metrics a temporal model stores (`models/lab/tests/shipped.rs` checks
/// them): test epochs and mean absolute error overall and after the first motion, of
/// the model, `kf` and atan2, from the tables streamed over its recipe's test tracks
/// ([`held_out_tables`]).
pub fn held_out_metrics(model: &Model, tables: &[streval::Table]) -> serde_json::Value {
    let all = tables.last().expect("an 'all' table");
    serde_json::json!({
        "test_epochs": all.rows.iter().find(|r| r.label == "**all**").map(|r| r.count),
        "mae_deg": all.overall(model.name()),
        "kf_mae_deg": all.overall("kf"),
        "atan2_mae_deg": all.overall(streval::ATAN2),
        "after_first_motion": {
            "mae_deg": all.after_motion(model.name()),
            "kf_mae_deg": all.after_motion("kf"),
            "atan2_mae_deg": all.after_motion(streval::ATAN2),
        },
    })
}

/// The tables of a temporal model streamed over its recipe's test tracks against the
/// shipped `kf`: what [`held_out_metrics`] reads.
pub fn held_out_tables(model: &Arc<Model>) -> Result<Vec<streval::Table>> {
    let kf = Arc::new(Model::from_name_or_path("kf")?);
    let [_, _, test] = TemporalRecipe::of(model)?.tracks();
    Ok(streval::tables(
        model,
        &kf,
        None,
        &test,
        "held-out simulated tracks",
    ))
}

/// `ghnet restamp`: recompute the held-out metrics a temporal model stores, streamed
/// over its recipe's test tracks against the shipped `kf`, and write the model with
/// them, weights unchanged. A change to the mode filter's rules moves what the shipped
/// network streams without training it again; this keeps the stored numbers (and the
/// test that checks them) in step.
pub fn restamp_recipe_model(model: &str, output: &Path) -> Result<()> {
    let model = Arc::new(Model::from_name_or_path(model)?);
    if !matches!(model.meta().kind, ModelKind::Temporal { .. }) {
        anyhow::bail!(
            "{} is not a temporal model: only those store these metrics",
            model.name()
        );
    }
    let tables = held_out_tables(&model)?;
    let mut meta = model.meta().clone();
    meta.metrics = held_out_metrics(&model, &tables);
    let out = Model::new(model.params().clone(), meta);
    std::fs::write(output, out.to_safetensors())
        .with_context(|| format!("writing {}", output.display()))?;
    eprintln!("wrote {} with {}", output.display(), out.meta().metrics);
    Ok(())
}

/// `cfg` with the JSON object `json` merged into it (nested objects key by key).
fn merged(cfg: &TemporalConfig, json: &str) -> Result<TemporalConfig> {
    fn merge(a: &mut serde_json::Value, b: serde_json::Value) {
        match (a, b) {
            (serde_json::Value::Object(a), serde_json::Value::Object(b)) => {
                for (k, v) in b {
                    merge(a.entry(k).or_insert(serde_json::Value::Null), v);
                }
            }
            (a, b) => *a = b,
        }
    }
    let mut v = serde_json::to_value(cfg)?;
    merge(
        &mut v,
        serde_json::from_str(json).context("--config is not JSON")?,
    );
    serde_json::from_value(v).context("--config does not fit the training configuration")
}

/// `m` with the recipe as its `training_data`, so `ghnet eval` can regenerate the test
/// tracks.
fn with_data(m: &Model, r: &TemporalRecipe) -> Result<Model> {
    let mut meta = m.meta().clone();
    meta.training_data = serde_json::to_value(r)?;
    Ok(Model::new(m.params().clone(), meta))
}
