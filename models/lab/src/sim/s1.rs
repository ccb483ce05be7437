//! The GHNet paper's S1 protocol: a discrete grid of speeds and headings in 0..90° with
//! white velocity noise.

use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};

use super::sample::{heading_f32, Sample, Split};

/// Parameters of the paper's S1 simulation (GHNet, Section IV-A, Table II).
///
/// The defaults are the paper's: speeds 0..=3.5 m/s in 0.1 steps, headings 0..=90° in
/// 0.5° steps, ten noise draws per combination, white Gaussian noise σ = 0.01 m/s on
/// v_N and v_E, random 80/20 split. The grid is the prior: [`crate::bayes::BayesS1`]
/// uses these same numbers to compute the Bayes-optimal estimate.
#[derive(Clone, Debug, PartialEq, clap::Args, Serialize, Deserialize)]
pub struct S1Params {
    /// Largest simulated speed (m/s); speeds run from 0 to this value inclusive.
    #[arg(long, default_value_t = 3.5)]
    pub speed_max: f64,
    /// Speed grid step (m/s).
    #[arg(long, default_value_t = 0.1)]
    pub speed_step: f64,
    /// Largest simulated heading (deg); headings run from 0 to this value inclusive.
    #[arg(long, default_value_t = 90.0)]
    pub heading_max: f64,
    /// Heading grid step (deg).
    #[arg(long, default_value_t = 0.5)]
    pub heading_step: f64,
    /// Noise draws per (speed, heading) combination.
    #[arg(long, default_value_t = 10)]
    pub draws: u32,
    /// Standard deviation of the white Gaussian noise on v_N and v_E (m/s).
    #[arg(long, default_value_t = 0.01)]
    pub sigma: f64,
    /// Share of samples put in the test split (chosen by a seeded shuffle); the rest is
    /// train, from which the trainer splits its own validation part.
    #[arg(long, default_value_t = 0.2)]
    pub test_fraction: f64,
}

impl Default for S1Params {
    fn default() -> Self {
        Self {
            speed_max: 3.5,
            speed_step: 0.1,
            heading_max: 90.0,
            heading_step: 0.5,
            draws: 10,
            sigma: 0.01,
            test_fraction: 0.2,
        }
    }
}

/// Number of points of a grid 0, step, …, max (inclusive, tolerant to rounding).
fn grid_len(max: f64, step: f64) -> usize {
    assert!(step > 0.0 && max >= 0.0, "grid needs step > 0 and max >= 0");
    (max / step + 1e-9).floor() as usize + 1
}

impl S1Params {
    /// The speed grid (m/s): `i * speed_step` for i = 0..=speed_max/speed_step.
    ///
    /// Computed as a product (not by accumulation) so that every point is the nearest
    /// float to its decimal value; shared with the Bayes estimator so that both use the
    /// very same prior support.
    pub fn speeds(&self) -> Vec<f64> {
        (0..grid_len(self.speed_max, self.speed_step))
            .map(|i| i as f64 * self.speed_step)
            .collect()
    }

    /// The heading grid (deg): `j * heading_step` for j = 0..=heading_max/heading_step.
    pub fn headings_deg(&self) -> Vec<f64> {
        (0..grid_len(self.heading_max, self.heading_step))
            .map(|j| j as f64 * self.heading_step)
            .collect()
    }
}

/// Simulates the paper's S1 data set.
///
/// Every (speed, heading) grid point is repeated `draws` times with independent white
/// Gaussian noise of σ = `sigma` on v_N and v_E; v_D is 0 (the paper assumes level
/// motion and adds no vertical noise). A seeded shuffle puts `test_fraction` of the
/// samples in [`Split::Test`] and the rest in [`Split::Train`]; samples are returned in
/// grid order (speed, heading, draw). `speed_acc` is the true σ (an ideal receiver).
///
/// Note the count: with the paper's parameters this gives 36 × 181 × 10 = 65,160
/// samples, although the paper reports 7,317 for the same description. No reading of
/// its text reproduces 7,317; we follow the protocol, not the count.
pub fn simulate_s1(p: &S1Params, seed: u64) -> Vec<Sample> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let speeds = p.speeds();
    let headings = p.headings_deg();
    let n = speeds.len() * headings.len() * p.draws as usize;
    let mut out = Vec::with_capacity(n);
    for (i, &s) in speeds.iter().enumerate() {
        for (j, &h) in headings.iter().enumerate() {
            let (sin, cos) = h.to_radians().sin_cos();
            for d in 0..p.draws {
                let nn: f64 = rng.sample(StandardNormal);
                let ne: f64 = rng.sample(StandardNormal);
                out.push(Sample {
                    t_s: d as f64,
                    track: (i * headings.len() + j) as u32,
                    v_north: (s * cos + p.sigma * nn) as f32,
                    v_east: (s * sin + p.sigma * ne) as f32,
                    v_down: 0.0,
                    speed_acc: p.sigma as f32,
                    true_heading_deg: heading_f32(h),
                    true_speed: s as f32,
                    sigma_v: p.sigma as f32,
                    split: Split::Train,
                });
            }
        }
    }
    let n_test = (p.test_fraction.clamp(0.0, 1.0) * n as f64).round() as usize;
    let mut idx: Vec<usize> = (0..n).collect();
    idx.shuffle(&mut rng);
    for &k in &idx[..n_test] {
        out[k].split = Split::Test;
    }
    out
}
