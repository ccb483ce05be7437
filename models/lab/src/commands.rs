//! The `ghnet` subcommands of temporal models: the `ghnet-temporal` recipe, training on
//! users' logs, and streamed evaluation.

use std::path::Path;
use std::sync::Arc;

use anyhow::{bail, Context, Result};

use ghnet_lab::drive::Platform;
use ghnet_lab::plot::{plot_heading_timeline, Series};
use ghnet_lab::temporal::TemporalConfig;
use ghnet_lab::timeline::{self, TemporalRecipe};
use ghnet_lab::train::{self, Dataset, TrainConfig};
use ghnet_lab::{ownlogs, streval};
use ghnet_models::head::Head;
use ghnet_models::weights::{ModelMeta, FORMAT};
use ghnet_models::{Arch, Model};

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
    let cars = timeline::only(&va, Platform::Car);
    let tips = timeline::only(&va, Platform::TurnInPlace);
    let (kf, kf_mae) = timeline::tuned_kf(&va, r.train.max_gap_s);
    eprintln!(
        "kf tuned on all validation tracks: {:?} (val MAE {kf_mae:.2}°)",
        kf.meta().kind
    );
    let (kf_p, kf_p_mae) = timeline::tuned_kf(
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
    let trained = timeline::train_logged(&r.name, &tr, &va, &kf, None, &r.train)?;
    let model = Arc::new(with_data(&trained.model, &r)?);
    let tables = timeline::tables(
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

/// `ghnet calibrate`: refit the σ maps of a temporal model on the training and
/// validation tracks of the recipe it names, headings unchanged (what training does
/// last, without training again).
pub fn calibrate_recipe_model(model: &str, output: &Path) -> Result<()> {
    let m = Model::from_name_or_path(model)?;
    let r: TemporalRecipe = serde_json::from_value(m.meta().training_data.clone())
        .context("the model's metadata names no temporal recipe")?;
    let [tr, va, _] = r.tracks();
    let both: Vec<_> = tr.into_iter().chain(va).collect();
    let out = ghnet_lab::temporal::calibrate(m.params().clone(), m.meta().clone(), &both);
    std::fs::write(output, out.to_safetensors())
        .with_context(|| format!("writing {}", output.display()))?;
    eprintln!("wrote {}", output.display());
    Ok(())
}

/// The trained model's metadata with its training run and its test metrics (overall and
/// after the first motion) written in.
fn shipped_meta(
    model: &Model,
    trained: &ghnet_lab::temporal::TrainedTemporal,
    tables: &[streval::Table],
    cfg: &TemporalConfig,
    seconds: f64,
) -> ModelMeta {
    let all = tables.last().expect("an 'all' table");
    let mut meta = model.meta().clone();
    meta.training = serde_json::json!({
        "config": cfg,
        "best_epoch": trained.best_epoch,
        "epochs_run": trained.epochs_run,
        "best_val_mae_deg": trained.best_val_mae_deg,
        "seconds": seconds,
    });
    meta.metrics = serde_json::json!({
        "test_epochs": all.rows.iter().find(|r| r.label == "**all**").map(|r| r.count),
        "mae_deg": all.overall(model.name()),
        "kf_mae_deg": all.overall("kf"),
        "atan2_mae_deg": all.overall(streval::ATAN2),
        "after_first_motion": {
            "mae_deg": all.after_motion(model.name()),
            "kf_mae_deg": all.after_motion("kf"),
            "atan2_mae_deg": all.after_motion(streval::ATAN2),
        },
    });
    meta
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

/// The shipped `kf`, the baseline of every streamed table.
fn builtin_kf() -> Result<Arc<Model>> {
    Ok(Arc::new(Model::builtin("kf").context(
        "no built-in kf: run `ghnet train --recipe ghnet-temporal` first",
    )?))
}

/// `ghnet train --data ...`: the shipped model (or `--init`) fitted to the user's logs.
/// First what depends on the platform and the receiver (the mode filter's constants,
/// [`ghnet_lab::ownlogs::fit_modes`]) on the training part, kept only if the held-out
/// part (the last 20% of each track) agrees; then the network fine-tuned and the σ maps
/// fitted; the result is written only if it beats the starting model on the held-out
/// part (else the starting model is, with a note). A log of minutes cannot train the
/// network from scratch, so the starting model is never random.
pub fn train_data(
    paths: &[impl AsRef<Path>],
    output: &Path,
    init: Option<&str>,
    range: Option<(f32, f32)>,
    seed: Option<u64>,
    epochs: Option<usize>,
    platform: Option<ghnet_models::Platform>,
) -> Result<()> {
    let (tr, va) = timeline::read_logs(paths, 0.2)?;
    if let Some((lo, hi)) = range {
        return train_restricted(&tr, &va, output, lo, hi, seed, epochs);
    }
    let base = Model::from_name_or_path(init.unwrap_or(ghnet_models::DEFAULT_MODEL))?;
    let (cfg, kf) = own_config(&base, &tr, &va, platform)?;
    let cfg = TemporalConfig {
        seed: seed.unwrap_or(cfg.seed),
        epochs: epochs.unwrap_or(cfg.epochs),
        ..cfg
    };
    let name = output
        .file_stem()
        .and_then(|s| s.to_str())
        .unwrap_or("ghnet-custom")
        .to_owned();
    let n: usize = tr.iter().map(|t| t.len()).sum();
    let trained = if n >= MIN_FINE_TUNE_EPOCHS {
        timeline::train_logged(&name, &tr, &va, &kf, Some(&base), &cfg)?.model
    } else {
        eprintln!(
            "{n} training epochs (fewer than {MIN_FINE_TUNE_EPOCHS}): the network and its σ maps \
             stay as they are, only the mode filter is fitted"
        );
        ownlogs::with_modes(&base, cfg.modes)
    };
    let base_va = ownlogs::mae_with(&base, ownlogs::modes_of(&base), &va);
    let new_va = ownlogs::mae_with(&trained, cfg.modes, &va);
    eprintln!(
        "held-out part: {new_va:.2}° fitted against {base_va:.2}° for {} as it is",
        base.name()
    );
    let model = if new_va <= base_va {
        trained
    } else {
        eprintln!(
            "the fitted model is worse on the held-out part: writing {} unchanged",
            base.name()
        );
        base
    };
    // Named after the output, whatever it came from: consumers tell models by name.
    let mut meta = model.meta().clone();
    meta.name = name;
    let model = Arc::new(Model::new(model.params().clone(), meta));
    for t in timeline::tables(
        &model,
        &kf,
        None,
        &va,
        "validation (last 20% of each track)",
    ) {
        println!("### {}\n\n{}", t.title, streval::to_markdown(&t));
    }
    std::fs::write(output, model.to_safetensors())
        .with_context(|| format!("writing {}", output.display()))?;
    eprintln!("wrote {}", output.display());
    Ok(())
}

/// Fewest training epochs for `ghnet train --data` to fine-tune the network and refit
/// its σ maps: on less (about 13 minutes at 5 Hz) the held-out part that
/// judges the result is too small to tell a better network from a luckier one (on
/// half of the shared real drive, 442 epochs at 1 Hz, a fine-tune that won on its
/// validation part lost on the other half).
const MIN_FINE_TUNE_EPOCHS: usize = 4000;

/// The training configuration of `ghnet train --data` from the starting model `base`:
/// its window, gap limit, start convention (its `kf`) and σ choices, and the mode
/// filter's constants fitted to `tr` (kept if `va` agrees), each change printed.
fn own_config(
    base: &Model,
    tr: &[ghnet_lab::logs::LogTrack],
    va: &[ghnet_lab::logs::LogTrack],
    platform: Option<ghnet_models::Platform>,
) -> Result<(TemporalConfig, Arc<Model>)> {
    let ghnet_models::weights::ModelKind::Temporal {
        max_gap_s,
        q_deg_per_sqrt_s,
        sigma_v_mps,
        modes,
        sigma_map,
    } = base.meta().kind
    else {
        bail!("--init {}: not a temporal model", base.name());
    };
    let t0 = std::time::Instant::now();
    let fitted = ownlogs::fit_modes(base, tr, platform);
    let before = ownlogs::mae_with(base, modes, va);
    let after = ownlogs::mae_with(base, fitted.modes, va);
    eprintln!(
        "mode filter fitted in {:.1} s: training part {:.2}° → {:.2}°, held-out part {before:.2}° → {after:.2}°",
        t0.elapsed().as_secs_f64(),
        fitted.mae_before,
        fitted.mae_after
    );
    let mut chosen = if after <= before { fitted.modes } else { modes };
    if after > before {
        eprintln!("  kept the model's constants: the held-out part does not confirm the fit");
    } else if fitted.changes.is_empty() {
        eprintln!("  no constant changed");
    }
    for c in fitted.changes.iter().filter(|_| after <= before) {
        eprintln!("  {c}");
    }
    if let Some(p) = platform {
        chosen.platform = p;
    }
    let cfg = TemporalConfig {
        max_gap_s,
        window: base.params().arch().window,
        modes: chosen,
        yaw_sigma_s: sigma_map.yaw_s,
        scatter_k: sigma_map.scatter_k,
        lr: TemporalConfig::default().lr / 4.0,
        ..TemporalConfig::default()
    };
    // Small logs: short runs, so that a few minutes of data still make mini-batches.
    let n: usize = tr.iter().map(|t| t.len()).sum();
    let cfg = if n < 50_000 {
        TemporalConfig {
            tile_len: 16,
            tiles: 4,
            ..cfg
        }
    } else {
        cfg
    };
    let kf = Arc::new(streval::kf_model(q_deg_per_sqrt_s, sigma_v_mps, max_gap_s));
    Ok((cfg, kf))
}

/// The paper's protocol on a user's logs: a per-epoch model restricted to `[lo, hi]`.
fn train_restricted(
    tr: &[ghnet_lab::logs::LogTrack],
    va: &[ghnet_lab::logs::LogTrack],
    output: &Path,
    lo: f32,
    hi: f32,
    seed: Option<u64>,
    epochs: Option<usize>,
) -> Result<()> {
    let data = |ts: &[ghnet_lab::logs::LogTrack]| {
        let mut d = Dataset::default();
        for t in ts {
            for i in 0..t.len() {
                d.push(t.v_north[i], t.v_east[i], t.truth_deg[i], t.speed_acc[i]);
            }
        }
        d
    };
    let (dtr, dva) = (data(tr), data(va));
    if dtr.len() < 2 || dva.is_empty() {
        bail!("too little data for a restricted-range model");
    }
    let head = Head::Blend {
        centre_deg: 0.5 * (lo + hi),
        half_range_deg: 0.5 * (hi - lo),
    };
    let cfg = TrainConfig {
        seed: seed.unwrap_or(1),
        epochs: epochs.unwrap_or(100),
        ..TrainConfig::default()
    };
    let arch = Arch::paper(head.outputs());
    let t = train::train(&arch, &head, 5.0, &dtr, &dva, &cfg, |_| {});
    let meta = ModelMeta {
        format: FORMAT.into(),
        name: output
            .file_stem()
            .and_then(|s| s.to_str())
            .unwrap_or("custom")
            .into(),
        architecture: arch,
        activation: "gelu_tanh".into(),
        head,
        input_scale_mps: 5.0,
        heading_range_deg: [lo, hi],
        sigma_scale: t.sigma_scale,
        accuracy_sigma_scale: f32::NAN,
        training_data: serde_json::json!({"logs": "user data", "heading_range_deg": [lo, hi]}),
        training: serde_json::json!({"config": cfg, "best_epoch": t.best_epoch}),
        metrics: serde_json::json!({"val_mae_deg": t.best_val_mae_deg}),
        kind: ghnet_models::weights::ModelKind::Epoch,
    };
    ghnet_models::weights::write(output, &t.params, &meta)?;
    eprintln!(
        "restricted model: validation MAE {:.3}° -> {}",
        t.best_val_mae_deg,
        output.display()
    );
    Ok(())
}

/// `ghnet eval` for stateful models, or any model with `--data`.
pub fn eval_stream(
    model: &Arc<Model>,
    data: Option<&Path>,
    kf: Option<&str>,
    plot: Option<&Path>,
) -> Result<()> {
    let kf = match kf {
        Some(k) => Arc::new(Model::from_name_or_path(k)?),
        None if timeline::is_kf(model) => model.clone(),
        None => builtin_kf()?,
    };
    let (tracks, what) = match data {
        Some(p) => {
            let (t, s) = ghnet_lab::logs::read_csv(p, true)?;
            if s.skipped > 0 {
                eprintln!("{}: skipped {} of {} rows", p.display(), s.skipped, s.rows);
            }
            (t, p.display().to_string())
        }
        None => {
            let r: TemporalRecipe = serde_json::from_value(model.meta().training_data.clone())
                .context("model metadata does not name the drives it was trained on; use --data")?;
            (
                r.tracks()[2].clone(),
                "held-out simulated tracks".to_owned(),
            )
        }
    };
    for t in timeline::tables(model, &kf, None, &tracks, &what) {
        println!("### {}\n\n{}", t.title, streval::to_markdown(&t));
    }
    if let Some(p) = plot {
        plot_timeline(model, &kf, &tracks[..1], &what, p)?;
    }
    Ok(())
}

/// Heading against time on `tracks`: truth, atan2, the Kalman filter, the model ±σ.
fn plot_timeline(
    model: &Arc<Model>,
    kf: &Arc<Model>,
    tracks: &[ghnet_lab::logs::LogTrack],
    what: &str,
    path: &Path,
) -> Result<()> {
    let t: Vec<f64> = tracks.iter().flat_map(|t| t.t_s.iter().copied()).collect();
    let truth: Vec<f32> = tracks
        .iter()
        .flat_map(|t| t.truth_deg.iter().copied())
        .collect();
    let a = streval::run_atan2(tracks);
    let k = streval::run_model(kf, tracks, "kf");
    let m = streval::run_model(model, tracks, model.name());
    let series = [
        Series {
            name: "truth",
            heading_deg: &truth,
            std_deg: None,
        },
        Series {
            name: "atan2",
            heading_deg: &a.heading_deg,
            std_deg: None,
        },
        Series {
            name: "kf",
            heading_deg: &k.heading_deg,
            std_deg: None,
        },
        Series {
            name: model.name(),
            heading_deg: &m.heading_deg,
            std_deg: m.std_deg.as_deref(),
        },
    ];
    let title = format!("{what}: heading against time ({} ±1σ)", model.name());
    plot_heading_timeline(path, &title, &t, &series)?;
    eprintln!("wrote {}", path.display());
    Ok(())
}
