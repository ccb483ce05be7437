//! A realistic consumer receiver over the full circle: tracks of stops, manoeuvres,
//! turns and straight runs with time-correlated noise, quantisation, course freezing
//! and glitches.

use std::f64::consts::PI;

use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};

use super::sample::{heading_deg, heading_f32, log_uniform, uniform, Sample, Split};

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
