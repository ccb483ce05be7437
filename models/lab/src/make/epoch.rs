//! How the per-epoch models are made and judged: data, head, scaling and
//! hyper-parameters for `paper-s1` and `ghnet-epoch`, their training run, and the
//! held-out evaluation of any model.
//!
//! A model file records in its `training_data` metadata which simulator, parameters and
//! seed produced it, so `ghnet eval --model X` regenerates exactly its held-out split
//! (test tracks or test grid points that training never saw) without shipping data.

use std::path::Path;
use std::sync::Arc;

use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};

use crate::bayes::BayesS1;
use crate::eval::{self, Estimate, EvalConfig, Report, Truth};
use crate::sim::{self, RealisticParams, S1Params, Sample, Split};
use crate::train::{self, Dataset, TrainConfig};
use ghnet_inference::head::Head;
use ghnet_inference::weights::{ModelMeta, FORMAT};
use ghnet_inference::Arch;
use ghnet_inference::{Model, Predictor};

/// Which simulator made a data set, with its parameters and seed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "sim", rename_all = "snake_case")]
#[allow(clippy::large_enum_variant)] // made once per command; boxing buys nothing
pub enum DataSpec {
    /// The paper's S1 grid.
    S1 {
        /// Grid and noise.
        params: S1Params,
        /// Seed of noise and split.
        seed: u64,
    },
    /// The realistic receiver over the full circle.
    Realistic {
        /// Trajectories and receiver behaviour.
        params: RealisticParams,
        /// Seed.
        seed: u64,
    },
}

impl DataSpec {
    /// Generate the samples (all splits).
    pub fn generate(&self) -> Vec<Sample> {
        match self {
            DataSpec::S1 { params, seed } => sim::simulate_s1(params, *seed),
            DataSpec::Realistic { params, seed } => sim::simulate_realistic(params, *seed),
        }
    }

    /// Short name for reports.
    pub fn label(&self) -> &'static str {
        match self {
            DataSpec::S1 { .. } => "S1",
            DataSpec::Realistic { .. } => "realistic",
        }
    }
}

/// Everything that defines a shipped model.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Recipe {
    /// Model name.
    pub name: String,
    /// Training data.
    pub data: DataSpec,
    /// Output head.
    pub head: Head,
    /// Input divisor, m/s.
    pub input_scale_mps: f32,
    /// Hyper-parameters.
    pub train: TrainConfig,
    /// Speed above which evaluation puts everything in one last bin, m/s.
    pub eval_max_speed: f64,
}

impl Recipe {
    /// A shipped recipe by model name.
    pub fn named(name: &str) -> Option<Recipe> {
        match name {
            "paper-s1" => Some(Recipe {
                name: name.into(),
                data: DataSpec::S1 {
                    params: S1Params::default(),
                    seed: 1,
                },
                head: Head::Blend {
                    centre_deg: 45.0,
                    half_range_deg: 45.0,
                },
                input_scale_mps: 3.5,
                train: TrainConfig {
                    epochs: 300,
                    batch: 256,
                    lr: 3e-3,
                    patience: 60,
                    ..TrainConfig::default()
                },
                eval_max_speed: 3.5,
            }),
            "ghnet-epoch" => Some(Recipe {
                name: name.into(),
                data: DataSpec::Realistic {
                    params: RealisticParams::default(),
                    seed: 1,
                },
                head: Head::Residual {
                    range_deg: [0.0, 360.0],
                },
                input_scale_mps: 5.0,
                train: TrainConfig {
                    epochs: 60,
                    batch: 256,
                    lr: 2e-3,
                    patience: 15,
                    ..TrainConfig::default()
                },
                eval_max_speed: 10.0,
            }),
            _ => None,
        }
    }

    /// Architecture: Table I with this head's outputs.
    pub fn arch(&self) -> Arch {
        Arch::paper(self.head.outputs())
    }
}

/// Split samples into training, validation and test sets.
///
/// Realistic data carries whole-track splits from the simulator. S1 marks only train and
/// test (the paper's 80/20); validation is every tenth training sample in simulator order,
/// which is a seeded random order.
pub fn split(samples: &[Sample]) -> (Dataset, Dataset, Vec<Sample>) {
    let (mut tr, mut va, mut te) = (Dataset::default(), Dataset::default(), Vec::new());
    let has_val = samples.iter().any(|s| s.split == Split::Val);
    let mut k = 0usize;
    for s in samples {
        match s.split {
            Split::Test => te.push(s.clone()),
            Split::Val => va.push(s.v_north, s.v_east, s.true_heading_deg, s.speed_acc),
            Split::Train => {
                k += 1;
                if !has_val && k.is_multiple_of(10) {
                    va.push(s.v_north, s.v_east, s.true_heading_deg, s.speed_acc);
                } else {
                    tr.push(s.v_north, s.v_east, s.true_heading_deg, s.speed_acc);
                }
            }
        }
    }
    (tr, va, te)
}

/// Heading and σ of `model` for every sample, through the batch path, using each
/// sample's reported speed accuracy as a deployed receiver would.
pub fn model_estimate(model: &std::sync::Arc<Model>, samples: &[Sample]) -> Estimate {
    let mut p = Predictor::new(model.clone());
    let vn: Vec<f32> = samples.iter().map(|s| s.v_north).collect();
    let ve: Vec<f32> = samples.iter().map(|s| s.v_east).collect();
    let acc: Vec<f32> = samples.iter().map(|s| s.speed_acc).collect();
    let mut out = vec![ghnet_inference::Prediction::INVALID; samples.len()];
    p.predict_batch_with_accuracy(&vn, &ve, &acc, &mut out);
    Estimate {
        name: model.name().to_string(),
        heading_deg: out.iter().map(|p| p.heading_deg).collect(),
        std_deg: Some(out.iter().map(|p| p.std_deg).collect()),
    }
}

/// Evaluate `model` on `test` with the baselines that apply: atan2, the prior-only
/// baseline (atan2 clipped to the model's heading range) and, for S1 data, the
/// Bayes-optimal estimate.
pub fn evaluate(
    model: &std::sync::Arc<Model>,
    data: &DataSpec,
    test: &[Sample],
    max_speed: f64,
) -> Result<Report, eval::EvalError> {
    let [lo, hi] = model.meta().heading_range_deg;
    let mut estimates = vec![Estimate::atan2(test)];
    let full_circle = hi - lo >= 360.0;
    if !full_circle {
        estimates.push(Estimate::prior_only(test, lo, hi));
    }
    if let DataSpec::S1 { params, .. } = data {
        estimates.push(BayesS1::new(params).estimates(test).median);
    }
    estimates.push(model_estimate(model, test));
    let cfg = EvalConfig {
        max_speed,
        ..EvalConfig::default()
    };
    eval::evaluate(&Truth::from_samples(test), &estimates, &cfg)
}

/// The per-epoch progress bar of `ghnet train` (hidden with `--quiet`).
fn progress_bar(quiet: bool, epochs: usize) -> indicatif::ProgressBar {
    let bar = if quiet {
        indicatif::ProgressBar::hidden()
    } else {
        indicatif::ProgressBar::new(epochs as u64)
    };
    bar.set_style(
        indicatif::ProgressStyle::with_template(
            "{elapsed_precise} [{bar:30}] epoch {pos}/{len} {msg}",
        )
        .expect("template")
        .progress_chars("=> "),
    );
    bar
}

/// `ghnet train --recipe paper-s1|ghnet-epoch`: generate the recipe's data, train, fit
/// the σ scales, measure on the held-out split and write the model with those metrics
/// in its metadata (so `ghnet info` shows them without the data).
pub fn train_recipe(r: &Recipe, output: &Path, quiet: bool) -> Result<()> {
    let t0 = std::time::Instant::now();
    let samples = r.data.generate();
    let (tr, va, test) = split(&samples);
    if tr.is_empty() || va.is_empty() || test.is_empty() {
        bail!(
            "recipe {} produced an empty train, validation or test split",
            r.name
        );
    }
    eprintln!(
        "{}: {} train, {} validation, {} test samples ({})",
        r.name,
        tr.len(),
        va.len(),
        test.len(),
        r.data.label()
    );
    let bar = progress_bar(quiet, r.train.epochs);
    let arch = r.arch();
    let trained = train::train(&arch, &r.head, r.input_scale_mps, &tr, &va, &r.train, |e| {
        bar.set_position(e.epoch as u64);
        bar.set_message(format!(
            "loss {:.4}  val {:.4} (MAE {:.3}°)  best MAE {:.3}°  lr {:.1e}",
            e.train_loss, e.val_loss, e.val_mae_deg, e.best_val_mae_deg, e.lr
        ));
        if quiet {
            eprintln!(
                "epoch {} loss {:.4} val {:.4} MAE {:.3} best MAE {:.3}",
                e.epoch, e.train_loss, e.val_loss, e.val_mae_deg, e.best_val_mae_deg
            );
        }
    });
    bar.finish();
    let (lo, hi) = r.head.range_deg();
    let mut meta = ModelMeta {
        format: FORMAT.into(),
        name: r.name.clone(),
        architecture: arch,
        activation: "gelu_tanh".into(),
        head: r.head,
        input_scale_mps: r.input_scale_mps,
        heading_range_deg: [lo, hi],
        sigma_scale: trained.sigma_scale,
        accuracy_sigma_scale: trained.accuracy_sigma_scale,
        training_data: serde_json::to_value(&r.data)?,
        training: serde_json::json!({
            "config": r.train,
            "best_epoch": trained.best_epoch,
            "epochs_run": trained.epochs_run,
            "best_val_mae_deg": trained.best_val_mae_deg,
            "train_samples": tr.len(),
            "val_samples": va.len(),
            "seconds": t0.elapsed().as_secs_f64(),
            "eval_max_speed": r.eval_max_speed,
        }),
        metrics: serde_json::Value::Null,
        kind: ghnet_inference::weights::ModelKind::Epoch,
    };
    // Measure on held-out data and store the headline numbers in the file itself.
    let (metrics, summary) = test_metrics(&trained.params, &meta, r, &test)?;
    meta.metrics = metrics;
    ghnet_inference::weights::write(output, &trained.params, &meta)
        .with_context(|| format!("writing {}", output.display()))?;
    eprintln!(
        "{}: best epoch {} of {}, {summary}, {:.0} s -> {}",
        r.name,
        trained.best_epoch,
        trained.epochs_run,
        t0.elapsed().as_secs_f64(),
        output.display()
    );
    Ok(())
}

/// A per-epoch model's metrics on its recipe's `test` samples (for its metadata) and a
/// one-line summary.
fn test_metrics(
    params: &ghnet_inference::params::ParamSet,
    meta: &ModelMeta,
    r: &Recipe,
    test: &[crate::sim::Sample],
) -> Result<(serde_json::Value, String)> {
    let model = Arc::new(Model::new(params.clone(), meta.clone()));
    let report = evaluate(&model, &r.data, test, r.eval_max_speed)?;
    let overall = report
        .overall
        .stats_of(&r.name)
        .context("model missing from its own report")?;
    let atan2 = report.overall.stats_of(eval::ATAN2).map(|s| s.mae_deg);
    let metrics = serde_json::json!({
        "test_samples": test.len(),
        "mae_deg": overall.mae_deg,
        "rmse_deg": overall.rmse_deg,
        "within_1sigma": overall.within_1sigma,
        "within_2sigma": overall.within_2sigma,
        "atan2_mae_deg": atan2,
    });
    let summary = format!(
        "test MAE {:.3}° (atan2 {:.3}°), within 1σ {:.1}%, 2σ {:.1}%",
        overall.mae_deg,
        atan2.unwrap_or(f64::NAN),
        100.0 * overall.within_1sigma.unwrap_or(f64::NAN),
        100.0 * overall.within_2sigma.unwrap_or(f64::NAN),
    );
    Ok((metrics, summary))
}
