//! Samples of a simulated data set, their split and their CSV form, and the draws and
//! heading conventions both simulators share.

use std::path::Path;

use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};

/// Which part of a data set a sample belongs to.
///
/// Stored with every sample so that the split travels with the CSV and cannot be
/// recomputed differently by a later reader.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Split {
    /// Used to fit the model.
    Train,
    /// Used for early stopping and tuning; never for the reported numbers.
    Val,
    /// Held out; only for the reported numbers.
    Test,
}

/// One GNSS velocity epoch with its ground truth.
///
/// The field order is the CSV column order:
/// `t_s,track,v_north,v_east,v_down,speed_acc,true_heading_deg,true_speed,sigma_v,split`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Sample {
    /// Time since the start of the track (s). For S1 it is the index of the noise draw
    /// (one draw per second of a vehicle at constant velocity).
    pub t_s: f64,
    /// Track (trajectory) id. Samples of one track are consecutive epochs of one
    /// vehicle; splits that must not leak assign whole tracks. For S1 it is the grid
    /// cell (speed index × number of headings + heading index).
    pub track: u32,
    /// Measured north velocity (m/s).
    pub v_north: f32,
    /// Measured east velocity (m/s).
    pub v_east: f32,
    /// Measured down velocity (m/s) (not used for heading; kept because receivers give it).
    pub v_down: f32,
    /// Speed accuracy the receiver reports (1σ, m/s), like u-blox `sAcc`; NaN if the
    /// receiver does not report one. It is rough: not equal to [`Sample::sigma_v`].
    pub speed_acc: f32,
    /// True heading of the vehicle [deg, clockwise from north, 0..360). At standstill it
    /// is the heading the vehicle had when it stopped.
    pub true_heading_deg: f32,
    /// True horizontal speed (m/s); evaluation bins by this.
    pub true_speed: f32,
    /// Standard deviation of the noise actually added to each horizontal axis (m/s)
    /// (the stationary σ of white plus correlated parts). Truth, not a measurement.
    pub sigma_v: f32,
    /// Train / validation / test membership.
    pub split: Split,
}

/// Errors of CSV input and output of samples.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    /// The CSV file could not be opened, written or parsed.
    #[error("sample CSV {path}: {source}")]
    Csv {
        /// File involved.
        path: String,
        /// Underlying error.
        #[source]
        source: csv::Error,
    },
    /// Flushing the written file failed.
    #[error("sample CSV {path}: {source}")]
    Io {
        /// File involved.
        path: String,
        /// Underlying error.
        #[source]
        source: std::io::Error,
    },
}

/// `n` velocities (north, east; m/s) spread deterministically over speeds 0.05 to
/// 9.65 m/s and all directions (golden-angle steps), no noise, no seed: the inputs
/// of the inference benchmarks (`ghnet bench` and `cargo bench`), so both time the
/// same work across every status and kernel branch.
pub fn spread_velocities(n: usize) -> (Vec<f32>, Vec<f32>) {
    (0..n)
        .map(|i| {
            let a = i as f32 * 0.618;
            let s = 0.05 + (i % 97) as f32 * 0.1;
            (s * a.cos(), s * a.sin())
        })
        .unzip()
}

/// Writes samples as CSV with a header row (see [`Sample`] for the columns).
///
/// Unknown `speed_acc` is written as `NaN`, which [`read_csv`] reads back.
pub fn write_csv(path: impl AsRef<Path>, samples: &[Sample]) -> Result<(), SimError> {
    let path = path.as_ref();
    let csv_err = |source| SimError::Csv {
        path: path.display().to_string(),
        source,
    };
    let mut w = csv::Writer::from_path(path).map_err(csv_err)?;
    for s in samples {
        w.serialize(s).map_err(csv_err)?;
    }
    w.flush().map_err(|source| SimError::Io {
        path: path.display().to_string(),
        source,
    })
}

/// Reads samples written by [`write_csv`] (or any CSV with the same header).
pub fn read_csv(path: impl AsRef<Path>) -> Result<Vec<Sample>, SimError> {
    let path = path.as_ref();
    let csv_err = |source| SimError::Csv {
        path: path.display().to_string(),
        source,
    };
    let mut r = csv::Reader::from_path(path).map_err(csv_err)?;
    r.deserialize().map(|row| row.map_err(csv_err)).collect()
}

/// Heading in degrees [0, 360) of a north/east vector; atan2(0, 0) gives 0.
pub(crate) fn heading_deg(north: f64, east: f64) -> f64 {
    let h = east.atan2(north).to_degrees().rem_euclid(360.0);
    // rem_euclid of a tiny negative number rounds up to exactly 360.
    if h >= 360.0 {
        0.0
    } else {
        h
    }
}

/// Casts a heading to f32 keeping it inside [0, 360) (359.99999999 would round to 360).
pub(crate) fn heading_f32(h_deg: f64) -> f32 {
    let h = h_deg as f32;
    if h >= 360.0 {
        0.0
    } else {
        h
    }
}

/// Uniform draw in [lo, hi] that tolerates lo == hi (rand's ranges panic when empty).
/// Shared with [`crate::drive`], so both simulators treat a collapsed range alike.
pub(crate) fn uniform(rng: &mut ChaCha8Rng, lo: f64, hi: f64) -> f64 {
    if hi > lo {
        rng.random_range(lo..=hi)
    } else {
        lo
    }
}

/// Log-uniform draw in [lo, hi] (both > 0), for scales such as noise σ where a
/// factor matters, not a difference.
pub(crate) fn log_uniform(rng: &mut ChaCha8Rng, lo: f64, hi: f64) -> f64 {
    uniform(rng, lo.ln(), hi.ln()).exp()
}

/// The share of a receiver's velocity noise σ (per axis) that is correlated in time
/// ([`correlated_step`]); the rest, [`NOISE_WHITE_SHARE`], is white, so that the two
/// add to σ in quadrature. The drive simulator's receivers have it ([`crate::drive`]),
/// and `ghnet simulate noisy` adds it to a real log ([`crate::noisy`]).
pub(crate) const NOISE_CORRELATED_SHARE: f64 = 0.8;

/// The white share of a receiver's velocity noise σ (see [`NOISE_CORRELATED_SHARE`]).
pub(crate) const NOISE_WHITE_SHARE: f64 = 0.6;

/// One step of the correlated part of the noise on both axes: a first-order process
/// of unit variance whose correlation over the step is `phi` (`e^(−dt/τ)`; 0 draws it
/// afresh).
pub(crate) fn correlated_step(ar: &mut [f64; 2], phi: f64, rng: &mut ChaCha8Rng) {
    let innov = (1.0 - phi * phi).sqrt();
    for a in ar {
        *a = phi * *a + innov * rng.sample::<f64, _>(StandardNormal);
    }
}
