//! `ghnet eval` of stateful models (or any model on a log): the streamed tables and the
//! heading plot.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use anyhow::{bail, Context, Result};

use ghnet_inference::Model;
use ghnet_lab::make::{self, TemporalRecipe};
use ghnet_lab::{eval, plot, streval};

/// The shipped `kf`, the baseline of every streamed table.
fn builtin_kf() -> Result<Arc<Model>> {
    Ok(Arc::new(Model::builtin("kf").context(
        "no built-in kf: run `ghnet train --recipe ghnet-temporal` first",
    )?))
}

/// `ghnet eval` for stateful models, or any model with `--data`.
pub fn eval_stream(
    model: &Arc<Model>,
    data: Option<&Path>,
    kf: Option<&str>,
    plot: Option<&Path>,
) -> Result<()> {
    let (tracks, mut what) = match data {
        Some(p) => (ghnet_lab::logs::read_truth_csv(p)?, p.display().to_string()),
        None => {
            let r = TemporalRecipe::of(model)
                .context("model metadata does not name the drives it was trained on; use --data")?;
            (
                r.tracks()[2].clone(),
                "held-out simulated tracks".to_owned(),
            )
        }
    };
    let kf = match kf {
        Some(TUNED_KF) if data.is_none() => {
            bail!("--kf {TUNED_KF} tunes on a log's truth: give the log with --data")
        }
        Some(TUNED_KF) => {
            let (kf, note) = kf_tuned_on(model, &tracks)?;
            what = format!("{what} ({note})");
            kf
        }
        Some(k) => Arc::new(Model::from_name_or_path(k)?),
        None if streval::is_kf(model) => model.clone(),
        None => builtin_kf()?,
    };
    for t in streval::tables(model, &kf, None, &tracks, &what) {
        println!("### {}\n\n{}", t.title, streval::to_markdown(&t));
    }
    if let Some(p) = plot {
        plot_timeline(model, &kf, &tracks[..1], &what, p)?;
    }
    Ok(())
}

/// The `--kf` value that tunes the Kalman filter on the evaluated log itself.
const TUNED_KF: &str = "tuned";

/// A `kf` tuned on `tracks` against their truth (grid search, [`make::kf::tune_kf`]),
/// with `model`'s gap limit (the shipped `kf`'s for a per-epoch model), and a note of
/// its parameters for the table's title: the baseline a navigation engineer would
/// tune on the drive at hand, at its best.
fn kf_tuned_on(
    model: &Model,
    tracks: &[ghnet_lab::logs::LogTrack],
) -> Result<(Arc<Model>, String)> {
    let max_gap_s = match model.meta().kind.max_gap_s() {
        Some(g) => g,
        None => builtin_kf()?
            .meta()
            .kind
            .max_gap_s()
            .context("the built-in kf has no gap limit")?,
    };
    let (q, sv, _) = make::kf::tune_kf(tracks, max_gap_s);
    let note = format!("kf tuned on this log: q = {q} °/√s, σ_v = {sv} m/s");
    Ok((Arc::new(make::kf::kf_model(q, sv, max_gap_s)), note))
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
        plot::Series {
            name: "truth",
            heading_deg: &truth,
            std_deg: None,
        },
        plot::Series {
            name: "atan2",
            heading_deg: &a.heading_deg,
            std_deg: None,
        },
        plot::Series {
            name: "kf",
            heading_deg: &k.heading_deg,
            std_deg: None,
        },
        plot::Series {
            name: model.name(),
            heading_deg: &m.heading_deg,
            std_deg: m.std_deg.as_deref(),
        },
    ];
    let title = format!("{what}: heading against time ({} ±1σ)", model.name());
    plot::plot_heading_timeline(path, &title, &t, &series)?;
    eprintln!("wrote {}", path.display());
    Ok(())
}

/// `ghnet eval` of a per-epoch model on its held-out data.
pub fn eval_epoch(model: &Arc<Model>, out_dir: Option<PathBuf>) -> Result<()> {
    let data: make::DataSpec = serde_json::from_value(model.meta().training_data.clone()).context(
        "model metadata `training_data` does not name a simulator to regenerate its held-out data",
    )?;
    let max_speed = model.meta().training["eval_max_speed"]
        .as_f64()
        .unwrap_or(5.0);
    let (_, _, test) = make::epoch::split(&data.generate());
    let report = make::epoch::evaluate(model, &data, &test, max_speed)?;
    let md = eval::to_markdown(&report);
    let Some(dir) = out_dir else {
        println!("{md}");
        return Ok(());
    };
    std::fs::create_dir_all(&dir)?;
    let name = model.name();
    std::fs::write(dir.join(format!("{name}.md")), &md)?;
    std::fs::write(
        dir.join(format!("{name}.summary.md")),
        eval::to_markdown_compact(&report, name, 200),
    )?;
    eval::write_csv(dir.join(format!("{name}.csv")), &report)?;
    std::fs::write(
        dir.join(format!("{name}.json")),
        serde_json::to_string_pretty(&report)?,
    )?;
    plot::plot_mae_vs_speed_with(&report, dir.join(format!("{name}.svg")), plot::YScale::Log)?;
    eprintln!(
        "wrote {}/{name}.{{md,summary.md,csv,json,svg}}",
        dir.display()
    );
    Ok(())
}
