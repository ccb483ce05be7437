//! A real log seen by a noisier receiver: receiver noise added to its velocities, its
//! truth and timing kept (`ghnet simulate noisy`, `models/noisy.sh`; the log is written
//! by [`crate::logs::write_log_csv`]).
//!
//! The simulator's drives are where the model was made, so they cannot say how it does
//! on a receiver unlike its training ones; a real drive can, once its receiver is made
//! worse in a known way. The noise is the drive simulator's receiver model (both take
//! it from `crate::sim`): per axis, a correlated part (first-order, `0.8σ`) and a white
//! part (`0.6σ`), σ per axis in all. The log's sAcc is kept (the receiver then
//! understates its noise, as RTKLIB's formal accuracy does) or dropped (a receiver
//! that gives none, as NMEA).

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

use crate::logs::LogTrack;
use crate::sim::{correlated_step, NOISE_CORRELATED_SHARE, NOISE_WHITE_SHARE};

/// The receiver noise [`add_receiver_noise`] adds.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReceiverNoise {
    /// Noise σ per axis, m/s.
    pub sigma: f32,
    /// Correlation time of the correlated part, s.
    pub corr_s: f64,
    /// Whether the log's speed accuracy is dropped (NaN) rather than kept.
    pub drop_acc: bool,
}

/// Adds `noise` to every epoch's velocity of `tracks` (each track's correlated part
/// starts afresh), drawing from `seed`; truth, time and true speed stay as they are.
pub fn add_receiver_noise(tracks: &mut [LogTrack], noise: ReceiverNoise, seed: u64) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let sigma = f64::from(noise.sigma);
    // The correlated part `a` and the white one `w` of an axis, each of unit variance.
    let added = |a: f64, w: f64| sigma * (NOISE_CORRELATED_SHARE * a + NOISE_WHITE_SHARE * w);
    for t in tracks.iter_mut() {
        let mut ar = [0.0f64; 2];
        for i in 0..t.len() {
            // A track's first epoch, or one after a backward step, starts the
            // correlated part from its stationary spread.
            let dt = if i > 0 { t.t_s[i] - t.t_s[i - 1] } else { 0.0 };
            let phi = if dt > 0.0 && noise.corr_s > 0.0 {
                (-dt / noise.corr_s).exp()
            } else {
                0.0
            };
            correlated_step(&mut ar, phi, &mut rng);
            let white: [f64; 2] = [rng.sample(StandardNormal), rng.sample(StandardNormal)];
            t.v_north[i] += added(ar[0], white[0]) as f32;
            t.v_east[i] += added(ar[1], white[1]) as f32;
            if noise.drop_acc {
                t.speed_acc[i] = f32::NAN;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A standing 1 Hz track of `n` epochs with sAcc 0.05 m/s.
    fn standing(n: usize) -> LogTrack {
        LogTrack {
            key: "a".into(),
            platform: None,
            t_s: (0..n).map(|i| i as f64).collect(),
            v_north: vec![0.0; n],
            v_east: vec![0.0; n],
            speed_acc: vec![0.05; n],
            truth_deg: vec![90.0; n],
            true_speed: vec![f32::NAN; n],
            receiver_course_deg: vec![f32::NAN; n],
        }
    }

    /// The added noise has σ per axis and, correlated over 2 s, carries over from one
    /// 1 Hz epoch to the next (about `0.64·e^(−1/2)` = 0.39); the truth is untouched and
    /// the sAcc kept or dropped as asked.
    #[test]
    fn the_noise_has_its_sigma_and_memory() {
        let noise = ReceiverNoise {
            sigma: 0.2,
            corr_s: 2.0,
            drop_acc: false,
        };
        let mut tracks = vec![standing(20_000)];
        add_receiver_noise(&mut tracks, noise, 7);
        let v = &tracks[0].v_north;
        let n = v.len() as f64;
        let var = v.iter().map(|&x| f64::from(x).powi(2)).sum::<f64>() / n;
        let lag1 = v
            .windows(2)
            .map(|w| f64::from(w[0]) * f64::from(w[1]))
            .sum::<f64>()
            / (n - 1.0);
        assert!((var.sqrt() - 0.2).abs() < 0.01, "σ {}", var.sqrt());
        assert!(
            (lag1 / var - 0.39).abs() < 0.05,
            "lag-1 correlation {}",
            lag1 / var
        );
        assert!(tracks[0].truth_deg.iter().all(|&h| h == 90.0));
        assert!(tracks[0].speed_acc.iter().all(|&a| a == 0.05));
        add_receiver_noise(
            &mut tracks,
            ReceiverNoise {
                drop_acc: true,
                ..noise
            },
            7,
        );
        assert!(tracks[0].speed_acc.iter().all(|a| a.is_nan()));
    }
}
