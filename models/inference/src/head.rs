//! Output heads: how the network's outputs become a heading and its standard deviation.
//! The losses that train them are in the lab (`ghnet_lab::loss`).
//!
//! Two heads exist because the two shipped models answer different questions.
//!
//! * [`Head::Angle`] is the paper's: one output is the heading itself, scaled to the trained
//!   range (`ψ = centre + half_range·y₀`). It suits a restricted range such as the paper's
//!   0–90°, where the prior is informative and the network should pull low-speed estimates
//!   toward it. It cannot represent the full circle (a single regressed angle has a seam).
//! * [`Head::Residual`] is for the full circle: two outputs `(c, s)` give a rotation
//!   `Δ = atan2(s, c)` applied to the model-based heading, `ψ = atan2(v_E, v_N) + Δ`. The
//!   seam disappears (everything is on the circle) and, more importantly, the identity
//!   (`Δ = 0`) is easy to represent. Under a uniform heading prior the posterior of ψ is
//!   symmetric around atan2 (see `NOTES-domain.md`), so no per-epoch estimator can beat atan2
//!   on a symmetric loss; what a network can add is a calibrated σ and corrections for
//!   receiver artefacts. A direct `(cos ψ, sin ψ)` head would have to compute `v/|v|` to
//!   ~0.05° over speeds from 0.1 to 30 m/s to stay within 2% of atan2 at speed, which a
//!   38k-parameter GELU network does not do.
//!
//! Both heads end with one more output, `log σ` (σ in radians), trained with a Gaussian
//! negative log-likelihood on the *detached* wrapped error, so σ learns the error scale
//! without pulling on the heading. A scalar `sigma_scale`, fitted after training on the
//! validation set so that 68.3% of errors fall within 1σ, corrects the residual mis-scale
//! of a Gaussian fit to heavy-tailed errors.
//!
//! Both heading losses are the paper's MAE, on the wrapped error.

use serde::{Deserialize, Serialize};

/// Largest reported standard deviation: that of a uniform distribution on the circle
/// (`180°/√3`). A larger σ would claim less than no information.
pub const MAX_STD_DEG: f32 = 103.923_05;

/// Lower bound on the raw `log σ` output (σ in radians), so one bad output can't
/// underflow; the lab's loss clamps with the same bounds.
pub const LOG_SIGMA_MIN: f32 = -12.0;
/// Upper bound on the raw `log σ` output, so one bad output can't overflow.
pub const LOG_SIGMA_MAX: f32 = 3.0;

/// How outputs map to a heading.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Head {
    /// `ψ = centre_deg + half_range_deg·y₀`, `log σ = y₁` (the paper's single angle).
    Angle {
        /// Centre of the trained heading range, degrees.
        centre_deg: f32,
        /// Half the width of the trained heading range, degrees.
        half_range_deg: f32,
    },
    /// Shrinkage toward a learned in-range angle, for a restricted heading range:
    /// `θ = centre + half_range·y₀`, `w = sigmoid(y₁)`, `ψ = A + w·wrap(θ − A)` with
    /// `A = atan2(v_E, v_N)`, `log σ = y₂`; the result is clamped to the range.
    /// At speed the network drives `w → 0` and keeps atan2's full precision; near
    /// standstill `w → 1` and the heading comes from the prior, which is what the
    /// Bayes-optimal estimate does for a known range.
    Blend {
        /// Centre of the trained heading range, degrees.
        centre_deg: f32,
        /// Half the width of the trained heading range, degrees.
        half_range_deg: f32,
    },
    /// `ψ = atan2(v_E, v_N) + sigmoid(y₂)·atan2(y₁, y₀)`, `log σ = y₃`; the gate lets the
    /// network switch its correction off exactly where atan2 cannot be improved (at
    /// speed, a rotation that is merely small still costs precision). A heading outside
    /// `range_deg` (when it is narrower than the circle) is moved to the nearer end, which
    /// can only reduce the error for a vehicle whose heading is known to lie in the range.
    Residual {
        /// Trained heading range `[lo, hi]`, degrees; `[0, 360]` for the full circle.
        range_deg: [f32; 2],
    },
    /// The temporal models' learned filter step over the previous output `ψₚ`: the
    /// network corrects a Kalman step. With that step's prior variance `P` and
    /// measurement variance `R²` ([`KalmanBase`]) and gain `K = P/(P + R²)`: a gain
    /// `g = clamp(K + y₀/4, 0, 1)`, a reverse switch `r = [y₁ > 0]`,
    /// `ψ = ψₚ + g·wrap(A + r·π − ψₚ)` and `log σ = ½·ln((1−g)²P + g²R²) + y₂`
    /// ([`filter_step`]). The history keeps the step's own variance, without `y₂`, so a
    /// correction of the reported σ never compounds through the recurrence. Zero
    /// outputs (and the switch off) are exactly the Kalman
    /// filter, so training starts from the baseline and learns what it misses: backing
    /// up, when to trust a slow course, σ. A gain of exactly
    /// 1 returns atan2 exactly (no bias at speed, nothing to learn about `v/|v|`); a gain
    /// of exactly 0 holds the heading through a stop of any length (a logistic gain is
    /// never 0, and 1% of a noise course per epoch drifts tens of degrees over a minute
    /// at 10 Hz); the switch follows a course opposite to the heading, as when a car
    /// backs up. The gain learns from the heading error, the
    /// switch by classification (is the course opposite to the true heading?), because
    /// a soft mixture of the two directions leaks a fraction of 180° into every answer.
    /// Without a previous output (the first epoch of a history) `ψₚ = A`.
    Filter,
}

/// Wrap radians to (−π, π] (NaN for a non-finite angle).
///
/// An angle already in range comes back as it is, and one outside loses the nearest
/// whole number of turns: exact where `atan2(sin x, cos x)` rounds twice, and a few
/// nanoseconds where that costs three transcendental calls. The streaming path wraps
/// about ten angles per epoch, so this is a visible share of its cost (the `stream`
/// group of `models/lab/benches/inference.rs`).
#[inline]
pub fn wrap_rad(x: f32) -> f32 {
    use std::f32::consts::{PI, TAU};
    if x > -PI && x <= PI {
        return x;
    }
    if !x.is_finite() {
        return f32::NAN;
    }
    let y = x - TAU * (x / TAU).round();
    if y <= -PI {
        y + TAU
    } else if y > PI {
        y - TAU
    } else {
        y
    }
}

/// The heading (radians) of a vehicle whose velocity points along `course`: the course
/// itself, or half a turn from it when the vehicle `reverse`s (backing up, it faces
/// away from where it moves). Not wrapped: callers take differences through
/// [`wrap_rad`]. One spelling for the mode filter's rules, its update and the σ of an
/// answer the glitch gate held, which must agree on what a course says.
#[inline]
pub fn facing(course: f32, reverse: bool) -> f32 {
    if reverse {
        course + std::f32::consts::PI
    } else {
        course
    }
}

/// Heading in degrees, clockwise from north, in [0, 360).
#[inline]
pub fn heading_deg(v_north: f32, v_east: f32) -> f32 {
    let h = v_east.atan2(v_north).to_degrees();
    let h = if h < 0.0 { h + 360.0 } else { h };
    if h >= 360.0 {
        0.0
    } else {
        h
    }
}

/// The logistic function, the gate of the blend and residual heads.
#[inline]
pub fn sigmoid(x: f32) -> f32 {
    1.0 / (1.0 + (-x).exp())
}

/// Clips a heading to the arc from `lo` clockwise to `hi` (degrees).
///
/// A heading inside the arc is returned unchanged (in
/// [0, 360)); outside, it maps to the boundary nearer on the circle (ties go to `lo`).
/// Arcs may cross north (`lo = 350, hi = 10`); an arc of 360° or more leaves `h` as is.
pub fn clip_to_range(h: f32, lo: f32, hi: f32) -> f32 {
    let h = (h as f64).rem_euclid(360.0);
    let lo64 = lo as f64;
    let span = hi as f64 - lo64;
    if span >= 360.0 {
        return h as f32;
    }
    let span = span.rem_euclid(360.0);
    let offset = (h - lo64).rem_euclid(360.0);
    if offset <= span {
        return h as f32;
    }
    // Outside: distance back to lo versus distance forward past hi.
    let to_lo = 360.0 - offset;
    let to_hi = offset - span;
    let b = if to_lo <= to_hi { lo64 } else { hi as f64 };
    b.rem_euclid(360.0) as f32
}

impl Head {
    /// Number of network outputs this head reads.
    pub fn outputs(&self) -> usize {
        match self {
            Head::Angle { .. } => 2,
            Head::Blend { .. } => 3,
            Head::Residual { .. } => 4,
            Head::Filter => 3,
        }
    }

    /// The heading range the head was trained on, degrees `(lo, hi)`.
    pub fn range_deg(&self) -> (f32, f32) {
        match *self {
            Head::Angle {
                centre_deg,
                half_range_deg,
            } => (centre_deg - half_range_deg, centre_deg + half_range_deg),
            Head::Blend {
                centre_deg,
                half_range_deg,
            } => (centre_deg - half_range_deg, centre_deg + half_range_deg),
            Head::Residual { range_deg } => (range_deg[0], range_deg[1]),
            Head::Filter => (0.0, 360.0),
        }
    }

    /// Predicted heading in radians (not wrapped) and raw `log σ`: what [`Head::decode`]
    /// finishes for users and what the lab's loss differentiates.
    #[inline]
    pub fn raw(&self, y: &[f32], v_north: f32, v_east: f32) -> (f32, f32) {
        match *self {
            Head::Angle {
                centre_deg,
                half_range_deg,
            } => ((centre_deg + half_range_deg * y[0]).to_radians(), y[1]),
            Head::Residual { .. } => (
                v_east.atan2(v_north) + sigmoid(y[2]) * y[1].atan2(y[0]),
                y[3],
            ),
            Head::Blend {
                centre_deg,
                half_range_deg,
            } => {
                let a = v_east.atan2(v_north);
                let theta = (centre_deg + half_range_deg * y[0]).to_radians();
                let w = sigmoid(y[1]);
                (a + w * wrap_rad(theta - a), y[2])
            }
            Head::Filter => {
                // No prior: the course, with the network's σ around a uniform error.
                let a = v_east.atan2(v_north);
                let cap = MAX_STD_DEG.to_radians();
                let base = KalmanBase {
                    p: cap * cap,
                    r2: cap * cap,
                };
                let (psi, ls, _, _) = filter_step(y, a, a, &base);
                (psi, ls + y[2])
            }
        }
    }

    /// Whether σ should come from the receiver's speed accuracy when it reports one:
    /// only for the full circle, where the heading is atan2 plus a small correction and
    /// its error is the receiver's velocity noise over the speed.
    pub fn uses_speed_accuracy(&self) -> bool {
        matches!(*self, Head::Residual { range_deg } if range_deg[1] - range_deg[0] >= 360.0)
    }

    /// Heading (degrees, [0, 360)) and standard deviation (degrees) from outputs `y`.
    #[inline]
    pub fn decode(&self, y: &[f32], v_north: f32, v_east: f32, sigma_scale: f32) -> (f32, f32) {
        let (psi, log_sigma) = self.raw(y, v_north, v_east);
        let mut deg = psi.to_degrees().rem_euclid(360.0);
        let (lo, hi) = self.range_deg();
        if hi - lo < 360.0 {
            deg = clip_to_range(deg, lo, hi);
        }
        let deg = if deg >= 360.0 { 0.0 } else { deg };
        let sigma = log_sigma.clamp(LOG_SIGMA_MIN, LOG_SIGMA_MAX).exp() * sigma_scale;
        (deg, sigma.to_degrees().min(MAX_STD_DEG))
    }
}

/// The Kalman step a temporal model corrects: prior variance `p` and measurement
/// variance `r2` (radians²) of one epoch.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KalmanBase {
    /// Prior variance: the previous σ² plus `q²·dt`, capped at a uniform error's.
    pub p: f32,
    /// Measurement variance `(σ_v/ŝ)²`; a velocity within its own noise gets the cap
    /// and no weight.
    pub r2: f32,
}

impl KalmanBase {
    /// The step's gain `P/(P + R²)` (0 when the measurement carries nothing).
    pub fn gain(&self) -> f32 {
        let cap = MAX_STD_DEG.to_radians();
        if self.r2 >= cap * cap * 0.999 {
            0.0
        } else {
            self.p / (self.p + self.r2)
        }
    }

    /// `ln σ` after a step with gain `g`: `½·ln((1−g)²P + g²R²)`.
    pub fn log_sigma(&self, g: f32) -> f32 {
        let v = (1.0 - g) * (1.0 - g) * self.p + g * g * self.r2;
        0.5 * v.max(1e-12).ln()
    }
}

/// The filter head's gain from its first output around the Kalman gain `k`:
/// `clamp(k + y/4, 0, 1)`, which reaches 0 (hold) and 1 (follow) exactly.
#[inline]
pub fn filter_gain(y: f32, k: f32) -> f32 {
    (k + 0.25 * y).clamp(0.0, 1.0)
}

/// One filter step ([`Head::Filter`]): from outputs `y`, the course `course = atan2(v_E,
/// v_N)`, the previous heading `prior` (radians) and the Kalman step `base`, the heading
/// (radians, not wrapped), the step's own `log σ` (what the history keeps; the reported
/// one adds `y₂`), the gain and the innovation `wrap(A + r·π − ψₚ)`.
#[inline]
pub fn filter_step(y: &[f32], course: f32, prior: f32, base: &KalmanBase) -> (f32, f32, f32, f32) {
    let g = filter_gain(y[0], base.gain());
    let z = if y[1] > 0.0 {
        course + std::f32::consts::PI
    } else {
        course
    };
    let d = wrap_rad(z - prior);
    (prior + g * d, base.log_sigma(g), g, d)
}

/// Scale velocities into the network's input: divided by the model's `input_scale_mps`,
/// so training and inference see the same numbers.
#[inline]
pub fn scale_input(v_north: f32, v_east: f32, input_scale: f32) -> [f32; 2] {
    [v_north / input_scale, v_east / input_scale]
}

/// The unscaled σ (radians) a receiver's speed accuracy implies for atan2 at this
/// velocity: `sAcc/ŝ`, capped at the uniform-circle value, where
/// `ŝ² = |v|² − 2·sAcc²` removes the noise's own contribution to the measured speed
/// (2-D noise adds `2σ²` to `E|v|²`; without this, a stopped vehicle's noise looks
/// like slow motion with a confident heading). `None` when sAcc is unknown, negative or
/// not finite.
pub fn accuracy_sigma_base(v_north: f32, v_east: f32, speed_acc: f32) -> Option<f32> {
    if !(speed_acc.is_finite() && speed_acc > 0.0) {
        return None;
    }
    let cap = crate::head::MAX_STD_DEG.to_radians();
    let s2 = v_north * v_north + v_east * v_east - 2.0 * speed_acc * speed_acc;
    Some(if s2 > 0.0 {
        (speed_acc / s2.sqrt()).min(cap)
    } else {
        cap
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wrap_and_heading_conventions() {
        assert!(
            (wrap_rad(359f32.to_radians() - 1f32.to_radians()).to_degrees() + 2.0).abs() < 1e-3
        );
        assert_eq!(heading_deg(1.0, 0.0), 0.0);
        assert!((heading_deg(0.0, 1.0) - 90.0).abs() < 1e-5);
        assert!((heading_deg(-1.0, 0.0) - 180.0).abs() < 1e-5);
        assert!((heading_deg(0.0, -1.0) - 270.0).abs() < 1e-5);
        assert!(heading_deg(1.0, -1e-9) < 360.0);
    }

    /// The wrap keeps in-range angles exactly, lands everything else in (−π, π] within
    /// float rounding of `atan2(sin x, cos x)`, keeps +π and sends −π to +π, and gives
    /// NaN for what has no direction.
    #[test]
    fn wrap_lands_in_the_half_open_turn() {
        use std::f32::consts::{PI, TAU};
        for x in [0.0, 1.0, -3.0, PI, 3.1, -3.1] {
            assert_eq!(wrap_rad(x), x);
        }
        assert_eq!(wrap_rad(-PI), PI);
        let mut x = -40.0f32;
        while x < 40.0 {
            let (w, old) = (wrap_rad(x), x.sin().atan2(x.cos()));
            assert!(w > -PI && w <= PI, "{x} -> {w}");
            let d = (w - old).abs();
            assert!(d.min(TAU - d) < 1e-5, "{x}: {w} against {old}");
            x += 0.0137;
        }
        for x in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
            assert!(wrap_rad(x).is_nan());
        }
    }

    #[test]
    fn decode_angle_and_residual() {
        let h = Head::Angle {
            centre_deg: 45.0,
            half_range_deg: 45.0,
        };
        let (deg, std) = h.decode(&[0.5, (0.01f32).ln()], 1.0, 1.0, 1.0);
        assert!((deg - 67.5).abs() < 1e-4);
        assert!((std - 0.01f32.to_degrees()).abs() < 1e-4);
        let r = Head::Residual {
            range_deg: [0.0, 360.0],
        };
        // Δ = atan2(1, 1) = 45° with an open gate on top of atan2 heading 90°.
        let (deg, _) = r.decode(&[1.0, 1.0, 30.0, 0.0], 0.0, 2.0, 1.0);
        assert!((deg - 135.0).abs() < 1e-3);
        // Half-open gate: half the rotation.
        let (deg, _) = r.decode(&[1.0, 1.0, 0.0, 0.0], 0.0, 2.0, 1.0);
        assert!((deg - 112.5).abs() < 1e-3);
        // σ is capped at the uniform-circle value.
        let (_, std) = r.decode(&[1.0, 0.0, 0.0, 3.0], 0.0, 2.0, 10.0);
        assert_eq!(std, MAX_STD_DEG);
    }

    #[test]
    fn restricted_residual_head_clamps_to_its_range() {
        let r = Head::Residual {
            range_deg: [0.0, 90.0],
        };
        let (deg, _) = r.decode(&[1.0, 0.0, 0.0, 0.0], -1.0, -1.2, 1.0); // atan2 = 230.2°
        assert_eq!(deg, 0.0);
    }
}
