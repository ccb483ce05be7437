//! Output heads: how the network's outputs become a heading and its standard deviation,
//! and the loss that trains them.
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

/// Bounds on the raw `log σ` output (σ in radians), so one bad output can't overflow.
const LOG_SIGMA_MIN: f32 = -12.0;
const LOG_SIGMA_MAX: f32 = 3.0;

/// Weight of the penalty that keeps the residual head's `(c, s)` near the unit circle,
/// where `atan2(s, c)` is well conditioned.
const NORM_PENALTY: f32 = 0.01;

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
}

/// Wrap radians to (−π, π].
#[inline]
pub fn wrap_rad(x: f32) -> f32 {
    let y = x.sin().atan2(x.cos());
    if y <= -std::f32::consts::PI {
        y + 2.0 * std::f32::consts::PI
    } else {
        y
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

#[inline]
fn sigmoid(x: f32) -> f32 {
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
        }
    }

    /// Predicted heading in radians (not wrapped) and raw `log σ`.
    #[inline]
    fn raw(&self, y: &[f32], v_north: f32, v_east: f32) -> (f32, f32) {
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

    /// Loss for one sample and its gradient with respect to the outputs, written to `dy`.
    ///
    /// Returns `(loss, wrapped error in radians, raw σ in radians)`. `sigma_weight` scales the
    /// likelihood term.
    pub fn loss(
        &self,
        y: &[f32],
        v_north: f32,
        v_east: f32,
        truth_deg: f32,
        sigma_weight: f32,
        dy: &mut [f32],
    ) -> (f32, f32, f32) {
        let (psi, log_sigma) = self.raw(y, v_north, v_east);
        let e = wrap_rad(psi - truth_deg.to_radians());
        let sign = if e > 0.0 {
            1.0
        } else if e < 0.0 {
            -1.0
        } else {
            0.0
        };
        let mut loss = e.abs();
        let s = log_sigma.clamp(LOG_SIGMA_MIN, LOG_SIGMA_MAX);
        let inv_var = (-2.0 * s).exp();
        loss += sigma_weight * (0.5 * e * e * inv_var + s);
        let ds = if log_sigma == s {
            sigma_weight * (1.0 - e * e * inv_var)
        } else {
            0.0
        };
        match *self {
            Head::Angle { half_range_deg, .. } => {
                dy[0] = sign * half_range_deg.to_radians();
                dy[1] = ds;
            }
            Head::Blend {
                centre_deg,
                half_range_deg,
            } => {
                let a = v_east.atan2(v_north);
                let d = wrap_rad((centre_deg + half_range_deg * y[0]).to_radians() - a);
                let w = sigmoid(y[1]);
                dy[0] = sign * w * half_range_deg.to_radians();
                dy[1] = sign * d * w * (1.0 - w);
                dy[2] = ds;
            }
            Head::Residual { .. } => {
                let (c, sn) = (y[0], y[1]);
                let r2 = (c * c + sn * sn).max(1e-12);
                let pen = r2 - 1.0;
                let w = sigmoid(y[2]);
                loss += NORM_PENALTY * pen * pen;
                dy[0] = sign * w * (-sn / r2) + NORM_PENALTY * 4.0 * pen * c;
                dy[1] = sign * w * (c / r2) + NORM_PENALTY * 4.0 * pen * sn;
                dy[2] = sign * sn.atan2(c) * w * (1.0 - w);
                dy[3] = ds;
            }
        }
        (loss, e, s.exp())
    }

    /// Initial bias of the output layer: the residual head starts at `Δ = 0`
    /// (`c = 1, s = 0`), both heads at σ ≈ 1 rad.
    pub fn initial_bias(&self) -> Vec<f32> {
        match self {
            Head::Angle { .. } => vec![0.0, 0.0],
            Head::Residual { .. } => vec![1.0, 0.0, 0.0, 0.0],
            Head::Blend { .. } => vec![0.0, 0.0, 0.0],
        }
    }
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

    /// The σ term uses the error as a constant (stop-gradient), which finite differences
    /// cannot see: heading outputs are checked with the σ term off, the σ output with it on.
    fn check_loss_grad(head: Head, y: &[f32], vn: f32, ve: f32, truth: f32) {
        let k_sigma = y.len() - 1;
        for k in 0..y.len() {
            let w = if k == k_sigma { 0.3 } else { 0.0 };
            let mut dy = vec![0.0; y.len()];
            head.loss(y, vn, ve, truth, w, &mut dy);
            let h = 1e-3;
            let mut yp = y.to_vec();
            let mut ym = y.to_vec();
            yp[k] += h;
            ym[k] -= h;
            let mut tmp = vec![0.0; y.len()];
            let lp = head.loss(&yp, vn, ve, truth, w, &mut tmp).0 as f64;
            let lm = head.loss(&ym, vn, ve, truth, w, &mut tmp).0 as f64;
            let fd = (lp - lm) / (2.0 * h as f64);
            assert!(
                (fd - dy[k] as f64).abs() < 2e-3 * (1.0 + fd.abs()),
                "{head:?} output {k}: analytic {} fd {fd}",
                dy[k]
            );
        }
    }

    #[test]
    fn head_loss_gradients_match_finite_differences() {
        let angle = Head::Angle {
            centre_deg: 45.0,
            half_range_deg: 45.0,
        };
        check_loss_grad(angle, &[0.3, -1.2], 1.0, 0.5, 20.0);
        check_loss_grad(angle, &[-0.7, 0.4], 0.1, 0.2, 80.0);
        let r = Head::Residual {
            range_deg: [0.0, 360.0],
        };
        check_loss_grad(r, &[0.9, 0.2, 0.3, -0.5], 1.0, 0.5, 10.0);
        check_loss_grad(r, &[1.3, -0.4, -0.8, 0.7], -1.0, -0.5, 300.0);
        let b = Head::Blend {
            centre_deg: 45.0,
            half_range_deg: 45.0,
        };
        check_loss_grad(b, &[0.2, 0.3, -0.5], 1.0, 0.5, 60.0);
        check_loss_grad(b, &[-0.6, -1.1, 0.4], -0.1, 0.05, 10.0);
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
