//! Models made from users' own logs (`ghnet train --data`): the shipped temporal model
//! (or `--init`) fitted to them, or the paper's per-epoch protocol restricted to a
//! heading range.

use std::path::Path;
use std::sync::Arc;

use anyhow::{bail, Context, Result};

use ghnet_inference::head::Head;
use ghnet_inference::modes::ModeParams;
use ghnet_inference::weights::{ModelMeta, FORMAT};
use ghnet_inference::{Arch, Model, Platform};

use super::blocks::{with_modes, Scored, MIN_GAIN};
use super::kf::kf_model;
use super::modes::{
    changes, fit_modes, measured_trail, modes_of, platform_candidates, Trail, TRAIL_MAX_SE_S,
};
use super::temporal::train_logged;
use crate::logs::{self, LogTrack};
use crate::streval;
use crate::temporal::{rescale_moving, shares_within, stream_errors, TemporalConfig};
use crate::train::{self, Dataset, TrainConfig};

/// `ghnet train --data ...`: the shipped model (or `--init`) fitted to the user's logs.
/// First what depends on the platform and the receiver (the mode filter's constants,
/// [`fit_modes`]) on the training part, kept only if the held-out part (the last 20% of
/// each track) confirms it ([`Scored::confirms_over`]: a gain outside its best minute,
/// not one event's) and fits on parts of the training part pay on the rest
/// (`cross_checked`); then the network fine-tuned and the σ maps fitted; the result is
/// written only if the held-out part confirms it over the starting model the same way
/// (else the starting model with the fitted mode filter, if that is confirmed, or the
/// starting model as it is, with a note: `keep_confirmed`); last, the σ maps of moving
/// epochs scaled to the log's receiver if the held-out part confirms that
/// (`keep_sigma_confirmed`). A log of minutes cannot train the network from scratch, so
/// the starting model is never random.
pub fn train_data(
    paths: &[impl AsRef<Path>],
    output: &Path,
    init: Option<&str>,
    range: Option<(f32, f32)>,
    seed: Option<u64>,
    epochs: Option<usize>,
    platform: Option<ghnet_inference::Platform>,
) -> Result<()> {
    let (tr, va) = read_logs(paths, 0.2)?;
    if let Some((lo, hi)) = range {
        return train_restricted(&tr, &va, output, lo, hi, seed, epochs);
    }
    let base = Model::from_name_or_path(init.unwrap_or(ghnet_inference::DEFAULT_MODEL))?;
    let base = allowed_platform(base, &tr, platform);
    let (cfg, kf, floor) = own_config(&base, &tr, &va, platform)?;
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
        train_logged(&name, &tr, &va, &kf, Some(&base), &cfg)?.model
    } else {
        eprintln!(
            "{n} training epochs (fewer than {MIN_FINE_TUNE_EPOCHS}): the network and its σ maps \
             stay as they are, only the mode filter is fitted"
        );
        with_modes(&base, cfg.modes)
    };
    let model = keep_confirmed(base, trained, (cfg.modes, floor), &va);
    let model = keep_sigma_confirmed(model, &tr, &va);
    // Named after the output, whatever it came from: consumers tell models by name.
    let mut meta = model.meta().clone();
    meta.name = name;
    let model = Arc::new(Model::new(model.params().clone(), meta));
    for t in streval::tables(
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

/// `base`, or `base` on `auto` when the log rules out its platform
/// ([`platform_candidates`]: a robot's `--init` on a log driven at car speeds), so that
/// neither the fit nor a fallback to the starting model writes a car as a robot.
fn allowed_platform(base: Model, tr: &[LogTrack], platform: Option<Platform>) -> Model {
    let modes = modes_of(&base);
    let (allowed, why) = platform_candidates(tr, platform);
    if platform.is_some() || allowed.contains(&modes.platform) {
        return base;
    }
    eprintln!(
        "{}'s platform {} is ruled out ({why}): starting from auto",
        base.name(),
        modes.platform
    );
    with_modes(
        &base,
        ModeParams {
            platform: Platform::Auto,
            ..modes
        },
    )
}

/// What `ghnet train --data` writes: `trained` (with the mode constants `modes`) if the
/// held-out part `va` confirms it over `base` the way the mode fit's steps are
/// confirmed ([`Scored::confirms_over`]: a fine-tune that only moves one event of the
/// held-out part is the held-out part's luck); else `base` with `modes` alone, if that
/// gains `floor` there outside its best minute (a fitted receiver is not lost with an
/// unconfirmed fine-tune; [`MIN_GAIN`], or less for a lag the truth measured:
/// [`lag_alone`]); else `base` as it is.
fn keep_confirmed(
    base: Model,
    trained: Model,
    (modes, floor): (ModeParams, f32),
    va: &[LogTrack],
) -> Model {
    let base_va = Scored::of(&base, modes_of(&base), va);
    let new_va = Scored::of(&trained, modes, va);
    eprintln!(
        "held-out part: {:.2}° fitted against {:.2}° for {} as it is",
        new_va.mae,
        base_va.mae,
        base.name()
    );
    if new_va.confirms_over(&base_va) {
        return trained;
    }
    if modes != modes_of(&base) && Scored::of(&base, modes, va).gain_over(&base_va) >= floor {
        eprintln!(
            "the fine-tuned network is not confirmed on the held-out part: writing {} with \
             the fitted mode filter",
            base.name()
        );
        return with_modes(&base, modes);
    }
    // Said also when the fine-tune answers the held-out part exactly as the model did
    // (it kept its first weights): what is written is the model as it was either way.
    let same = if new_va.blocks == base_va.blocks {
        " (it answers there as the model did)"
    } else {
        ""
    };
    eprintln!(
        "the fitted model is not confirmed on the held-out part{same}: writing {} unchanged",
        base.name()
    );
    base
}

/// `model` with the σ maps of its moving epochs scaled on the training part `tr`
/// ([`rescale_moving`]) if the held-out part `va` confirms it ([`sigma_confirms`]). Only σ
/// changes, never a heading, so this runs whether or not the network was fine-tuned:
/// a receiver's noise and lag are what a user's log shows best, and the shipped maps
/// are fitted on receivers pooled.
fn keep_sigma_confirmed(model: Model, tr: &[LogTrack], va: &[LogTrack]) -> Model {
    let (scaled, classes) = rescale_moving(&model, tr, MIN_SIGMA_EPOCHS);
    if classes.iter().all(|c| c.1 == 1.0) {
        eprintln!(
            "σ maps kept: no class of moving epochs with {MIN_SIGMA_EPOCHS} epochs in the \
             training part asks for a change"
        );
        return model;
    }
    let shares = |m: &Model| shares_within(&stream_errors(&Arc::new(m.clone()), va), |_| true);
    let (old, new) = (shares(&model), shares(&scaled));
    let factors: Vec<String> = classes
        .iter()
        .map(|(c, f)| format!("{c} × {f:.2}"))
        .collect();
    let what = format!(
        "σ maps of moving epochs scaled on the training part ({}): held-out part \
         {:.1}% / {:.1}% → {:.1}% / {:.1}% within 1σ / 2σ",
        factors.join(", "),
        100.0 * old.0,
        100.0 * old.1,
        100.0 * new.0,
        100.0 * new.1
    );
    if sigma_confirms(new, old) {
        eprintln!("{what}");
        scaled
    } else {
        eprintln!("{what}, not confirmed: kept");
        model
    }
}

/// Whether shares within 1σ and 2σ `new` beat `old`: they miss the bars (60–76%, at
/// least 90%) by [`SIGMA_CONFIRM`] less, or `new` meets the bars and `old` does not, or
/// both meet them and `new`'s 1σ share is [`SIGMA_CONFIRM`] nearer 68.3%.
fn sigma_confirms(new: (f64, f64), old: (f64, f64)) -> bool {
    let miss =
        |(c1, c2): (f64, f64)| (c1 - 0.76).max(0.0) + (0.60 - c1).max(0.0) + (0.90 - c2).max(0.0);
    let off = |(c1, _): (f64, f64)| (c1 - 0.683).abs();
    let (m_new, m_old) = (miss(new), miss(old));
    m_new + SIGMA_CONFIRM <= m_old
        || (m_new == 0.0 && m_old > 0.0)
        || (m_new == 0.0 && off(new) + SIGMA_CONFIRM <= off(old))
}

/// Fewest moving epochs of a class (cars, others) in the training part for
/// `ghnet train --data` to refit its σ map: 200 s of driving at 5 Hz.
const MIN_SIGMA_EPOCHS: usize = 1000;

/// How much nearer the bars a refitted σ must bring the held-out part (shares, 0–1): two
/// points, about the sampling error of a share over the few thousand correlated epochs
/// a held-out part of a 20-minute log holds.
const SIGMA_CONFIRM: f64 = 0.02;

/// Fewest training epochs for `ghnet train --data` to fine-tune the network and refit
/// its σ maps: on less (about 13 minutes at 5 Hz) the held-out part that
/// judges the result is too small to tell a better network from a luckier one (on
/// half of the shared real drive, 442 epochs at 1 Hz, a fine-tune that won on its
/// validation part lost on the other half).
const MIN_FINE_TUNE_EPOCHS: usize = 4000;

/// The training configuration of `ghnet train --data` from the starting model `base`:
/// its window, gap limit, start convention (its `kf`) and σ choices, and the mode
/// filter's constants fitted to `tr` (kept if `va` agrees), each change printed; with
/// the least held-out gain the constants alone must show to be written
/// ([`keep_confirmed`]'s `floor`).
fn own_config(
    base: &Model,
    tr: &[crate::logs::LogTrack],
    va: &[crate::logs::LogTrack],
    platform: Option<ghnet_inference::Platform>,
) -> Result<(TemporalConfig, Arc<Model>, f32)> {
    let ghnet_inference::weights::ModelKind::Temporal {
        max_gap_s,
        q_deg_per_sqrt_s,
        sigma_v_mps,
        modes,
        sigma_map,
    } = base.meta().kind
    else {
        bail!("--init {}: not a temporal model", base.name());
    };
    let (mut chosen, floor) = confirmed_modes(base, modes, tr, va, platform);
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
    let kf = Arc::new(kf_model(q_deg_per_sqrt_s, sigma_v_mps, max_gap_s));
    Ok((cfg, kf, floor))
}

/// The mode filter's constants fitted to `tr` ([`fit_modes`]) if the held-out part
/// `va` confirms them over `base`'s `modes` and they are [`cross_checked`]; else
/// `modes` (with the fitted boresight, if `va` confirms that alone, and the fitted lag,
/// if the truth's trail measures it: [`lag_alone`]). What was fitted, the gains and the
/// choice are printed. With the constants, the least held-out gain they must show to be
/// written ([`keep_confirmed`]): [`MIN_GAIN`], or `-MIN_GAIN` for a measured lag.
fn confirmed_modes(
    base: &Model,
    modes: ModeParams,
    tr: &[LogTrack],
    va: &[LogTrack],
    platform: Option<Platform>,
) -> (ModeParams, f32) {
    let t0 = std::time::Instant::now();
    let fitted = fit_modes(base, tr, platform);
    let before = Scored::of(base, modes, va);
    let after = Scored::of(base, fitted.modes, va);
    eprintln!(
        "mode filter fitted in {:.1} s: training part {:.2}° → {:.2}°, held-out part {:.2}° → {:.2}°",
        t0.elapsed().as_secs_f64(),
        fitted.mae_before,
        fitted.mae_after,
        before.mae,
        after.mae
    );
    eprintln!("  {}", fitted.platform_note);
    let trail = measured_trail(tr);
    if let Some(t) = trail {
        eprintln!(
            "  the courses trail the truth's turns by {:.2} ± {:.2} s over {} epochs (a \
             receiver's lag trails them, an antenna ahead of the turning axis leads them)",
            t.s, t.se_s, t.epochs
        );
    }
    eprintln!(
        "  held-out gain outside its best minute: {:.1}%",
        100.0 * after.gain_over(&before)
    );
    let held_out = after.confirms_over(&before);
    let confirmed = held_out && cross_checked(base, modes, tr, platform);
    let mut chosen = if confirmed { fitted.modes } else { modes };
    if fitted.changes.is_empty() {
        eprintln!("  no constant changed");
    } else if !confirmed {
        let why = if held_out {
            "the cross-check on the training part does not confirm the fit".to_owned()
        } else {
            format!(
                "the held-out part does not confirm the fit by {:.1}% outside its best minute",
                100.0 * MIN_GAIN
            )
        };
        eprintln!(
            "  kept the model's constants: {why} (fitted: {})",
            fitted.changes.join(", ")
        );
        chosen = boresight_alone(base, modes, fitted.modes.boresight_deg, &before, va);
        let with_lag = lag_alone(base, chosen, &fitted.modes, trail, va);
        if with_lag != chosen {
            return (with_lag, -MIN_GAIN);
        }
    }
    for c in fitted.changes.iter().filter(|_| confirmed) {
        eprintln!("  {c}");
    }
    (chosen, MIN_GAIN)
}

/// How many parts of the training part [`cross_checked`] fits on all but one of.
const FOLDS: usize = 5;

/// Whether fitting the mode filter pays on data the fit did not see, judged on the
/// training part `tr` itself: each fifth of every track is scored with the constants
/// fitted on the other four fifths, and the fits together must gain [`MIN_GAIN`] over
/// `modes` outside their best stretch ([`Scored::confirms_over`]). The held-out part
/// alone is a minute or two of a short log, one or two stops: on half of the shared
/// real drive it confirmed a fit that lost on the other half (`models/reports/ownlog.md`).
fn cross_checked(
    base: &Model,
    modes: ModeParams,
    tr: &[LogTrack],
    platform: Option<Platform>,
) -> bool {
    let empty = || Scored {
        mae: 0.0,
        blocks: Vec::new(),
    };
    let (mut before, mut after) = (empty(), empty());
    for k in 0..FOLDS {
        let (mut rest, mut fold) = (Vec::new(), Vec::new());
        for t in tr {
            let (a, b) = (k * t.len() / FOLDS, (k + 1) * t.len() / FOLDS);
            fold.extend((a < b).then(|| t.slice(a..b)));
            rest.extend((a > 0).then(|| t.slice(0..a)));
            rest.extend((b < t.len()).then(|| t.slice(b..t.len())));
        }
        if fold.is_empty() || rest.is_empty() {
            continue;
        }
        let fitted = fit_modes(base, &rest, platform).modes;
        before.blocks.extend(Scored::of(base, modes, &fold).blocks);
        after.blocks.extend(Scored::of(base, fitted, &fold).blocks);
    }
    let gain = after.gain_over(&before);
    eprintln!(
        "  cross-checked on the training part ({FOLDS} parts, each scored by a fit on the \
         others): gain outside its best minute {:.1}%",
        100.0 * gain
    );
    gain >= MIN_GAIN
}

/// `modes` with the fitted boresight `b` alone, if the held-out part `va` confirms it
/// over `before` (the model as it is there) the way the whole fit is confirmed: it is
/// measured on the truth, not searched, and may stand when the searched constants
/// around it do not.
fn boresight_alone(
    base: &Model,
    modes: ModeParams,
    b: f32,
    before: &Scored,
    va: &[LogTrack],
) -> ModeParams {
    let cand = ModeParams {
        boresight_deg: b,
        ..modes
    };
    if cand == modes || !Scored::of(base, cand, va).confirms_over(before) {
        return modes;
    }
    eprintln!("  alone, the held-out part confirms:");
    eprintln!("  boresight_deg: {} → {b}", modes.boresight_deg);
    cand
}

/// `modes` with the fitted modes' lag alone (`lag_s` and the three it replaces, which
/// the fit sets alike), if the `trail` the training part's truth measures
/// ([`measured_trail`], within [`TRAIL_MAX_SE_S`]) is nearest that lag of the fit's
/// grid, and the held-out part `va` loses less than [`MIN_GAIN`] by it outside its
/// best minute. Two measures on the training part then agree (the searched lag gained
/// there, and the trail puts it nearest); the MAE a lag gains sits in the turns, a few
/// stretches of a short log, so a held-out part of a minute or two seldom confirms it
/// by [`MIN_GAIN`] as well. Without this, robots on a receiver that reads 0.000 at rest
/// without lagging, led as if it filtered (`hold_lag_s`), kept that lead through their
/// turns (the snap rows of `models/reports/ownlog.md`).
fn lag_alone(
    base: &Model,
    modes: ModeParams,
    fitted: &ModeParams,
    trail: Option<Trail>,
    va: &[LogTrack],
) -> ModeParams {
    let cand = ModeParams {
        lag_s: fitted.lag_s,
        hold_lag_s: fitted.hold_lag_s,
        no_acc_lag_s: fitted.no_acc_lag_s,
        acc_lag_s: fitted.acc_lag_s,
        ..modes
    };
    if cand == modes {
        return modes;
    }
    let Some(trail) = trail else {
        return modes;
    };
    if trail.se_s > TRAIL_MAX_SE_S || trail.nearest_lag() != fitted.lag_s {
        return modes;
    }
    if Scored::of(base, cand, va).gain_over(&Scored::of(base, modes, va)) < -MIN_GAIN {
        return modes;
    }
    eprintln!(
        "  alone, the trail above putting it nearest and the held-out part losing less \
         than {:.1}%:",
        100.0 * MIN_GAIN
    );
    for c in changes(&modes, &cand) {
        eprintln!("  {c}");
    }
    cand
}

/// The paper's protocol on a user's logs: a per-epoch model restricted to `[lo, hi]`.
fn train_restricted(
    tr: &[crate::logs::LogTrack],
    va: &[crate::logs::LogTrack],
    output: &Path,
    lo: f32,
    hi: f32,
    seed: Option<u64>,
    epochs: Option<usize>,
) -> Result<()> {
    let data = |ts: &[crate::logs::LogTrack]| {
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
        kind: ghnet_inference::weights::ModelKind::Epoch,
    };
    ghnet_inference::weights::write(output, &t.params, &meta)?;
    eprintln!(
        "restricted model: validation MAE {:.3}° -> {}",
        t.best_val_mae_deg,
        output.display()
    );
    Ok(())
}

/// Read several logs with truth and split them by time for training.
pub fn read_logs(
    paths: &[impl AsRef<Path>],
    val_fraction: f64,
) -> Result<(Vec<LogTrack>, Vec<LogTrack>)> {
    let mut all = Vec::new();
    for p in paths {
        all.extend(logs::read_truth_csv(p.as_ref())?);
    }
    if all.is_empty() {
        bail!("no rows with velocity, time and truth");
    }
    Ok(logs::time_split(&all, val_fraction))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::make::modes::fit_modes;

    /// A receiver's lag the model lacks shows in every part of a log: fitted on four
    /// fifths, it pays on the fifth left out. (That a fit which pays on one stretch
    /// alone is refused is `models/reports/ownlog.md`'s "vs shipped" column, which
    /// `committed_reports_meet_the_accuracy_bars` checks.)
    #[test]
    fn a_receivers_lag_is_cross_checked() {
        let (base, tracks) = crate::make::modes::lagging_robot_on_a_no_lag_model();
        let robot = Some(ghnet_inference::Platform::Robot);
        assert!(cross_checked(&base, modes_of(&base), &tracks, robot));
    }

    /// A 20-minute 5 Hz robot log with `receiver`, seeded `seed`: its first 80% to fit,
    /// the rest held out.
    fn robot_log(
        receiver: crate::drive::ReceiverKind,
        seed: u64,
    ) -> (Vec<LogTrack>, Vec<LogTrack>) {
        let t = crate::make::modes::robot_day(receiver, seed).remove(0);
        let cut = t.len() * 4 / 5;
        (vec![t.slice(0..cut)], vec![t.slice(cut..t.len())])
    }

    /// A lag of 0 fitted to a robot on a receiver that snaps to 0.000 at rest without
    /// lagging stands alone, the truth's trail measuring it, against the shipped lead of a
    /// static hold; fitted to one that lags (the consumer style), it does not.
    #[test]
    fn a_lag_stands_alone_where_the_truth_measures_it() {
        let base = Model::builtin("ghnet-temporal").expect("built in");
        let modes = modes_of(&base);
        let none = ModeParams {
            lag_s: 0.0,
            hold_lag_s: 0.0,
            no_acc_lag_s: 0.0,
            acc_lag_s: 0.0,
            ..modes
        };
        let (tr, va) = robot_log(crate::drive::ReceiverKind::Snap, 30);
        assert_eq!(
            lag_alone(&base, modes, &none, measured_trail(&tr), &va),
            none
        );
        let (tr, va) = robot_log(crate::drive::ReceiverKind::Consumer, 30);
        assert_eq!(
            lag_alone(&base, modes, &none, measured_trail(&tr), &va),
            modes
        );
    }

    /// A fine-tune the held-out part does not confirm (here a network whose weights are
    /// tripled) does not take the confirmed mode fit (a receiver's lag) down with it.
    #[test]
    fn an_unconfirmed_fine_tune_keeps_the_fitted_mode_filter() {
        let (base, tracks) = crate::make::modes::lagging_robot_on_a_no_lag_model();
        let modes = fit_modes(&base, &tracks, Some(ghnet_inference::Platform::Robot)).modes;
        assert!(modes.lag_s > 0.0);
        let mut params = base.params().clone();
        params.data_mut().iter_mut().for_each(|w| *w *= 3.0);
        let broken = Model::new(params, base.meta().clone());
        let kept = keep_confirmed(base.clone(), broken, (modes, MIN_GAIN), &tracks);
        assert_eq!(kept.params().data(), base.params().data());
        assert_eq!(modes_of(&kept), modes);
    }

    /// σ is rescaled only where the held-out part comes two points nearer the bars:
    /// out of them by less, or within them and nearer 68.3% within 1σ.
    #[test]
    fn a_rescaled_sigma_must_come_nearer_the_bars() {
        assert!(sigma_confirms((0.74, 0.93), (0.89, 0.98)), "over-covered");
        assert!(
            sigma_confirms((0.70, 0.91), (0.77, 0.95)),
            "just over the 1σ bar"
        );
        assert!(sigma_confirms((0.66, 0.91), (0.58, 0.86)), "under-covered");
        assert!(
            sigma_confirms((0.69, 0.93), (0.74, 0.96)),
            "within, nearer 68%"
        );
        assert!(sigma_confirms((0.75, 0.96), (0.68, 0.89)), "into the bars");
        assert!(
            !sigma_confirms((0.71, 0.93), (0.72, 0.95)),
            "within the noise"
        );
        assert!(
            !sigma_confirms((0.68, 0.88), (0.75, 0.92)),
            "2σ under its bar"
        );
        assert!(
            !sigma_confirms((0.66, 0.93), (0.70, 0.95)),
            "as near 68% as before"
        );
    }

    /// A robot's `--init` on a log driven at car speeds starts from `auto`, so that a
    /// fallback to the starting model cannot write a car as a robot; a platform the
    /// user gives stands.
    #[test]
    fn a_car_log_rules_out_a_robot_start() {
        let builtin = Model::builtin("ghnet-temporal").expect("built in");
        let robot = ModeParams {
            platform: Platform::Robot,
            ..modes_of(&builtin)
        };
        let car = LogTrack::north_at(&[9.0; 60]);
        let m = allowed_platform(
            with_modes(&builtin, robot),
            std::slice::from_ref(&car),
            None,
        );
        assert_eq!(modes_of(&m).platform, Platform::Auto);
        let m = allowed_platform(with_modes(&builtin, robot), &[car], Some(Platform::Robot));
        assert_eq!(modes_of(&m).platform, Platform::Robot);
    }
}
