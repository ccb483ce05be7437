//! GNSS velocity simulation: the paper's S1 grid and a realistic consumer receiver.
//!
//! Both generators are seeded ([`ChaCha8Rng::seed_from_u64`]) so that a data set is
//! reproduced from `(parameters, seed)` alone; the same inputs give byte-identical CSV.
//! Conventions: velocities in NED (north, east, down) in m/s; heading ψ in degrees
//! clockwise from true north, ψ = atan2(v_E, v_N) wrapped to [0, 360).
//!
//! * [`simulate_s1`] follows the GHNet paper's S1 protocol exactly (a discrete grid of
//!   speeds and headings in 0..90°, white noise σ = 0.01 m/s). It is what the paper
//!   trained on, and its prior is what [`crate::bayes::BayesS1`] integrates over.
//! * [`simulate_realistic`] models what a consumer receiver actually delivers: tracks
//!   of stops, slow manoeuvres, turns and straight runs at 5–10 Hz, over the full
//!   circle, with varying and time-correlated noise, mm/s quantisation, course freezing
//!   at low speed, glitches and a rough reported speed accuracy. A model that is only
//!   good on S1 will show it here.

use std::f64::consts::PI;
use std::path::Path;

use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
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
fn heading_deg(north: f64, east: f64) -> f64 {
    let h = east.atan2(north).to_degrees().rem_euclid(360.0);
    // rem_euclid of a tiny negative number rounds up to exactly 360.
    if h >= 360.0 {
        0.0
    } else {
        h
    }
}

/// Casts a heading to f32 keeping it inside [0, 360) (359.99999999 would round to 360).
fn heading_f32(h_deg: f64) -> f32 {
    let h = h_deg as f32;
    if h >= 360.0 {
        0.0
    } else {
        h
    }
}

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

/// Parameters of the realistic consumer-receiver simulation ([`simulate_realistic`]).
///
/// Defaults describe a mixed fleet of slow robots and road vehicles seen by u-blox-class
/// receivers (see `NOTES-domain.md`, "Real receivers"); every knob is exposed so that a
/// model can be trained on one setting and tested on another.
#[derive(Clone, Debug, PartialEq, clap::Args, Serialize, Deserialize)]
pub struct RealisticParams {
    /// Total number of samples; the last track is cut to hit it exactly.
    #[arg(long, default_value_t = 300_000)]
    pub samples: usize,
    /// Shortest track (s).
    #[arg(long, default_value_t = 30.0)]
    pub track_min_s: f64,
    /// Longest track (s).
    #[arg(long, default_value_t = 300.0)]
    pub track_max_s: f64,
    /// Lowest output rate (Hz); each track draws an integer rate in [rate_min, rate_max].
    #[arg(long, default_value_t = 5)]
    pub rate_min_hz: u32,
    /// Highest output rate (Hz).
    #[arg(long, default_value_t = 10)]
    pub rate_max_hz: u32,
    /// Relative weight of stop segments (speed 0 for a few seconds).
    #[arg(long, default_value_t = 0.2)]
    pub w_stop: f64,
    /// Relative weight of slow manoeuvres (0 to slow_max m/s, frequent heading changes).
    #[arg(long, default_value_t = 0.35)]
    pub w_slow: f64,
    /// Relative weight of turns (constant yaw rate).
    #[arg(long, default_value_t = 0.2)]
    pub w_turn: f64,
    /// Relative weight of straight runs (cruise speed with acceleration/deceleration).
    #[arg(long, default_value_t = 0.25)]
    pub w_straight: f64,
    /// Shortest standstill of a stop segment (s).
    #[arg(long, default_value_t = 2.0)]
    pub stop_min_s: f64,
    /// Longest standstill of a stop segment (s).
    #[arg(long, default_value_t = 15.0)]
    pub stop_max_s: f64,
    /// Top speed of slow manoeuvres (m/s).
    #[arg(long, default_value_t = 1.0)]
    pub slow_max: f64,
    /// Largest yaw rate in slow manoeuvres and turns (deg/s).
    #[arg(long, default_value_t = 30.0)]
    pub yaw_rate_max: f64,
    /// Largest lateral acceleration in turns (m/s²); caps the turn speed at a yaw rate.
    #[arg(long, default_value_t = 3.0)]
    pub lat_acc_max: f64,
    /// Cruise speeds of straight runs are uniform in [0.3, cruise_low_max] m/s …
    #[arg(long, default_value_t = 3.0)]
    pub cruise_low_max: f64,
    /// … except with probability p_fast, where they are uniform in
    /// [cruise_low_max, cruise_max] m/s: the low end dominates, the tail reaches far.
    #[arg(long, default_value_t = 0.25)]
    pub p_fast: f64,
    /// Highest cruise speed (m/s).
    #[arg(long, default_value_t = 20.0)]
    pub cruise_max: f64,
    /// Longest straight run (s) (shortest is 5 s).
    #[arg(long, default_value_t = 60.0)]
    pub straight_max_s: f64,
    /// Largest longitudinal acceleration/deceleration (m/s²).
    #[arg(long, default_value_t = 1.5)]
    pub acc_max: f64,
    /// Smallest per-axis velocity noise σ (m/s) (good sky).
    #[arg(long, default_value_t = 0.02)]
    pub sigma_min: f64,
    /// Largest per-axis velocity noise σ (m/s) (poor sky, multipath).
    #[arg(long, default_value_t = 0.5)]
    pub sigma_max: f64,
    /// Each track draws σ log-uniformly in [sigma_min, sigma_max]; each segment
    /// multiplies it by exp(sigma_seg_log_std · N(0,1)), clamped to the same range,
    /// as sky conditions change along a track.
    #[arg(long, default_value_t = 0.3)]
    pub sigma_seg_log_std: f64,
    /// Share of the noise variance that is time-correlated (AR(1)); the rest is white.
    #[arg(long, default_value_t = 0.7)]
    pub corr_fraction: f64,
    /// Correlation time of the AR(1) noise part, in epochs (φ = exp(−1/this)).
    #[arg(long, default_value_t = 3.0)]
    pub corr_epochs: f64,
    /// Vertical noise σ as a multiple of the horizontal σ (receivers are worse vertically).
    #[arg(long, default_value_t = 1.5)]
    pub down_sigma_factor: f64,
    /// Velocity quantisation step (m/s) (u-blox reports mm/s); 0 disables.
    #[arg(long, default_value_t = 0.001)]
    pub quant: f64,
    /// Probability that a track's receiver freezes the course at low speed, like
    /// NMEA/u-blox: below freeze_speed the velocity keeps the last valid direction.
    #[arg(long, default_value_t = 0.5)]
    pub p_freeze_track: f64,
    /// Measured speed below which a freezing receiver keeps the last course (m/s).
    #[arg(long, default_value_t = 0.1)]
    pub freeze_speed: f64,
    /// Probability per sample of a one-epoch glitch.
    #[arg(long, default_value_t = 1e-3)]
    pub p_glitch: f64,
    /// Smallest glitch jump (m/s), in a random horizontal direction.
    #[arg(long, default_value_t = 2.0)]
    pub glitch_min: f64,
    /// Largest glitch jump (m/s).
    #[arg(long, default_value_t = 8.0)]
    pub glitch_max: f64,
    /// Reported speed accuracy is σ times a factor uniform in
    /// [sacc_factor_min, sacc_factor_max], drawn per segment (receivers' sAcc is rough).
    #[arg(long, default_value_t = 0.7)]
    pub sacc_factor_min: f64,
    /// Upper end of the speed-accuracy factor.
    #[arg(long, default_value_t = 1.5)]
    pub sacc_factor_max: f64,
    /// Share of tracks whose receiver reports no speed accuracy (speed_acc = NaN).
    #[arg(long, default_value_t = 0.2)]
    pub p_sacc_unknown: f64,
    /// Share of tracks in the validation split (whole tracks, never shared).
    #[arg(long, default_value_t = 0.15)]
    pub val_fraction: f64,
    /// Share of tracks in the test split (whole tracks, never shared).
    #[arg(
        id = "realistic_test_fraction",
        long = "realistic-test-fraction",
        default_value_t = 0.15
    )]
    pub test_fraction: f64,
}

impl Default for RealisticParams {
    fn default() -> Self {
        Self {
            samples: 300_000,
            track_min_s: 30.0,
            track_max_s: 300.0,
            rate_min_hz: 5,
            rate_max_hz: 10,
            w_stop: 0.2,
            w_slow: 0.35,
            w_turn: 0.2,
            w_straight: 0.25,
            stop_min_s: 2.0,
            stop_max_s: 15.0,
            slow_max: 1.0,
            yaw_rate_max: 30.0,
            lat_acc_max: 3.0,
            cruise_low_max: 3.0,
            p_fast: 0.25,
            cruise_max: 20.0,
            straight_max_s: 60.0,
            acc_max: 1.5,
            sigma_min: 0.02,
            sigma_max: 0.5,
            sigma_seg_log_std: 0.3,
            corr_fraction: 0.7,
            corr_epochs: 3.0,
            down_sigma_factor: 1.5,
            quant: 0.001,
            p_freeze_track: 0.5,
            freeze_speed: 0.1,
            p_glitch: 1e-3,
            glitch_min: 2.0,
            glitch_max: 8.0,
            sacc_factor_min: 0.7,
            sacc_factor_max: 1.5,
            p_sacc_unknown: 0.2,
            val_fraction: 0.15,
            test_fraction: 0.15,
        }
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

/// One piece of a track: what the vehicle is trying to do for how long.
struct Segment {
    /// Epochs left in this segment.
    epochs: usize,
    /// Speed the vehicle accelerates or brakes towards (m/s).
    target_speed: f64,
    /// Current yaw rate (deg/s).
    yaw_rate: f64,
    /// Slow manoeuvres redraw their yaw rate every few seconds; epochs until then.
    yaw_redraw_in: Option<usize>,
    /// Noise σ per horizontal axis in this segment (m/s).
    sigma: f64,
    /// Factor from σ to the reported speed accuracy.
    sacc_factor: f64,
}

/// Draws the next segment of a track given the current speed.
fn next_segment(
    p: &RealisticParams,
    rng: &mut ChaCha8Rng,
    rate: f64,
    speed: f64,
    sigma_track: f64,
) -> Segment {
    let weights = [p.w_stop, p.w_slow, p.w_turn, p.w_straight];
    let total: f64 = weights.iter().map(|w| w.max(0.0)).sum();
    let mut u = rng.random::<f64>() * total;
    let mut kind = 3;
    for (k, w) in weights.iter().enumerate() {
        if u < w.max(0.0) {
            kind = k;
            break;
        }
        u -= w.max(0.0);
    }
    let epochs = |secs: f64| ((secs * rate).round() as usize).max(1);
    let sign = if rng.random::<bool>() { 1.0 } else { -1.0 };
    let (secs, target_speed, yaw_rate, yaw_redraw_in) = match kind {
        0 => {
            // Braking time plus the standstill itself.
            let hold = uniform(rng, p.stop_min_s, p.stop_max_s);
            (speed / p.acc_max + hold, 0.0, 0.0, None)
        }
        1 => {
            let v = uniform(rng, 0.0, p.slow_max);
            let yaw = sign * uniform(rng, 0.0, p.yaw_rate_max);
            (
                uniform(rng, 3.0, 20.0),
                v,
                yaw,
                Some(epochs(uniform(rng, 1.0, 3.0))),
            )
        }
        2 => {
            let yaw_mag = uniform(rng, 5.0, p.yaw_rate_max.max(5.0));
            // A turn keeps lateral acceleration v·ω below lat_acc_max.
            let v_cap = p.lat_acc_max / yaw_mag.to_radians();
            let v = uniform(rng, 0.3, p.cruise_low_max).min(v_cap);
            let angle = uniform(rng, 30.0, 180.0);
            (angle / yaw_mag, v, sign * yaw_mag, None)
        }
        _ => {
            let v = if rng.random::<f64>() < p.p_fast {
                uniform(rng, p.cruise_low_max, p.cruise_max)
            } else {
                uniform(rng, 0.3, p.cruise_low_max)
            };
            let accel_time = (v - speed).abs() / p.acc_max;
            (
                accel_time + uniform(rng, 5.0, p.straight_max_s),
                v,
                0.0,
                None,
            )
        }
    };
    let z: f64 = rng.sample(StandardNormal);
    let sigma = (sigma_track * (p.sigma_seg_log_std * z).exp()).clamp(p.sigma_min, p.sigma_max);
    Segment {
        epochs: epochs(secs),
        target_speed,
        yaw_rate,
        yaw_redraw_in,
        sigma,
        sacc_factor: uniform(rng, p.sacc_factor_min, p.sacc_factor_max),
    }
}

fn quantize(v: f64, q: f64) -> f64 {
    if q > 0.0 {
        (v / q).round() * q
    } else {
        v
    }
}

/// Simulates a realistic consumer GNSS receiver on many independent tracks.
///
/// Each track is one vehicle or robot: an integer output rate in
/// [`rate_min_hz`, `rate_max_hz`], a uniformly random initial heading over the full
/// circle, and a sequence of segments (stop, slow manoeuvre, turn, straight run; see
/// [`RealisticParams`]) integrated with rate-limited acceleration. The measured velocity
/// is truth + noise (per-axis σ from a per-track log-uniform draw varied per segment;
/// `corr_fraction` of the variance is AR(1) with `corr_epochs` correlation, the rest
/// white) + rare one-epoch glitches; then, for freezing receivers, a measured speed
/// below `freeze_speed` keeps the last valid course direction; finally every
/// component is quantised to `quant`. Whole tracks are assigned to train, validation
/// and test (the split shares are shares of tracks), so held-out data never shares a
/// trajectory, noise realisation or receiver with training data.
///
/// The true heading at standstill is the heading the vehicle had when it stopped: the
/// vehicle still points somewhere, even if its velocity says nothing about it.
pub fn simulate_realistic(p: &RealisticParams, seed: u64) -> Vec<Sample> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut out: Vec<Sample> = Vec::with_capacity(p.samples);
    // Start index in `out` of each track, for the split assignment at the end.
    let mut track_starts: Vec<usize> = Vec::new();
    let noise = NoiseModel::new(p);
    while out.len() < p.samples {
        let track = track_starts.len() as u32;
        track_starts.push(out.len());
        simulate_track(p, &noise, track, &mut rng, &mut out);
    }
    assign_splits(p, &track_starts, &mut rng, &mut out);
    out
}

/// The velocity noise of [`simulate_realistic`]: per axis a unit-variance AR(1) part
/// (`corr_fraction` of the variance, `corr_epochs` correlation) plus a white part.
struct NoiseModel {
    phi: f64,
    innov: f64,
    c_share: f64,
    w_share: f64,
    down_factor: f64,
}

impl NoiseModel {
    fn new(p: &RealisticParams) -> Self {
        let phi = (-1.0 / p.corr_epochs.max(1e-9)).exp();
        let corr = p.corr_fraction.clamp(0.0, 1.0);
        NoiseModel {
            phi,
            innov: (1.0 - phi * phi).sqrt(),
            c_share: corr.sqrt(),
            w_share: (1.0 - corr).sqrt(),
            down_factor: p.down_sigma_factor,
        }
    }

    /// One epoch's noise (north, east, down) with stationary σ `sigma` per horizontal
    /// axis; advances the AR(1) states `ar`.
    fn draw(&self, ar: &mut [f64; 3], sigma: f64, rng: &mut ChaCha8Rng) -> [f64; 3] {
        let mut noise = [0.0_f64; 3];
        for (axis, (a, nz)) in ar.iter_mut().zip(noise.iter_mut()).enumerate() {
            let e: f64 = rng.sample(StandardNormal);
            *a = self.phi * *a + self.innov * e;
            let w: f64 = rng.sample(StandardNormal);
            let scale = if axis == 2 {
                sigma * self.down_factor
            } else {
                sigma
            };
            *nz = scale * (self.c_share * *a + self.w_share * w);
        }
        noise
    }
}

/// Appends one track (one vehicle with its own receiver) to `out`.
fn simulate_track(
    p: &RealisticParams,
    noise: &NoiseModel,
    track: u32,
    rng: &mut ChaCha8Rng,
    out: &mut Vec<Sample>,
) {
    let rate = rng.random_range(p.rate_min_hz.min(p.rate_max_hz)..=p.rate_max_hz) as f64;
    let dt = 1.0 / rate;
    let n_track = ((uniform(rng, p.track_min_s, p.track_max_s) * rate).round() as usize)
        .clamp(1, p.samples - out.len());
    let sigma_track = log_uniform(rng, p.sigma_min, p.sigma_max);
    let freezes = rng.random::<f64>() < p.p_freeze_track;
    let sacc_known = rng.random::<f64>() >= p.p_sacc_unknown;

    let mut heading = rng.random::<f64>() * 360.0;
    let mut speed = 0.0_f64;
    // Unit-variance AR(1) states for north, east, down.
    let mut ar = [0.0_f64; 3];
    for a in &mut ar {
        *a = rng.sample(StandardNormal);
    }
    let mut frozen_course: Option<f64> = None;
    let mut seg = next_segment(p, rng, rate, speed, sigma_track);

    for k in 0..n_track {
        if seg.epochs == 0 {
            seg = next_segment(p, rng, rate, speed, sigma_track);
        }
        seg.epochs -= 1;
        redraw_yaw_rate(p, &mut seg, rate, rng);
        // Kinematics: speed moves towards the target at most acc_max; the vehicle
        // only turns while it moves.
        let dv = (seg.target_speed - speed).clamp(-p.acc_max * dt, p.acc_max * dt);
        speed = (speed + dv).max(0.0);
        if speed > 0.0 {
            heading = (heading + seg.yaw_rate * dt).rem_euclid(360.0);
        }
        let nz = noise.draw(&mut ar, seg.sigma, rng);
        let (sin_h, cos_h) = heading.to_radians().sin_cos();
        let mut vn = speed * cos_h + nz[0];
        let mut ve = speed * sin_h + nz[1];
        if rng.random::<f64>() < p.p_glitch {
            let mag = uniform(rng, p.glitch_min, p.glitch_max);
            let dir = rng.random::<f64>() * 2.0 * PI;
            vn += mag * dir.cos();
            ve += mag * dir.sin();
        }
        if freezes {
            freeze_course(&mut frozen_course, p.freeze_speed, &mut vn, &mut ve);
        }
        let speed_acc = if sacc_known {
            quantize(seg.sigma * seg.sacc_factor, p.quant) as f32
        } else {
            f32::NAN
        };
        out.push(Sample {
            t_s: k as f64 * dt,
            track,
            v_north: quantize(vn, p.quant) as f32,
            v_east: quantize(ve, p.quant) as f32,
            v_down: quantize(nz[2], p.quant) as f32,
            speed_acc,
            true_heading_deg: heading_f32(heading),
            true_speed: speed as f32,
            sigma_v: seg.sigma as f32,
            split: Split::Train,
        });
    }
}

/// A segment with a varying yaw rate draws a new one every 1–3 s.
fn redraw_yaw_rate(p: &RealisticParams, seg: &mut Segment, rate: f64, rng: &mut ChaCha8Rng) {
    if let Some(n) = seg.yaw_redraw_in.as_mut() {
        if *n == 0 {
            let sign = if rng.random::<bool>() { 1.0 } else { -1.0 };
            seg.yaw_rate = sign * uniform(rng, 0.0, p.yaw_rate_max);
            *n = ((uniform(rng, 1.0, 3.0) * rate).round() as usize).max(1);
        } else {
            *n -= 1;
        }
    }
}

/// A freezing receiver: under `freeze_speed` the velocity keeps the last valid course
/// direction (`frozen`) with its measured magnitude; above it, the course is stored.
fn freeze_course(frozen: &mut Option<f64>, freeze_speed: f64, vn: &mut f64, ve: &mut f64) {
    let m = vn.hypot(*ve);
    if m < freeze_speed {
        if let Some(c) = *frozen {
            let (s, c) = c.to_radians().sin_cos();
            *vn = m * c;
            *ve = m * s;
        }
    } else {
        *frozen = Some(heading_deg(*vn, *ve));
    }
}

/// Whole tracks to splits, in a seeded random order (held-out data never shares a
/// trajectory with training data).
fn assign_splits(
    p: &RealisticParams,
    track_starts: &[usize],
    rng: &mut ChaCha8Rng,
    out: &mut [Sample],
) {
    let n_tracks = track_starts.len();
    let mut order: Vec<usize> = (0..n_tracks).collect();
    order.shuffle(rng);
    let n_test = (p.test_fraction.clamp(0.0, 1.0) * n_tracks as f64).round() as usize;
    let n_val = ((p.val_fraction.clamp(0.0, 1.0) * n_tracks as f64).round() as usize)
        .min(n_tracks - n_test);
    let total = out.len();
    for (rank, &t) in order.iter().enumerate() {
        let split = if rank < n_test {
            Split::Test
        } else if rank < n_test + n_val {
            Split::Val
        } else {
            continue;
        };
        let end = track_starts.get(t + 1).copied().unwrap_or(total);
        for s in &mut out[track_starts[t]..end] {
            s.split = split;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::{HashMap, HashSet};

    fn csv_bytes(samples: &[Sample]) -> Vec<u8> {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("s.csv");
        write_csv(&path, samples).unwrap();
        std::fs::read(path).unwrap()
    }

    fn small_realistic() -> RealisticParams {
        RealisticParams {
            samples: 20_000,
            ..RealisticParams::default()
        }
    }

    /// Both parameter sets flattened into one command, as a CLI may do.
    #[derive(clap::Parser, Debug)]
    struct Cli {
        #[command(flatten)]
        s1: S1Params,
        #[command(flatten)]
        realistic: RealisticParams,
    }

    #[test]
    fn clap_defaults_match_default_and_flags_do_not_clash() {
        use clap::{CommandFactory, Parser};
        Cli::command().debug_assert();
        let cli = Cli::try_parse_from(["x"]).unwrap();
        assert_eq!(cli.s1, S1Params::default());
        assert_eq!(cli.realistic, RealisticParams::default());
        let cli = Cli::try_parse_from([
            "x",
            "--sigma",
            "0.05",
            "--samples",
            "10",
            "--test-fraction",
            "0.3",
            "--realistic-test-fraction",
            "0.1",
        ])
        .unwrap();
        assert_eq!((cli.s1.sigma, cli.realistic.samples), (0.05, 10));
        assert_eq!(
            (cli.s1.test_fraction, cli.realistic.test_fraction),
            (0.3, 0.1)
        );
    }

    #[test]
    fn simulations_are_deterministic_per_seed() {
        let s1 = S1Params {
            speed_max: 0.5,
            heading_max: 10.0,
            ..S1Params::default()
        };
        let realistic = RealisticParams {
            samples: 5_000,
            ..RealisticParams::default()
        };
        let runs: [&dyn Fn(u64) -> Vec<u8>; 2] =
            [&|seed| csv_bytes(&simulate_s1(&s1, seed)), &|seed| {
                csv_bytes(&simulate_realistic(&realistic, seed))
            }];
        for run in runs {
            let a = run(7);
            assert_eq!(a, run(7));
            assert_ne!(a, run(8));
        }
    }

    #[test]
    fn csv_round_trips_including_nan() {
        let s = simulate_realistic(&small_realistic(), 3);
        assert!(s.iter().any(|x| x.speed_acc.is_nan()));
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("r.csv");
        write_csv(&path, &s).unwrap();
        let header = std::fs::read_to_string(&path).unwrap();
        assert!(header.starts_with(
            "t_s,track,v_north,v_east,v_down,speed_acc,true_heading_deg,true_speed,sigma_v,split\n"
        ));
        let back = read_csv(&path).unwrap();
        assert_eq!(back.len(), s.len());
        for (a, b) in s.iter().zip(&back) {
            // NaN != NaN, so compare the bit-exact CSV-relevant fields one by one.
            assert_eq!(a.speed_acc.is_nan(), b.speed_acc.is_nan());
            let mut a2 = a.clone();
            let mut b2 = b.clone();
            a2.speed_acc = 0.0;
            b2.speed_acc = 0.0;
            assert_eq!(a2, b2);
        }
    }

    #[test]
    fn s1_count_and_grid_are_exact() {
        let p = S1Params::default();
        let s = simulate_s1(&p, 0);
        assert_eq!(s.len(), 36 * 181 * 10);
        let mut cells: HashMap<(u32, u32), usize> = HashMap::new();
        for x in &s {
            // Speeds are decimal multiples of 0.1 stored as the nearest f32.
            let i = (x.true_speed as f64 / 0.1).round();
            assert_eq!(x.true_speed, (i * 0.1) as f32);
            // Headings are multiples of 0.5, exact in binary.
            let j = x.true_heading_deg * 2.0;
            assert_eq!(j, j.round());
            *cells.entry((i as u32, j as u32)).or_default() += 1;
        }
        assert_eq!(cells.len(), 36 * 181);
        assert!(cells.values().all(|&c| c == 10));
        let max_i = cells.keys().map(|k| k.0).max().unwrap();
        let max_j = cells.keys().map(|k| k.1).max().unwrap();
        assert_eq!((max_i, max_j), (35, 180));
        let n_test = s.iter().filter(|x| x.split == Split::Test).count();
        assert_eq!(n_test, (0.2 * s.len() as f64).round() as usize);
        assert!(s.iter().all(|x| x.split != Split::Val));
    }

    #[test]
    fn s1_noise_has_the_configured_sigma() {
        let p = S1Params::default();
        let s = simulate_s1(&p, 5);
        let n = s.len() as f64;
        let (mut sum, mut sum2) = (0.0, 0.0);
        for x in &s {
            let (sin, cos) = (x.true_heading_deg as f64).to_radians().sin_cos();
            let e = x.v_north as f64 - x.true_speed as f64 * cos;
            let f = x.v_east as f64 - x.true_speed as f64 * sin;
            sum += e + f;
            sum2 += e * e + f * f;
        }
        let mean = sum / (2.0 * n);
        let sd = (sum2 / (2.0 * n)).sqrt();
        assert!(mean.abs() < 2e-4, "noise mean {mean}");
        assert!((sd - 0.01).abs() < 2e-4, "noise sd {sd}");
    }

    #[test]
    fn realistic_statistics_are_as_configured() {
        let p = RealisticParams {
            samples: 100_000,
            ..RealisticParams::default()
        };
        let s = simulate_realistic(&p, 11);
        assert_eq!(s.len(), p.samples);
        let n = s.len() as f64;
        let low = s.iter().filter(|x| x.true_speed < 3.0).count() as f64 / n;
        assert!(low > 0.6, "share below 3 m/s: {low}");
        let max_speed = s.iter().map(|x| x.true_speed).fold(0.0, f32::max);
        assert!(max_speed > 10.0, "max speed {max_speed}");
        let stopped = s.iter().filter(|x| x.true_speed == 0.0).count() as f64 / n;
        assert!(stopped > 0.02, "share at standstill {stopped}");

        let smin = s.iter().map(|x| x.sigma_v).fold(f32::INFINITY, f32::min);
        let smax = s.iter().map(|x| x.sigma_v).fold(0.0, f32::max);
        assert!((0.02 * 0.999..0.03).contains(&smin), "sigma min {smin}");
        assert!((0.35..=0.5 * 1.001).contains(&smax), "sigma max {smax}");

        // Glitches: a horizontal innovation of at least glitch_min far beyond 6σ.
        let mut glitches = 0;
        for x in &s {
            let (sin, cos) = (x.true_heading_deg as f64).to_radians().sin_cos();
            let e = (x.v_north as f64 - x.true_speed as f64 * cos)
                .hypot(x.v_east as f64 - x.true_speed as f64 * sin);
            if e > (6.0 * x.sigma_v as f64).max(1.5) {
                glitches += 1;
            }
        }
        let rate = glitches as f64 / n;
        assert!(rate > 0.5e-3 && rate < 1.5e-3, "glitch rate {rate}");

        // Headings cover the circle: every 45° sector holds a fair share.
        let mut sectors = [0usize; 8];
        for x in &s {
            sectors[(x.true_heading_deg / 45.0) as usize % 8] += 1;
        }
        assert!(sectors.iter().all(|&c| c as f64 > 0.05 * n), "{sectors:?}");

        // Quantised to mm/s.
        assert!(s.iter().all(|x| ((x.v_north as f64) * 1000.0
            - (x.v_north as f64 * 1000.0).round())
        .abs()
            < 1e-3));
        // Reported accuracy is within the configured factor of the true σ when known.
        for x in s.iter().filter(|x| !x.speed_acc.is_nan()) {
            let f = x.speed_acc / x.sigma_v;
            assert!((0.65..=1.55).contains(&f), "sAcc factor {f}");
        }
    }

    #[test]
    fn realistic_freezes_course_at_low_speed() {
        let p = RealisticParams {
            samples: 30_000,
            p_freeze_track: 1.0,
            p_glitch: 0.0,
            ..RealisticParams::default()
        };
        let s = simulate_realistic(&p, 4);
        // Within a track, consecutive slow measurements keep the previous direction.
        // Only after a first valid course in the track (before it there is nothing to
        // keep), and above 0.04 m/s so that mm/s quantisation moves the direction < 1°.
        let (mut slow_pairs, mut same_dir) = (0, 0);
        let mut had_course = false;
        for w in s.windows(2) {
            let (a, b) = (&w[0], &w[1]);
            if a.track != b.track {
                had_course = false;
                continue;
            }
            let mb = (b.v_north as f64).hypot(b.v_east as f64);
            let ma = (a.v_north as f64).hypot(a.v_east as f64);
            had_course |= ma >= 0.1;
            if had_course && mb < 0.09 && ma < 0.09 && mb > 0.04 && ma > 0.04 {
                slow_pairs += 1;
                let da = heading_deg(a.v_north as f64, a.v_east as f64);
                let db = heading_deg(b.v_north as f64, b.v_east as f64);
                let d = (da - db).rem_euclid(360.0);
                if d.min(360.0 - d) < 3.0 {
                    same_dir += 1;
                }
            }
        }
        assert!(slow_pairs > 100, "too few slow pairs: {slow_pairs}");
        assert_eq!(same_dir, slow_pairs);
    }

    #[test]
    fn realistic_splits_are_whole_tracks() {
        let s = simulate_realistic(&small_realistic(), 9);
        let mut split_of: HashMap<u32, Split> = HashMap::new();
        for x in &s {
            let e = split_of.entry(x.track).or_insert(x.split);
            assert_eq!(*e, x.split, "track {} spans splits", x.track);
        }
        let sets: Vec<HashSet<u32>> = [Split::Train, Split::Val, Split::Test]
            .iter()
            .map(|sp| {
                split_of
                    .iter()
                    .filter(|(_, v)| **v == *sp)
                    .map(|(k, _)| *k)
                    .collect()
            })
            .collect();
        assert!(sets.iter().all(|set| !set.is_empty()));
        let n = split_of.len() as f64;
        let test_share = sets[2].len() as f64 / n;
        assert!((test_share - 0.15).abs() < 0.05, "test share {test_share}");
    }
}
