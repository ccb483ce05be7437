//! What a model answers for one epoch: [`Prediction`] (heading, σ, [`Status`]) and the
//! thresholds that decide the status ([`StatusPolicy`]). Apart from the model and the
//! predictors so that every engine (per-epoch, stream, the sample rules) speaks it
//! without depending on the others.

use crate::head::{accuracy_sigma_base, heading_deg, MAX_STD_DEG};
use crate::model::Model;

/// How far to trust a heading. Mirrors the wire status in `ghnet-client` (the daemon maps
/// one to the other; this crate knows nothing of the wire).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Status {
    /// Use it, with its σ.
    Ok,
    /// A heading exists but σ exceeds the policy's limit: do not feed it to a filter
    /// without inflating its variance.
    LowSpeed,
    /// Stopped with no heading known (speed below the stationary threshold, or a
    /// temporal model's stand before its history has a heading): heading is not
    /// observable.
    Stationary,
    /// The input was not a usable velocity (NaN, infinite, absurd): no heading.
    Invalid,
    /// Stopped, and the heading is the one held from the source's history (stateful
    /// models only); σ grows with the time stopped. Usable with its σ: a parked car
    /// keeps pointing where it stopped. One error for the whole stop: fuse it once.
    Held,
}

impl Status {
    /// Lower-case name, as written in CSV and logs.
    pub fn as_str(&self) -> &'static str {
        match self {
            Status::Ok => "ok",
            Status::LowSpeed => "low_speed",
            Status::Stationary => "stationary",
            Status::Invalid => "invalid",
            Status::Held => "held",
        }
    }
}

/// Thresholds that turn a prediction into a [`Status`].
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct StatusPolicy {
    /// Below this horizontal speed (m/s) the status is `stationary`.
    pub stationary_speed: f32,
    /// Above this σ (degrees) the status is `low_speed`.
    pub max_std_deg: f32,
    /// Above this speed (m/s) the input is `invalid`: no land vehicle does 100 m/s, a
    /// receiver glitch does.
    pub max_speed: f32,
}

impl Default for StatusPolicy {
    fn default() -> Self {
        Self {
            stationary_speed: 0.05,
            max_std_deg: 10.0,
            max_speed: 100.0,
        }
    }
}

/// One heading estimate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Prediction {
    /// Heading, degrees clockwise from north in [0, 360); NaN when invalid.
    pub heading_deg: f32,
    /// 1σ of the heading, degrees; NaN when invalid.
    pub std_deg: f32,
    /// The model-based heading atan2(v_E, v_N), degrees in [0, 360); NaN when invalid.
    pub atan2_deg: f32,
    /// Horizontal speed, m/s (NaN when a component is NaN).
    pub speed: f32,
    /// Trust.
    pub status: Status,
}

impl Prediction {
    /// The answer to invalid input: status `Invalid`, every number NaN. Also the
    /// filler for output buffers handed to `predict_batch*`, which overwrite them.
    pub const INVALID: Prediction = Prediction {
        heading_deg: f32::NAN,
        std_deg: f32::NAN,
        atan2_deg: f32::NAN,
        speed: f32::NAN,
        status: Status::Invalid,
    };
}

/// The answer of a per-epoch model from its outputs `y`: decoded heading, σ (from the
/// receiver's speed accuracy where the model uses it) and status. Shared by
/// [`Predictor`] and [`StreamPredictor`].
pub(crate) fn finish_epoch(
    model: &Model,
    policy: &StatusPolicy,
    y: &[f32],
    v_north: f32,
    v_east: f32,
    speed: f32,
    acc: f32,
) -> Prediction {
    let meta = model.meta();
    let (heading, mut std) = meta.head.decode(y, v_north, v_east, meta.sigma_scale);
    if meta.accuracy_sigma_scale.is_finite() {
        if let Some(base) = accuracy_sigma_base(v_north, v_east, acc) {
            std = (meta.accuracy_sigma_scale * base)
                .to_degrees()
                .min(MAX_STD_DEG);
        }
    }
    let status = if speed < policy.stationary_speed {
        Status::Stationary
    } else if std.is_nan() || std > policy.max_std_deg {
        Status::LowSpeed
    } else {
        Status::Ok
    };
    Prediction {
        heading_deg: heading,
        std_deg: std,
        atan2_deg: heading_deg(v_north, v_east),
        speed,
        status,
    }
}
