//! Judging a fitted change on a user's log by stretches of time, not by one mean.
//!
//! A log's heading error is heavy-tailed: most epochs are off by a degree or two, while
//! one departure taken the wrong way round, or one stop held through a turn, is off by
//! up to 180° for seconds on end. A change of the mode filter's constants can win or
//! lose a whole log's mean on one such event, and whether the next event goes the same
//! way is a coin toss: fitted by its mean, a u-blox car's departure threshold went to
//! "never reverse" on the strength of one departure and turned the next ones around
//! (the test `fit_modes_does_not_take_one_departures_gain`). What the receiver and the
//! platform are shows throughout a log, so a change is credited only with the gain that
//! remains once the stretch where it gains most is left out ([`Scored::gain_over`]).
//! `models/ownlog.sh` measures how own-log training fares (`models/reports/ownlog.md`).

use std::sync::Arc;

use ghnet_inference::modes::ModeParams;
use ghnet_inference::weights::ModelKind;
use ghnet_inference::Model;

use crate::logs::LogTrack;
use crate::temporal::stream_errors;

/// Smallest relative gain in MAE for a step of the mode fit
/// ([`super::modes::fit_modes`]) to be taken, and for a fit to be confirmed on the
/// held-out part ([`Scored::confirms_over`]): smaller ones are as likely the log's
/// noise as the receiver's nature.
pub const MIN_GAIN: f32 = 0.005;

/// `model` with the mode filter's constants `modes` (a temporal model; others come back
/// unchanged).
pub fn with_modes(model: &Model, modes: ModeParams) -> Model {
    let mut meta = model.meta().clone();
    if let ModelKind::Temporal { modes: m, .. } = &mut meta.kind {
        *m = modes;
    }
    Model::new(model.params().clone(), meta)
}

/// Length (s) of the stretches a gain is counted in: long enough to hold one stop and
/// the departure after it (an event's errors stay in one or two stretches), short
/// enough that minutes of log give several.
pub const BLOCK_S: f64 = 60.0;

/// A streamed pass of a model over some tracks: its mean absolute error and the sums of
/// absolute error per [`BLOCK_S`] stretch of each track.
#[derive(Debug, Clone, PartialEq)]
pub struct Scored {
    /// Mean absolute error, degrees.
    pub mae: f32,
    /// Sum of absolute errors (degrees) per stretch, tracks one after the other.
    pub blocks: Vec<f64>,
}

impl Scored {
    /// Stream `model` with `modes` over `tracks`.
    pub fn of(model: &Model, modes: ModeParams, tracks: &[LogTrack]) -> Scored {
        let s = stream_errors(&Arc::new(with_modes(model, modes)), tracks);
        let (mut blocks, mut k, mut total) = (Vec::new(), 0, 0.0);
        for t in tracks {
            let first = blocks.len();
            for i in 0..t.len() {
                let b = first + ((t.t_s[i] - t.t_s[0]) / BLOCK_S).max(0.0) as usize;
                if blocks.len() <= b {
                    blocks.resize(b + 1, 0.0);
                }
                let e = (s.err[k].abs() as f64).to_degrees();
                blocks[b] += e;
                total += e;
                k += 1;
            }
        }
        Scored {
            mae: (total / k.max(1) as f64) as f32,
            blocks,
        }
    }

    /// The share of `base`'s total error that `self` removes outside the stretch where
    /// it gains most (negative: it loses there). Zero on a single stretch: one stretch
    /// cannot show that a gain is the receiver's and not one event's.
    pub fn gain_over(&self, base: &Scored) -> f32 {
        let total: f64 = base.blocks.iter().sum();
        if total <= 0.0 || base.blocks.len() != self.blocks.len() {
            return 0.0;
        }
        let gains = base.blocks.iter().zip(&self.blocks).map(|(b, s)| b - s);
        let best = gains.clone().fold(f64::NEG_INFINITY, f64::max);
        ((gains.sum::<f64>() - best) / total) as f32
    }

    /// Whether `self` is confirmed better than `base`: it gains [`MIN_GAIN`] outside
    /// its best stretch, as every step of the fit must on the part it was fitted to.
    pub fn confirms_over(&self, base: &Scored) -> bool {
        self.gain_over(base) >= MIN_GAIN
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scored(blocks: &[f64]) -> Scored {
        Scored {
            mae: 0.0,
            blocks: blocks.to_vec(),
        }
    }

    /// A gain made in one stretch alone (one departure turned around) counts for
    /// nothing, though it lowers the mean; a gain spread over the log counts.
    #[test]
    fn a_gain_in_one_stretch_is_not_credited() {
        let base = scored(&[100.0, 100.0, 100.0, 100.0]);
        let one_event = scored(&[100.0, 20.0, 100.0, 100.0]);
        assert!(one_event.blocks.iter().sum::<f64>() < base.blocks.iter().sum::<f64>());
        assert_eq!(one_event.gain_over(&base), 0.0);
        assert!(!one_event.confirms_over(&base));
        let spread = scored(&[95.0, 95.0, 95.0, 95.0]);
        assert!((spread.gain_over(&base) - 0.0375).abs() < 1e-6);
        assert!(spread.confirms_over(&base));
        let slight = scored(&[99.9, 99.9, 99.9, 99.9]);
        assert!(slight.gain_over(&base) > 0.0);
        assert!(!slight.confirms_over(&base));
    }

    /// A big win in one stretch does not hide a loss in another.
    #[test]
    fn a_loss_elsewhere_is_not_hidden_by_one_win() {
        let base = scored(&[100.0, 100.0, 100.0]);
        let lucky = scored(&[10.0, 100.0, 120.0]);
        assert!(lucky.gain_over(&base) < 0.0);
        assert!(!lucky.confirms_over(&base));
        assert_eq!(scored(&[50.0]).gain_over(&scored(&[100.0])), 0.0);
    }
}
