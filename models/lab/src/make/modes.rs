//! Fitting the mode filter to a user's own logs: what depends on the platform and the
//! receiver (which platform, how fast it may turn while standing, how noisy the
//! receiver is when it gives no accuracy, how far its accuracy is to be trusted, when
//! an epoch moves, when a departure reverses, how far its course lags) is chosen on the
//! log itself, before the network is fine-tuned and the σ maps are fitted.
//!
//! Why a search and not gradients: the filter's rules are thresholds, and each
//! candidate is one streamed pass over the log (a few milliseconds for minutes of
//! data), so a coordinate search over a few multiplicative steps per constant is both
//! exact and fast. Each accepted step must lower the mean absolute error on the
//! training part by at least [`MIN_GAIN`]; the caller keeps the result only if the
//! held-out part agrees.

use std::sync::Arc;

use ghnet_inference::modes::ModeParams;
use ghnet_inference::weights::ModelKind;
use ghnet_inference::{Model, Platform};

use crate::logs::LogTrack;
use crate::temporal::{mean_abs_deg, stream_errors};

/// Smallest relative gain in MAE for a step of the search to be taken: smaller ones
/// are as likely the log's noise as the receiver's nature.
pub const MIN_GAIN: f32 = 0.005;

/// Multiplicative steps tried on each constant per round.
const STEPS: [f32; 4] = [0.5, 0.7, 1.4, 2.0];

/// Receiver lags (s) tried for `lag_s` (and `hold_lag_s`, set alike: a lag fitted on
/// the log replaces the one assumed from the receiver's static hold). A lag starts at
/// 0, where multiplicative steps cannot move it, so it has a grid of its own.
const LAGS: [f32; 6] = [0.0, 0.25, 0.5, 1.0, 1.5, 2.0];

/// Rounds of the coordinate search.
const ROUNDS: usize = 2;

/// A constant of the mode filter the search may change, with its sane range.
struct Knob {
    name: &'static str,
    get: fn(&mut ModeParams) -> &mut f32,
    range: (f32, f32),
}

/// A [`Knob`] of the [`ModeParams`] field `$field`, named after it, searched in
/// `$lo..=$hi`.
macro_rules! knob {
    ($field:ident, $lo:expr, $hi:expr) => {
        Knob {
            name: stringify!($field),
            get: |m| &mut m.$field,
            range: ($lo, $hi),
        }
    };
}

/// The constants that depend on the platform and the receiver.
const KNOBS: [Knob; 10] = [
    knob!(q_tip_deg, 5.0, 360.0),
    knob!(q_still_deg, 0.05, 20.0),
    knob!(tip_sigma_none, 0.01, 2.0),
    knob!(tip_acc_k, 0.2, 10.0),
    knob!(sigma_none, 0.01, 2.0),
    knob!(acc_k, 0.2, 10.0),
    knob!(noise_k, 0.2, 10.0),
    knob!(moving_r, 0.05, 1.5),
    knob!(flip_stop_deg, 45.0, 180.0),
    knob!(k_max, 0.02, 2.0),
];

/// What [`fit_modes`] chose.
#[derive(Debug, Clone)]
pub struct FittedModes {
    /// The fitted constants (the platform among them).
    pub modes: ModeParams,
    /// MAE (degrees) on the fitting tracks before and after.
    pub mae_before: f32,
    /// See `mae_before`.
    pub mae_after: f32,
    /// One line per change, `name: old → new`.
    pub changes: Vec<String>,
}

/// `model` with the mode filter's constants `modes` (a temporal model; others come back
/// unchanged).
pub fn with_modes(model: &Model, modes: ModeParams) -> Model {
    let mut meta = model.meta().clone();
    if let ModelKind::Temporal { modes: m, .. } = &mut meta.kind {
        *m = modes;
    }
    Model::new(model.params().clone(), meta)
}

/// The mode constants of a temporal `model` (the defaults for others).
pub fn modes_of(model: &Model) -> ModeParams {
    match model.meta().kind {
        ModelKind::Temporal { modes, .. } => modes,
        _ => ModeParams::default(),
    }
}

/// Streamed MAE (degrees) of `model` with `modes` over `tracks`.
pub fn mae_with(model: &Model, modes: ModeParams, tracks: &[LogTrack]) -> f32 {
    mean_abs_deg(&stream_errors(&Arc::new(with_modes(model, modes)), tracks).err)
}

/// Fit the platform (unless `platform` fixes it) and the receiver- and platform-
/// dependent constants of `model`'s mode filter to `tracks` by coordinate search on
/// the streamed MAE, the network as it is.
pub fn fit_modes(model: &Model, tracks: &[LogTrack], platform: Option<Platform>) -> FittedModes {
    let start = modes_of(model);
    let mae_before = mae_with(model, start, tracks);
    let mut best = start;
    let mut best_mae = mae_before;
    let platforms = match platform {
        Some(p) => vec![p],
        None => vec![Platform::Auto, Platform::Car, Platform::Robot],
    };
    // The platform first: it decides which other constants matter.
    for p in platforms {
        let cand = ModeParams {
            platform: p,
            ..start
        };
        let m = mae_with(model, cand, tracks);
        if m < best_mae * (1.0 - MIN_GAIN) || (cand.platform == start.platform && m <= best_mae) {
            (best, best_mae) = (cand, m);
        }
    }
    if let Some(p) = platform {
        best.platform = p;
        best_mae = mae_with(model, best, tracks);
    }
    for _ in 0..ROUNDS {
        let mut moved = fit_lag(model, tracks, &mut best, &mut best_mae);
        for knob in &KNOBS {
            for f in STEPS {
                let mut cand = best;
                let v = (knob.get)(&mut cand);
                let new = (*v * f).clamp(knob.range.0, knob.range.1);
                if new == *v {
                    continue;
                }
                *v = new;
                let m = mae_with(model, cand, tracks);
                if m < best_mae * (1.0 - MIN_GAIN) {
                    (best, best_mae, moved) = (cand, m, true);
                }
            }
        }
        if !moved {
            break;
        }
    }
    FittedModes {
        modes: best,
        mae_before,
        mae_after: best_mae,
        changes: changes(&start, &best),
    }
}

/// Try every lag of [`LAGS`] on `best`; true when one lowered `best_mae` by
/// [`MIN_GAIN`].
fn fit_lag(model: &Model, tracks: &[LogTrack], best: &mut ModeParams, best_mae: &mut f32) -> bool {
    let mut moved = false;
    for lag in LAGS {
        let cand = ModeParams {
            lag_s: lag,
            hold_lag_s: lag,
            ..*best
        };
        if cand == *best {
            continue;
        }
        let m = mae_with(model, cand, tracks);
        if m < *best_mae * (1.0 - MIN_GAIN) {
            (*best, *best_mae, moved) = (cand, m, true);
        }
    }
    moved
}

/// `name: old → new` for every constant that differs.
fn changes(a: &ModeParams, b: &ModeParams) -> Vec<String> {
    let mut out = Vec::new();
    if a.platform != b.platform {
        out.push(format!("platform: {} → {}", a.platform, b.platform));
    }
    for (name, x, y) in [
        ("lag_s", a.lag_s, b.lag_s),
        ("hold_lag_s", a.hold_lag_s, b.hold_lag_s),
    ] {
        if x != y {
            out.push(format!("{name}: {x} → {y}"));
        }
    }
    for knob in &KNOBS {
        let (mut a, mut b) = (*a, *b);
        let (x, y) = (*(knob.get)(&mut a), *(knob.get)(&mut b));
        if x != y {
            out.push(format!("{}: {x} → {y}", knob.name));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The drives `p` simulates with `seed`, as logs.
    fn simulated(p: &crate::drive::DriveParams, seed: u64) -> Vec<LogTrack> {
        crate::drive::simulate(p, seed)
            .iter()
            .map(LogTrack::from)
            .collect()
    }

    /// The search never ends worse than it started, and a fixed platform is kept.
    #[test]
    fn fit_modes_never_worsens_and_keeps_a_fixed_platform() {
        let model = Model::builtin("ghnet-temporal").expect("built in");
        let p = crate::drive::DriveParams {
            tracks: 3,
            track_min_s: 120.0,
            track_max_s: 150.0,
            ..crate::drive::DriveParams::default().robots()
        };
        let tracks = simulated(&p, 5);
        let f = fit_modes(&model, &tracks, Some(Platform::Robot));
        assert!(f.mae_after <= f.mae_before, "{f:?}");
        assert_eq!(f.modes.platform, Platform::Robot);
        assert!((mae_with(&model, f.modes, &tracks) - f.mae_after).abs() < 1e-4);
    }

    /// A robot's lagging receiver (the consumer style: velocity lagged 0.5–1.5 s) on a
    /// model that assumes no lag: the search finds one and says so.
    #[test]
    fn fit_modes_finds_a_receivers_lag() {
        let builtin = Model::builtin("ghnet-temporal").expect("built in");
        let none = ModeParams {
            lag_s: 0.0,
            hold_lag_s: 0.0,
            ..modes_of(&builtin)
        };
        let model = with_modes(&builtin, none);
        let p = crate::drive::DriveParams {
            tracks: 4,
            track_min_s: 150.0,
            track_max_s: 200.0,
            receivers: vec![crate::drive::ReceiverKind::Consumer],
            rates_hz: vec![5],
            ..crate::drive::DriveParams::default().robots()
        };
        let tracks = simulated(&p, 11);
        let f = fit_modes(&model, &tracks, Some(Platform::Robot));
        assert!(f.modes.lag_s > 0.0, "{f:?}");
        assert!(f.changes.iter().any(|c| c.starts_with("lag_s")), "{f:?}");
    }
}
