//! The losses that train the output heads (inference only decodes: `ghnet_inference::head`).
//!
//! Both heading losses are the paper's MAE on the wrapped error. Every head's last output,
//! `log σ`, is trained with a Gaussian negative log-likelihood on the *detached* wrapped
//! error, so σ learns the error scale without pulling on the heading.

use ghnet_inference::head::{sigmoid, wrap_rad, Head, KalmanBase, LOG_SIGMA_MAX, LOG_SIGMA_MIN};
use ghnet_inference::modes::{corrected_gain, reverse_logit, Step};

/// Weight of the penalty that keeps the residual head's `(c, s)` near the unit circle,
/// where `atan2(s, c)` is well conditioned.
const NORM_PENALTY: f32 = 0.01;

/// Loss for one sample and its gradient with respect to the outputs, written to `dy`.
///
/// Returns `(loss, wrapped error in radians, raw σ in radians)`. `sigma_weight` scales the
/// likelihood term.
pub fn head_loss(
    head: &Head,
    y: &[f32],
    v_north: f32,
    v_east: f32,
    truth_deg: f32,
    sigma_weight: f32,
    dy: &mut [f32],
) -> (f32, f32, f32) {
    let (psi, log_sigma) = head.raw(y, v_north, v_east);
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
    match *head {
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
        Head::Filter => {
            // Without a prior (`Head::raw`): the filter step from ψₚ = A.
            let a = v_east.atan2(v_north);
            let r = reverse_label(v_north, v_east, truth_deg);
            let cap = ghnet_inference::head::MAX_STD_DEG.to_radians();
            let base = KalmanBase {
                p: cap * cap,
                r2: cap * cap,
            };
            return filter_loss(y, a, a, &base, truth_deg, r, sigma_weight, dy);
        }
    }
    (loss, e, s.exp())
}

/// Slope of the gain's surrogate gradient outside its clamp, relative to inside.
pub const GAIN_LEAK: f32 = 0.05;

/// Weight of the reverse switch's classification loss against the heading MAE
/// (radians): a misread direction costs 180°, so the switch earns a strong signal.
pub const REVERSE_WEIGHT: f32 = 0.2;

/// Loss of the filter head ([`ghnet_inference::head::Head::Filter`]) for one epoch whose
/// course is `course` and whose previous heading is `prior` (radians), with its gradient
/// with respect to the three outputs in `dy`. Returns `(loss, wrapped error, raw σ)`.
///
/// `ψ = ψₚ + g·d`, `g = clamp(K + y₀/4, 0, 1)` around the Kalman gain `K` of `base`,
/// `d = wrap(A + r·π − ψₚ)`: the MAE's
/// gradient is `sign(e)·d/4` on `y₀` inside the clamp, and a surrogate with
/// [`GAIN_LEAK`] of that slope outside it, so an epoch held (or followed) wrongly still
/// pulls its gain back instead of sitting in a flat zone. The switch `y₁` gets a
/// logistic loss towards `reverse` (the course is opposite to the true heading) when
/// that label is known (`Some`); `y₂` (the correction of the step's `log σ`) the
/// Gaussian likelihood of the detached error; `log σ`'s dependence on the gain is left
/// out of the gradient (detached too).
#[allow(clippy::too_many_arguments)] // one epoch's numbers
pub fn filter_loss(
    y: &[f32],
    course: f32,
    prior: f32,
    base: &KalmanBase,
    truth_deg: f32,
    reverse: Option<bool>,
    sigma_weight: f32,
    dy: &mut [f32],
) -> (f32, f32, f32) {
    let (psi, step_log_sigma, _, d) = ghnet_inference::head::filter_step(y, course, prior, base);
    let log_sigma = step_log_sigma + y[2];
    let e = wrap_rad(psi - truth_deg.to_radians());
    let sign = e.signum() * (e != 0.0) as i32 as f32;
    let (nll, dsigma, sigma) = sigma_likelihood(e, log_sigma, sigma_weight);
    let mut loss = e.abs() + nll;
    let raw_gain = base.gain() + 0.25 * y[0];
    let slope = if (0.0..=1.0).contains(&raw_gain) {
        0.25
    } else {
        0.25 * GAIN_LEAK
    };
    dy[0] = sign * slope * d;
    dy[1] = 0.0;
    if let Some(r) = reverse {
        let (l, d) = reverse_loss(y[1], r);
        loss += l;
        dy[1] = d;
    }
    dy[2] = dsigma;
    (loss, e, sigma)
}

/// The weighted logistic loss of the reverse logit `logit` towards label `reverse`, and
/// its derivative with respect to the logit.
fn reverse_loss(logit: f32, reverse: bool) -> (f32, f32) {
    // Written stably: log(1 + e^{−z}) for z = ±logit.
    let z = if reverse { logit } else { -logit };
    (
        REVERSE_WEIGHT * (-z.min(0.0) + (-z.abs()).exp().ln_1p()),
        REVERSE_WEIGHT * (sigmoid(logit) - reverse as i32 as f32),
    )
}

/// The weighted Gaussian negative log-likelihood of the (detached) error `e` under
/// `log σ`, clamped to its bounds; its derivative with respect to `log σ` (zero where
/// the clamp holds it); and the clamped σ.
fn sigma_likelihood(e: f32, log_sigma: f32, sigma_weight: f32) -> (f32, f32, f32) {
    let s = log_sigma.clamp(LOG_SIGMA_MIN, LOG_SIGMA_MAX);
    let inv_var = (-2.0 * s).exp();
    let d = if log_sigma == s {
        sigma_weight * (1.0 - e * e * inv_var)
    } else {
        0.0
    };
    (sigma_weight * (0.5 * e * e * inv_var + s), d, s.exp())
}

/// Loss of the temporal model's correction of one mode-filter step
/// ([`ghnet_inference::modes::commit`]) and its gradient with respect to the three outputs
/// in `dy`. Returns `(loss, wrapped error, raw σ)`.
///
/// The heading is `ψ = ψₚ + g·d` with `g` the Kalman gain `K` corrected in log-odds by
/// `y₀` (`∂g/∂y₀ = g(1−g)`) and `d = wrap(A + r·π − ψₚ)`, `r` the reverse decision
/// `[y₁ ± REVERSE_PRIOR > 0]`; the loss is the paper's MAE on its wrapped error. The
/// decision is a step, so `y₁` learns by classification instead: a logistic loss
/// (weight [`REVERSE_WEIGHT`]) towards `reverse` (the vehicle truly moves backwards)
/// when that label is known. `y₂` corrects the step's `log σ` and gets the Gaussian
/// likelihood of the detached error. A step that only holds (before the first motion)
/// or jumps (a decision against the rule) has no gain to learn.
pub fn mode_loss(
    y: &[f32],
    step: &Step,
    truth_deg: f32,
    reverse: Option<bool>,
    sigma_weight: f32,
    dy: &mut [f32],
) -> (f32, f32, f32) {
    dy[..3].fill(0.0);
    let truth = truth_deg.to_radians();
    if step.hold {
        let e = wrap_rad(step.prior - truth);
        return (0.0, e, ghnet_inference::head::MAX_STD_DEG.to_radians());
    }
    let logit = reverse_logit(step.rule_reverse, y[1]);
    let rev = logit > 0.0;
    let z = step.course + if rev { std::f32::consts::PI } else { 0.0 };
    let d = wrap_rad(z - step.prior);
    let jump = rev != step.rule_reverse
        && step.moving
        && !step.glitch
        && d.abs() > 0.5 * std::f32::consts::PI;
    let (psi, var, dg) = if jump {
        (z, step.r2, 0.0)
    } else {
        let g = corrected_gain(step.k, y[0]);
        let v = (1.0 - g) * (1.0 - g) * step.p + g * g * step.r2;
        (step.prior + g * d, v, g * (1.0 - g))
    };
    let e = wrap_rad(psi - truth);
    let sign = e.signum() * (e != 0.0) as i32 as f32;
    let log_sigma = 0.5 * var.max(1e-12).ln() + y[2];
    let (nll, dsigma, sigma) = sigma_likelihood(e, log_sigma, sigma_weight);
    let mut loss = e.abs() + nll;
    dy[0] = sign * d * dg;
    if let (Some(r), true) = (reverse, step.moving) {
        let (l, d) = reverse_loss(logit, r);
        loss += l;
        dy[1] = d;
    }
    dy[2] = dsigma;
    (loss, e, sigma)
}

/// The reverse label of an epoch: `Some(course opposite to the true heading)` when the
/// velocity clearly shows a direction (over 0.3 m/s and within 60° of either the heading
/// or its opposite), `None` otherwise.
pub fn reverse_label(v_north: f32, v_east: f32, truth_deg: f32) -> Option<bool> {
    let c = (v_east.atan2(v_north) - truth_deg.to_radians()).cos();
    (v_north.hypot(v_east) > 0.3 && c.abs() > 0.5).then_some(c < 0.0)
}

/// Initial bias of the output layer: the residual head starts at `Δ = 0`
/// (`c = 1, s = 0`), both heads at σ ≈ 1 rad.
pub fn initial_bias(head: &Head) -> Vec<f32> {
    match head {
        Head::Angle { .. } => vec![0.0, 0.0],
        Head::Residual { .. } => vec![1.0, 0.0, 0.0, 0.0],
        Head::Blend { .. } => vec![0.0, 0.0, 0.0],
        // The Kalman step unchanged, forwards: the filter starts as the baseline.
        Head::Filter => vec![0.0, -3.0, 0.0],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Holds the analytic gradient that `loss(y, sigma_weight, dy)` writes against
    /// central finite differences of the loss it returns, output by output; `case`
    /// names the failing case. The σ term uses the error as a constant
    /// (stop-gradient), which finite differences cannot see: heading outputs are
    /// checked with the σ term off, the σ output (the last) with it on.
    fn check_grad(
        case: &dyn std::fmt::Debug,
        y: &[f32],
        loss: impl Fn(&[f32], f32, &mut [f32]) -> (f32, f32, f32),
    ) {
        let k_sigma = y.len() - 1;
        for k in 0..y.len() {
            let w = if k == k_sigma { 0.3 } else { 0.0 };
            let mut dy = vec![0.0; y.len()];
            loss(y, w, &mut dy);
            let h = 1e-3;
            let (mut yp, mut ym) = (y.to_vec(), y.to_vec());
            yp[k] += h;
            ym[k] -= h;
            let mut tmp = vec![0.0; y.len()];
            let lp = loss(&yp, w, &mut tmp).0 as f64;
            let lm = loss(&ym, w, &mut tmp).0 as f64;
            let fd = (lp - lm) / (2.0 * h as f64);
            assert!(
                (fd - dy[k] as f64).abs() < 2e-3 * (1.0 + fd.abs()),
                "{case:?} output {k}: analytic {} fd {fd}",
                dy[k]
            );
        }
    }

    fn check_loss_grad(head: Head, y: &[f32], vn: f32, ve: f32, truth: f32) {
        check_grad(&head, y, |y, w, dy| {
            head_loss(&head, y, vn, ve, truth, w, dy)
        });
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

    /// The filter head (the temporal models' new layer) against finite differences,
    /// with a prior and without one, holding, following and reversing, with and without
    /// a reverse label. The switch is a step in `y₁`, so `y₁` is kept away from 0.
    #[test]
    fn filter_loss_gradient_matches_finite_differences() {
        check_loss_grad(Head::Filter, &[0.3, 1.2, -0.5], 1.0, 0.5, 40.0);
        type Case = ([f32; 3], f32, f32, f32, Option<bool>);
        let cases: [Case; 5] = [
            ([0.1, 0.8, -1.0], 0.5, 0.2, 30.0, Some(true)),
            ([0.5, -0.7, 0.3], 2.0, -1.0, 100.0, Some(false)),
            ([-0.4, 1.1, -2.0], -2.5, 0.9, 45.0, None),
            ([0.0, -0.5, 0.5], 3.0, -3.0, 200.0, Some(true)),
            ([-0.5, 2.5, 0.1], 1.0, 1.2, 250.0, Some(false)),
        ];
        let base = KalmanBase { p: 0.04, r2: 0.05 };
        for (y, course, prior, truth, rev) in cases {
            check_grad(&y, &y, |y, w, dy| {
                filter_loss(y, course, prior, &base, truth, rev, w, dy)
            });
        }
    }

    /// The mode filter's correction (the temporal model's new layer) against finite
    /// differences: holding, following, reversing by the rule, with and without a
    /// label, a zero Kalman gain. The decision is a step in `y₁`, kept away from it.
    #[test]
    fn mode_loss_gradient_matches_finite_differences() {
        let step = |course: f32, prior: f32, k: f32, rule: bool| Step {
            course,
            prior,
            p: 0.04,
            r2: 0.05,
            k,
            rule_reverse: rule,
            moving: true,
            hold: false,
            glitch: false,
            sigma_v: 0.1,
            speed: 1.0,
            has_acc: true,
            acc: 0.1,
            lead_s: 0.0,
            lever_s: 0.0,
            lever_max: 0.0,
        };
        type Case = ([f32; 3], Step, f32, Option<bool>);
        let cases: [Case; 6] = [
            (
                [0.1, 0.8, -1.0],
                step(0.5, 0.2, 0.4, false),
                30.0,
                Some(true),
            ),
            (
                [0.5, -0.7, 0.3],
                step(2.0, -1.0, 0.7, true),
                100.0,
                Some(false),
            ),
            ([-0.4, 1.1, -2.0], step(-2.5, 0.9, 0.2, false), 45.0, None),
            (
                [0.0, -0.5, 0.5],
                step(3.0, -3.0, 0.9, true),
                200.0,
                Some(true),
            ),
            (
                [-0.5, 2.5, 0.1],
                step(1.0, 1.2, 0.0, false),
                250.0,
                Some(false),
            ),
            (
                [1.5, -6.0, 0.4],
                step(0.3, 0.1, 0.5, true),
                10.0,
                Some(false),
            ),
        ];
        for (y, st, truth, rev) in cases {
            check_grad(&y, &y, |y, w, dy| mode_loss(y, &st, truth, rev, w, dy));
        }
    }
}
