//! Bayes-optimal heading for the S1 prior: the physical limit of any one-epoch estimator.
//!
//! S1 draws (speed, heading) uniformly from a discrete grid and adds isotropic Gaussian
//! noise σ to v_N and v_E. For an observation v = (v_N, v_E) the posterior over the
//! grid is
//!
//! p(s_i, ψ_j | v) ∝ exp(−|v − s_i·u(ψ_j)|² / 2σ²) ∝ exp((s_i·(v·u(ψ_j)) − s_i²/2) / σ²),
//!
//! with u(ψ) = (cos ψ, sin ψ); |v|² is common to all grid points and drops out. Summing
//! over speeds (log-sum-exp, since the exponents reach 10⁵ at σ = 0.01 m/s) gives the
//! posterior over heading. Its median minimises the expected absolute error (MAE), its
//! mean the expected squared error (RMSE). No network that sees one S1 epoch can do
//! better in expectation; a "gain" beyond this is an evaluation error.
//!
//! The prior IS the discrete grid, so it is used exactly rather than as a continuous
//! density.

use crate::eval::{Estimate, BAYES};
use crate::sim::{S1Params, Sample};

/// Posterior summary for one observation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Posterior {
    /// Posterior median (deg): the MAE-optimal estimate.
    pub median_deg: f32,
    /// Posterior mean (deg): the RMSE-optimal estimate (for a heading support under
    /// 180°, where wrapped and linear errors agree; otherwise the circular mean, an
    /// approximation).
    pub mean_deg: f32,
    /// Posterior standard deviation (deg) (for a support of 180° or more, the RMS of
    /// the wrapped deviation from the circular mean): the σ a calibrated estimator
    /// would report.
    pub std_deg: f32,
}

/// The median, mean and posterior σ for a batch of samples, ready for evaluation.
#[derive(Clone, Debug, PartialEq)]
pub struct BayesEstimates {
    /// Posterior medians, named [`BAYES`], with the posterior σ as its std.
    pub median: Estimate,
    /// Posterior means, named "bayes-mean", with the same posterior σ.
    pub mean: Estimate,
}

/// Bayes-optimal estimator for the S1 prior (see the module docs for the math).
///
/// Precomputes the grid once; each observation costs one pass over the
/// speeds × headings grid (36 × 181 with the paper's parameters).
#[derive(Clone, Debug)]
pub struct BayesS1 {
    /// s_i / σ² per speed.
    a: Vec<f64>,
    /// s_i² / (2σ²) per speed.
    b: Vec<f64>,
    headings_deg: Vec<f64>,
    cos: Vec<f64>,
    sin: Vec<f64>,
    /// The heading support spans 180° or more: wrapped and linear errors differ and
    /// the median must be found on the circle.
    wide: bool,
}

impl BayesS1 {
    /// Builds the estimator for the prior and noise of `p` (the same grid
    /// [`crate::sim::simulate_s1`] draws from).
    pub fn new(p: &S1Params) -> Self {
        let var = p.sigma * p.sigma;
        let speeds = p.speeds();
        let headings_deg = p.headings_deg();
        let (sin, cos) = headings_deg
            .iter()
            .map(|h| h.to_radians().sin_cos())
            .unzip();
        let span = headings_deg.last().copied().unwrap_or(0.0) - headings_deg[0];
        Self {
            a: speeds.iter().map(|s| s / var).collect(),
            b: speeds.iter().map(|s| s * s / (2.0 * var)).collect(),
            wide: span >= 180.0,
            headings_deg,
            cos,
            sin,
        }
    }

    /// Number of heading grid points: the length of the scratch [`Self::posterior`] uses.
    pub fn n_headings(&self) -> usize {
        self.headings_deg.len()
    }

    /// Posterior summary for one observation (v_N, v_E) in m/s.
    ///
    /// `weights` is caller-owned scratch (resized as needed) so that a loop over many
    /// samples allocates nothing; on return it holds the normalised posterior over the
    /// heading grid.
    pub fn posterior(&self, vn: f32, ve: f32, weights: &mut Vec<f64>) -> Posterior {
        let (vn, ve) = (vn as f64, ve as f64);
        weights.clear();
        // Log posterior per heading: log-sum-exp over speeds.
        let mut max_lw = f64::NEG_INFINITY;
        for (c, s) in self.cos.iter().zip(&self.sin) {
            let proj = vn * c + ve * s;
            let m = self
                .a
                .iter()
                .zip(&self.b)
                .map(|(a, b)| a * proj - b)
                .fold(f64::NEG_INFINITY, f64::max);
            let sum: f64 = self
                .a
                .iter()
                .zip(&self.b)
                .map(|(a, b)| (a * proj - b - m).exp())
                .sum();
            let lw = m + sum.ln();
            max_lw = max_lw.max(lw);
            weights.push(lw);
        }
        let mut total = 0.0;
        for w in weights.iter_mut() {
            *w = (*w - max_lw).exp();
            total += *w;
        }
        for w in weights.iter_mut() {
            *w /= total;
        }
        if self.wide {
            self.summary_circular(weights)
        } else {
            self.summary_linear(weights)
        }
    }

    /// Support under 180°: wrapped errors between points of the support are linear
    /// differences, so the linear median and mean are optimal.
    fn summary_linear(&self, w: &[f64]) -> Posterior {
        let mut cum = 0.0;
        let mut median = *self.headings_deg.last().expect("non-empty grid");
        for (wj, h) in w.iter().zip(&self.headings_deg) {
            cum += wj;
            if cum >= 0.5 {
                median = *h;
                break;
            }
        }
        let mean: f64 = w.iter().zip(&self.headings_deg).map(|(w, h)| w * h).sum();
        let var: f64 = w
            .iter()
            .zip(&self.headings_deg)
            .map(|(w, h)| w * (h - mean) * (h - mean))
            .sum();
        Posterior {
            median_deg: median as f32,
            mean_deg: mean as f32,
            std_deg: var.max(0.0).sqrt() as f32,
        }
    }

    /// Support of 180° or more: the circular median by brute force over grid points
    /// (quadratic in the number of headings, fine for a few hundred) and the circular
    /// mean with the spread around it.
    fn summary_circular(&self, w: &[f64]) -> Posterior {
        let mut best = (f64::INFINITY, 0.0);
        for &cand in &self.headings_deg {
            let cost: f64 = w
                .iter()
                .zip(&self.headings_deg)
                .map(|(w, h)| w * crate::eval::wrap_deg((h - cand) as f32).abs() as f64)
                .sum();
            if cost < best.0 {
                best = (cost, cand);
            }
        }
        let c: f64 = w.iter().zip(&self.cos).map(|(w, c)| w * c).sum();
        let s: f64 = w.iter().zip(&self.sin).map(|(w, s)| w * s).sum();
        let mean = s.atan2(c).to_degrees().rem_euclid(360.0);
        // RMS of the wrapped deviation from the mean rather than the circular std
        // sqrt(−2 ln R): it is bounded (≈104° for a uniform posterior) and is in the
        // same units as the wrapped errors the calibration table compares it to.
        let var: f64 = w
            .iter()
            .zip(&self.headings_deg)
            .map(|(w, h)| w * (crate::eval::wrap_deg((h - mean) as f32) as f64).powi(2))
            .sum();
        Posterior {
            median_deg: best.1 as f32,
            mean_deg: mean as f32,
            std_deg: var.sqrt() as f32,
        }
    }

    /// Posterior median and mean for every sample, as estimates for [`crate::eval`].
    pub fn estimates(&self, samples: &[Sample]) -> BayesEstimates {
        let mut scratch = Vec::with_capacity(self.n_headings());
        let mut median = Vec::with_capacity(samples.len());
        let mut mean = Vec::with_capacity(samples.len());
        let mut std = Vec::with_capacity(samples.len());
        for s in samples {
            let p = self.posterior(s.v_north, s.v_east, &mut scratch);
            median.push(p.median_deg);
            mean.push(p.mean_deg);
            std.push(p.std_deg);
        }
        BayesEstimates {
            median: Estimate {
                name: BAYES.to_owned(),
                heading_deg: median,
                std_deg: Some(std.clone()),
            },
            mean: Estimate {
                name: format!("{BAYES}-mean"),
                heading_deg: mean,
                std_deg: Some(std),
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::eval::{atan2_heading_deg, evaluate, EvalConfig, Truth, ATAN2};
    use crate::sim::{simulate_s1, Split};

    #[test]
    fn large_speed_matches_atan2() {
        let bayes = BayesS1::new(&S1Params::default());
        let mut w = Vec::new();
        for h in [3.0f64, 27.5, 61.0, 88.5] {
            let (s, c) = h.to_radians().sin_cos();
            let (vn, ve) = ((3.0 * c) as f32, (3.0 * s) as f32);
            let p = bayes.posterior(vn, ve, &mut w);
            let a = atan2_heading_deg(vn, ve);
            assert!((p.median_deg - a).abs() < 0.3, "{h}: {p:?} vs {a}");
            assert!((p.mean_deg - a).abs() < 0.3, "{h}: {p:?} vs {a}");
            assert!(p.std_deg < 0.5);
        }
    }

    #[test]
    fn zero_observation_gives_the_prior_centre() {
        let bayes = BayesS1::new(&S1Params::default());
        let mut w = Vec::new();
        let p = bayes.posterior(0.0, 0.0, &mut w);
        assert_eq!(p.median_deg, 45.0);
        assert!((p.mean_deg - 45.0).abs() < 1e-3);
        // Uniform over 0..90 in 0.5 steps: std = 0.5·sqrt((181² − 1)/12).
        let expected = 0.5 * ((181.0f64 * 181.0 - 1.0) / 12.0).sqrt();
        assert!((p.std_deg as f64 - expected).abs() < 1e-2, "{p:?}");
        assert!(w.iter().all(|x| (x - 1.0 / 181.0).abs() < 1e-12));
    }

    #[test]
    fn far_outside_the_prior_is_stable() {
        // Exponents of order 1e7: log-sum-exp must keep everything finite.
        let bayes = BayesS1::new(&S1Params::default());
        let mut w = Vec::new();
        let p = bayes.posterior(-30.0, -30.0, &mut w);
        assert!(p.median_deg.is_finite() && p.mean_deg.is_finite() && p.std_deg.is_finite());
        // Due west at 5 m/s is impossible under the prior except as noise around a
        // standstill, so the posterior is the (uniform) prior: median 45°.
        let p = bayes.posterior(0.0, -5.0, &mut w);
        assert_eq!(p.median_deg, 45.0);
        // Slightly west of north at 1 m/s is explained by heading 0 at the edge.
        let (s, c) = (-5f64).to_radians().sin_cos();
        let p = bayes.posterior(c as f32, s as f32, &mut w);
        assert_eq!(p.median_deg, 0.0);
    }

    #[test]
    fn full_circle_prior_is_symmetric() {
        let params = S1Params {
            heading_max: 358.0,
            heading_step: 2.0,
            speed_max: 1.0,
            ..S1Params::default()
        };
        let bayes = BayesS1::new(&params);
        let mut w = Vec::new();
        // With a uniform heading prior the posterior is symmetric about the observed
        // direction (here a grid heading, so the discrete grid is symmetric about it too).
        let (s, c) = 150f64.to_radians().sin_cos();
        // (f32 rounding of the observation leaves a trace of asymmetry: 1e-2 tolerance.)
        let p = bayes.posterior((0.1 * c) as f32, (0.1 * s) as f32, &mut w);
        assert!(
            crate::eval::wrap_deg(p.mean_deg - 150.0).abs() < 1e-2,
            "{p:?}"
        );
        assert!(
            crate::eval::wrap_deg(p.median_deg - 150.0).abs() < 1e-3,
            "{p:?}"
        );
        // About σ/s = 0.1 rad ≈ 5.7°, widened by the neighbouring speeds.
        assert!((2.0..20.0).contains(&p.std_deg), "{p:?}");
        // Nothing observed: uniform on the circle, std of a uniform circle ≈ 180/√3.
        let p = bayes.posterior(0.0, 0.0, &mut w);
        assert!((p.std_deg - 180.0 / 3f32.sqrt()).abs() < 1.5, "{p:?}");
    }

    #[test]
    fn beats_atan2_in_every_bin_on_s1_test() {
        let params = S1Params::default();
        let samples: Vec<Sample> = simulate_s1(&params, 42)
            .into_iter()
            .filter(|s| s.split == Split::Test)
            .collect();
        let bayes = BayesS1::new(&params).estimates(&samples);
        let r = evaluate(
            &Truth::from_samples(&samples),
            &[Estimate::atan2(&samples), bayes.median, bayes.mean],
            &EvalConfig::default(),
        )
        .unwrap();
        assert_eq!(r.bins.len(), 36);
        for row in &r.bins {
            let a = row.stats_of(ATAN2).unwrap();
            let b = row.stats_of(BAYES).unwrap();
            assert!(b.mae_deg <= a.mae_deg, "{}: {b:?} vs {a:?}", row.label);
        }
        let a = r.overall.stats_of(ATAN2).unwrap().rmse_deg;
        let m = r.overall.stats_of("bayes-mean").unwrap().rmse_deg;
        assert!(m <= a, "mean rmse {m} vs atan2 {a}");
        // The posterior σ is roughly calibrated (it is the truth's own posterior).
        let cover = r.overall.stats_of(BAYES).unwrap().within_2sigma.unwrap();
        assert!(cover > 0.85, "2σ coverage {cover}");
    }
}
