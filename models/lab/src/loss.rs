//! The losses that train the output heads (inference only decodes: `ghnet_models::head`).
//!
//! Both heading losses are the paper's MAE on the wrapped error. Every head's last output,
//! `log σ`, is trained with a Gaussian negative log-likelihood on the *detached* wrapped
//! error, so σ learns the error scale without pulling on the heading.

use ghnet_models::head::{sigmoid, wrap_rad, Head, LOG_SIGMA_MAX, LOG_SIGMA_MIN};

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
            return filter_loss(y, a, a, truth_deg, sigma_weight, dy);
        }
    }
    (loss, e, s.exp())
}

/// Loss of the filter head ([`ghnet_models::head::Head::Filter`]) for one epoch whose
/// course is `course` and whose previous heading is `prior` (radians), with its gradient
/// with respect to the four outputs in `dy`. Returns `(loss, wrapped error, raw σ)`.
///
/// `ψ = ψₚ + Σ g_j d_j` with softmax gains `g` and innovations `d = (0, wrap(A − ψₚ),
/// wrap(A + π − ψₚ))`, so `∂ψ/∂y_i = g_i (d_i − ψ + ψₚ)`.
pub fn filter_loss(
    y: &[f32],
    course: f32,
    prior: f32,
    truth_deg: f32,
    sigma_weight: f32,
    dy: &mut [f32],
) -> (f32, f32, f32) {
    let (psi, g, d) = ghnet_models::head::filter_step(y, course, prior);
    let e = wrap_rad(psi - truth_deg.to_radians());
    let sign = e.signum() * (e != 0.0) as i32 as f32;
    let s = y[3].clamp(LOG_SIGMA_MIN, LOG_SIGMA_MAX);
    let inv_var = (-2.0 * s).exp();
    let loss = e.abs() + sigma_weight * (0.5 * e * e * inv_var + s);
    let mean = psi - prior;
    let dd = [0.0, d[0], d[1]];
    for i in 0..3 {
        dy[i] = sign * g[i] * (dd[i] - mean);
    }
    dy[3] = if y[3] == s {
        sigma_weight * (1.0 - e * e * inv_var)
    } else {
        0.0
    };
    (loss, e, s.exp())
}

/// Initial bias of the output layer: the residual head starts at `Δ = 0`
/// (`c = 1, s = 0`), both heads at σ ≈ 1 rad.
pub fn initial_bias(head: &Head) -> Vec<f32> {
    match head {
        Head::Angle { .. } => vec![0.0, 0.0],
        Head::Residual { .. } => vec![1.0, 0.0, 0.0, 0.0],
        Head::Blend { .. } => vec![0.0, 0.0, 0.0],
        // Follow the course at first: the filter starts as atan2.
        Head::Filter => vec![0.0, 2.0, -2.0, 0.0],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The σ term uses the error as a constant (stop-gradient), which finite differences
    /// cannot see: heading outputs are checked with the σ term off, the σ output with it on.
    fn check_loss_grad(head: Head, y: &[f32], vn: f32, ve: f32, truth: f32) {
        let k_sigma = y.len() - 1;
        for k in 0..y.len() {
            let w = if k == k_sigma { 0.3 } else { 0.0 };
            let mut dy = vec![0.0; y.len()];
            head_loss(&head, y, vn, ve, truth, w, &mut dy);
            let h = 1e-3;
            let mut yp = y.to_vec();
            let mut ym = y.to_vec();
            yp[k] += h;
            ym[k] -= h;
            let mut tmp = vec![0.0; y.len()];
            let lp = head_loss(&head, &yp, vn, ve, truth, w, &mut tmp).0 as f64;
            let lm = head_loss(&head, &ym, vn, ve, truth, w, &mut tmp).0 as f64;
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

    /// The filter head (the temporal models' new layer) against finite differences,
    /// with a prior and without one, forward, holding and reversing configurations.
    #[test]
    fn filter_loss_gradient_matches_finite_differences() {
        check_loss_grad(Head::Filter, &[0.3, 1.2, -0.4, -0.5], 1.0, 0.5, 40.0);
        let cases: [([f32; 4], f32, f32, f32); 4] = [
            ([0.1, 0.8, -0.3, -1.0], 0.5, 0.2, 30.0),
            ([1.5, -0.2, 0.4, 0.3], 2.0, -1.0, 100.0),
            ([-0.4, 0.1, 1.1, -2.0], -2.5, 0.9, 45.0),
            ([0.0, 0.0, 0.0, 0.5], 3.0, -3.0, 200.0),
        ];
        for (y, course, prior, truth) in cases {
            for k in 0..4 {
                let w = if k == 3 { 0.3 } else { 0.0 };
                let mut dy = [0.0; 4];
                filter_loss(&y, course, prior, truth, w, &mut dy);
                let h = 1e-3;
                let (mut yp, mut ym) = (y, y);
                yp[k] += h;
                ym[k] -= h;
                let mut t = [0.0; 4];
                let lp = filter_loss(&yp, course, prior, truth, w, &mut t).0 as f64;
                let lm = filter_loss(&ym, course, prior, truth, w, &mut t).0 as f64;
                let fd = (lp - lm) / (2.0 * h as f64);
                assert!(
                    (fd - dy[k] as f64).abs() < 2e-3 * (1.0 + fd.abs()),
                    "{y:?} output {k}: analytic {} fd {fd}",
                    dy[k]
                );
            }
        }
    }
}
