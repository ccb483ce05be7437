//! Whether a receiver's velocity noise is smoothed: the sign of a navigation filter's
//! output, which lags the course, as against raw Doppler velocity, which does not.
//!
//! A receiver that holds static (0.000 at rest) is led as if its course trailed by
//! `hold_lag_s` ([`ModeParams::lead_s`]): a static hold is part of a navigation
//! filter. But some pass raw velocity through and only snap it to zero at rest, and
//! leading those costs what the lead gains on the rest (the snap rows of
//! `models/reports/unmet.md`). The lag cannot be seen in the course without a truth;
//! the smoothing that causes it can: a filter averages its noise as it averages the
//! motion, so successive changes of its velocity agree in sign, while white noise makes
//! each change undo the last (their correlation is −½).
//!
//! [`ModeParams::lead_s`]: crate::modes::ModeParams

use super::vehicle::{SmoothLink, Vehicle};

/// Speed (m/s) from which an epoch's velocity change counts: both epochs of each change
/// at least this fast (a receiver that holds static reads 0.000 under 0.3–0.6 m/s).
pub const SMOOTH_SPEED: f32 = 0.3;

/// Longest epoch interval (s) whose changes count: 4 Hz and faster. Over longer
/// intervals a filter forgets most of one epoch's noise by the next, and its changes
/// anticorrelate nearly as raw velocity's do (a 0.5 s lag read at 2 Hz: about −0.17 on
/// the scale of [`SMOOTH_WHITE_BAR`]).
pub const SMOOTH_MAX_DT: f32 = 0.3;

/// Pairs of successive changes (each axis one pair) before [`Vehicle::smooth`] decides
/// anything: 20 s of driving at 5 Hz.
pub const SMOOTH_MIN_PAIRS: u32 = 200;

/// Pairs [`Vehicle::smooth`] averages over once it has that many: a running mean.
pub const SMOOTH_WINDOW: f32 = 2000.0;

/// Mean agreement of successive velocity changes under which the noise is taken to be
/// white ([`Vehicle::raw_velocity`]). White noise alone gives about −0.27 (the mean of
/// `2ab/(a²+b²)` for normal changes correlated by ρ = −½ is `(1 − √(1−ρ²))/ρ`); the
/// least smooth output a filter gives, white noise through one first-order lag of
/// 0.5–1.5 s, gives −0.08 to −0.03 at 5 Hz (ρ = −(1−φ)/2, φ the lag's decay over an
/// epoch); a vehicle's own accelerations push both up. The bar sits nearer white, so
/// that a filtering receiver is not taken for a raw one: a lead withheld from a lagging
/// receiver costs what it gains on the rest. On simulated drives (`models/unmet.sh`'s
/// snap and consumer sections) no filtering receiver came under it, while the snap
/// style's noisier drives did (the quietest ones, whose motion outweighs their noise,
/// stay led).
///
/// [`Vehicle::raw_velocity`]: crate::modes::Vehicle::raw_velocity
pub const SMOOTH_WHITE_BAR: f32 = -0.12;

/// Feed [`Vehicle::smooth`] with this epoch's velocity (`v`, north and east, m/s, of
/// norm `speed`), `dt` s after the previous one: each axis's change since then against
/// the change before, as `2ab/(a²+b²)` (bounded, so a glitch counts as one pair, not by
/// its size). A chain of changes needs evenly spaced epochs at [`SMOOTH_SPEED`] or
/// faster, at most [`SMOOTH_MAX_DT`] apart; anything else starts it again.
#[inline]
pub(super) fn update_smooth(vehicle: &mut Vehicle, v: [f32; 2], speed: f32, dt: f32) {
    if speed < SMOOTH_SPEED || speed.is_nan() {
        vehicle.smooth_last = None;
        return;
    }
    let last = match vehicle.smooth_last {
        Some(last) if dt > 0.0 && dt <= SMOOTH_MAX_DT => last,
        _ => {
            vehicle.smooth_last = Some(SmoothLink { v, change: None });
            return;
        }
    };
    let d = [v[0] - last.v[0], v[1] - last.v[1]];
    if let Some((d0, dt0)) = last.change {
        if (dt - dt0).abs() <= 0.1 * dt {
            for (a, b) in d0.into_iter().zip(d) {
                add_pair(vehicle, a, b);
            }
        }
    }
    vehicle.smooth_last = Some(SmoothLink {
        v,
        change: Some((d, dt)),
    });
}

/// One pair of successive changes `a`, `b` (m/s) of an axis into the running mean.
#[inline]
fn add_pair(vehicle: &mut Vehicle, a: f32, b: f32) {
    let sq = a * a + b * b;
    if sq > 0.0 {
        vehicle.smooth_n = vehicle.smooth_n.saturating_add(1);
        let w = 1.0 / (vehicle.smooth_n as f32).min(SMOOTH_WINDOW);
        let m = if vehicle.smooth.is_finite() {
            vehicle.smooth
        } else {
            0.0
        };
        vehicle.smooth = m + w * (2.0 * a * b / sq - m);
    }
}

impl Vehicle {
    /// Whether the receiver's velocity is raw: its noise white, not smoothed by a
    /// navigation filter ([`SMOOTH_WHITE_BAR`] after [`SMOOTH_MIN_PAIRS`]). A receiver
    /// that holds static but shows this passes raw velocity through, which does not
    /// trail a turn: it is not led as a filter's output is ([`ModeParams::lead_s`]).
    ///
    /// [`ModeParams::lead_s`]: crate::modes::ModeParams
    #[inline]
    pub fn raw_velocity(&self) -> bool {
        self.smooth_n >= SMOOTH_MIN_PAIRS && self.smooth < SMOOTH_WHITE_BAR
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_distr::StandardNormal;

    /// `n` epochs at 5 Hz driving north at 1.5 m/s with per-axis noise of σ 0.1 m/s,
    /// white or passed through a first-order lag of 1 s (scaled back to σ).
    fn fed(n: usize, smoothed: bool) -> Vehicle {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let mut v = Vehicle::UNKNOWN;
        let alpha = 1.0 - (-0.2f32).exp();
        let scale = (alpha * alpha / (1.0 - (1.0 - alpha).powi(2))).sqrt();
        let mut lp = [0.0f32; 2];
        for _ in 0..n {
            let mut noise = [0.0f32; 2];
            for (i, x) in noise.iter_mut().enumerate() {
                let w: f32 = rng.sample(StandardNormal);
                lp[i] += alpha * (w - lp[i]);
                *x = 0.1 * if smoothed { lp[i] / scale } else { w };
            }
            let u = [1.5 + noise[0], noise[1]];
            update_smooth(&mut v, u, u[0].hypot(u[1]), 0.2);
        }
        v
    }

    /// White noise makes successive changes disagree (−0.27 on average); through a
    /// first-order lag of 1 s they nearly stop disagreeing (−0.05), on the filter's
    /// side of the bar; neither decides before enough pairs.
    #[test]
    fn white_noise_reads_raw_and_smoothed_noise_does_not() {
        let white = fed(1000, false);
        assert!((white.smooth + 0.27).abs() < 0.08, "{white:?}");
        assert!(white.raw_velocity());
        let smooth = fed(1000, true);
        assert!(smooth.smooth > -0.08, "{smooth:?}");
        assert!(!smooth.raw_velocity());
        assert!(!fed(50, false).raw_velocity(), "too few pairs to say");
    }

    /// A stand (0.000), a 1 Hz interval or uneven spacing breaks the chain: no pair
    /// spans it.
    #[test]
    fn stands_and_long_intervals_break_the_chain() {
        let mut v = Vehicle::UNKNOWN;
        for (s, dt) in [
            (1.0, 0.2),
            (1.1, 0.2),
            (0.0, 0.2),
            (1.2, 0.2),
            (1.0, 1.0),
            (1.3, 0.2),
        ] {
            update_smooth(&mut v, [s, 0.0], s, dt);
        }
        assert_eq!(v.smooth_n, 0, "{v:?}");
        update_smooth(&mut v, [1.0, 0.0], 1.0, 0.2);
        assert_eq!(v.smooth_n, 1, "{v:?}");
        assert!(
            (v.smooth + 1.0).abs() < 1e-6,
            "one change undone by the next"
        );
    }
}
