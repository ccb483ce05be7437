//! The drive simulator: whole tracks of cars and of platforms that turn in place, seen
//! by the receivers people actually have, for training and judging temporal models.
//!
//! Where [`crate::sim`] draws independent manoeuvres, this draws what a day of driving
//! looks like to a heading filter, because that is where history wins or loses:
//!
//! * **Cars** leave a parking space (often backing out), drive city blocks with
//!   curving roads, slow for junctions, wait at red lights, turn at 3–7 m/s, cruise at
//!   5–16 m/s (sometimes a fast road up to 28 m/s), and park again, often reversing into
//!   the space, then stand. Heading truth is where the body points; while reversing the
//!   velocity is opposite to it. Steering is a bicycle model: yaw rate = signed speed ×
//!   curvature, so a car never turns in place.
//! * **Turn-in-place platforms** (differential drive, Segway) creep and roll at up to
//!   2 m/s, stop often, spin in place while stopped (tens of °/s), turn while creeping
//!   and sometimes back up: a held heading is wrong after a spin.
//! * **Receivers**: 1, 2, 5 or 10 Hz; velocity noise σ_v per track log-uniform 0.02–0.3
//!   m/s with a time-correlated part; optional first-order lag (τ up to 1.5 s, the
//!   smoothing consumer receivers apply; the styles that hold static smooth their
//!   noise with it, as a navigation filter does, the others add it after); rare
//!   glitches; fix gaps (seconds to minutes); and one of five output styles:
//!   u-blox-like (raw velocity, mm/s, a rough sAcc), RTKLIB-like (raw velocity, a
//!   nearly constant formal sAcc near 0.07 m/s), NMEA-like (speed and course only,
//!   course frozen below 0.1 m/s, no sAcc), consumer (smoothed, 0.000 at rest, no
//!   sAcc), or a u-blox with its static hold on (as the consumer style, with the u-blox
//!   sAcc).
//!
//! Everything is seeded; a track is reproduced from `(parameters, seed)`.

use rand::seq::{IndexedRandom, SliceRandom};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};

use crate::sim::{
    correlated_step, log_uniform, uniform, Split, NOISE_CORRELATED_SHARE, NOISE_WHITE_SHARE,
};

/// Internal simulation step, s: kinematics and receiver filters run at 10 Hz and each
/// receiver takes every `10/rate`-th state.
const DT: f64 = 0.1;

/// Largest lateral acceleration of simulated vehicles, m/s².
const A_LAT_MAX: f64 = 4.0;

mod params;
pub use params::{DriveParams, Platform, ReceiverKind};

/// One epoch of a simulated track, with its truth.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct DriveSample {
    /// Time since the track's start, s.
    pub t_s: f64,
    /// Measured north velocity, m/s.
    pub v_north: f32,
    /// Measured east velocity, m/s.
    pub v_east: f32,
    /// Reported speed accuracy (1σ, m/s); NaN when the receiver gives none.
    pub speed_acc: f32,
    /// Where the vehicle points, degrees clockwise from north, [0, 360).
    pub truth_heading_deg: f32,
    /// True horizontal speed, m/s.
    pub true_speed: f32,
    /// The receiver's own course output (u-blox headMot / NMEA course): atan2 of the
    /// measured velocity, frozen below 0.1 m/s and while a receiver holds static (the
    /// consumer and u-blox-hold styles: velocity snapped to zero). A baseline, not a
    /// model input.
    pub receiver_course_deg: f32,
    /// True while the vehicle backs up.
    pub reversing: bool,
}

/// One simulated track.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Track {
    /// Index in the data set.
    pub id: u32,
    /// What moves.
    pub platform: Platform,
    /// Receiver style.
    pub receiver: ReceiverKind,
    /// Output rate, Hz.
    pub rate_hz: u32,
    /// Train, validation or test.
    pub split: Split,
    /// The epochs, in time order (gaps are missing epochs).
    pub samples: Vec<DriveSample>,
}

/// What the vehicle is asked to do for a while: reach `speed` (signed: negative backs
/// up) along `curvature` (1/m; for a turn-in-place platform at zero speed, `spin` °/s)
/// for `secs`.
#[derive(Debug, Clone, Copy)]
struct Leg {
    secs: f64,
    speed: f64,
    curvature: f64,
    spin: f64,
}

impl Leg {
    fn new(secs: f64, speed: f64, curvature: f64) -> Self {
        Self {
            secs,
            speed,
            curvature,
            spin: 0.0,
        }
    }
}

/// A car's plan: park, leave, then blocks with junctions, and park again, until `total`
/// seconds are planned.
fn car_plan(rng: &mut ChaCha8Rng, total: f64) -> Vec<Leg> {
    let mut legs = vec![Leg::new(uniform(rng, 0.0, 60.0), 0.0, 0.0)];
    let mut planned = legs[0].secs;
    let sign = |rng: &mut ChaCha8Rng| if rng.random::<bool>() { 1.0 } else { -1.0 };
    while planned < total {
        let start = legs.len();
        if rng.random::<f64>() < 0.5 {
            // Back out of the space with the wheel turned, stop, then go.
            let k = sign(rng) * uniform(rng, 0.05, 0.18);
            legs.push(Leg::new(uniform(rng, 3.0, 9.0), -uniform(rng, 0.5, 1.8), k));
            legs.push(Leg::new(uniform(rng, 1.0, 3.0), 0.0, 0.0));
        }
        legs.push(Leg::new(
            uniform(rng, 4.0, 10.0),
            uniform(rng, 1.5, 4.0),
            0.0,
        ));
        for _ in 0..rng.random_range(4..16) {
            block(rng, &mut legs);
        }
        // Park: slow down, maybe reverse into the space, then stand.
        legs.push(Leg::new(
            uniform(rng, 3.0, 8.0),
            uniform(rng, 1.0, 3.0),
            0.0,
        ));
        legs.push(Leg::new(uniform(rng, 1.0, 3.0), 0.0, 0.0));
        if rng.random::<f64>() < 0.5 {
            let k = sign(rng) * uniform(rng, 0.03, 0.18);
            legs.push(Leg::new(
                uniform(rng, 4.0, 15.0),
                -uniform(rng, 0.3, 1.5),
                k,
            ));
            if rng.random::<f64>() < 0.3 {
                // Straighten up: forward a little, then back again.
                legs.push(Leg::new(uniform(rng, 1.0, 2.0), 0.0, 0.0));
                legs.push(Leg::new(uniform(rng, 2.0, 4.0), uniform(rng, 0.5, 1.0), -k));
                legs.push(Leg::new(uniform(rng, 1.0, 2.0), 0.0, 0.0));
                legs.push(Leg::new(
                    uniform(rng, 2.0, 5.0),
                    -uniform(rng, 0.3, 1.0),
                    0.0,
                ));
            }
        }
        legs.push(Leg::new(uniform(rng, 10.0, 120.0), 0.0, 0.0));
        planned += legs[start..].iter().map(|l| l.secs).sum::<f64>();
    }
    legs
}

/// One city block: a road that curves a little, then a junction (red light, turn,
/// or straight through).
fn block(rng: &mut ChaCha8Rng, legs: &mut Vec<Leg>) {
    let cruise = if rng.random::<f64>() < 0.15 {
        uniform(rng, 16.0, 28.0)
    } else {
        uniform(rng, 5.0, 16.0)
    };
    let mut road = uniform(rng, 60.0, 500.0);
    while road > 0.0 {
        let bend = uniform(rng, -1.0, 1.0) * uniform(rng, 0.0, 0.004);
        let d = uniform(rng, 30.0, 150.0).min(road);
        legs.push(Leg::new(d / cruise, cruise, bend));
        road -= d;
    }
    let u = rng.random::<f64>();
    let turn_speed = uniform(rng, 3.0, 7.0);
    if u < 0.45 {
        legs.push(Leg::new(
            uniform(rng, 3.0, 6.0),
            uniform(rng, 1.0, 3.0),
            0.0,
        ));
        legs.push(Leg::new(uniform(rng, 5.0, 70.0), 0.0, 0.0));
        // A queue: creep forward a car length or two, stop again.
        for _ in 0..rng.random_range(0..3) {
            legs.push(Leg::new(
                uniform(rng, 2.0, 6.0),
                uniform(rng, 0.5, 2.5),
                0.0,
            ));
            legs.push(Leg::new(uniform(rng, 2.0, 20.0), 0.0, 0.0));
        }
    }
    if u < 0.3 || (0.45..0.75).contains(&u) {
        // A 90° turn on a radius of 8–20 m.
        let r = uniform(rng, 8.0, 20.0);
        let side = if rng.random::<bool>() { 1.0 } else { -1.0 };
        let secs = r * std::f64::consts::FRAC_PI_2 / turn_speed;
        // Slow down to the turn speed first (1.5 m/s² is the gentlest braking drawn).
        let approach = if u < 0.3 {
            3.0
        } else {
            3.0 + (cruise - turn_speed) / 1.5
        };
        legs.push(Leg::new(approach, turn_speed, 0.0));
        legs.push(Leg::new(secs, turn_speed, side / r));
    }
}

/// A turn-in-place platform's plan: creep, roll, stop, spin, sometimes back up.
fn platform_plan(p: &DriveParams, rng: &mut ChaCha8Rng, total: f64) -> Vec<Leg> {
    let (v_lo, v_hi) = DriveParams::range(&p.platform_speed, (0.5, 1.8));
    let (spin_lo, spin_hi) = DriveParams::range(&p.platform_spin, (10.0, 90.0));
    let mut legs = vec![Leg::new(uniform(rng, 0.0, 30.0), 0.0, 0.0)];
    let mut planned = legs[0].secs;
    while planned < total {
        let sign = if rng.random::<bool>() { 1.0 } else { -1.0 };
        let leg = match rng.random::<f64>() {
            u if u < 0.35 => {
                let v = uniform(rng, v_lo, v_hi);
                Leg::new(uniform(rng, 3.0, 30.0), v, sign * uniform(rng, 0.0, 0.3))
            }
            u if u < 0.55 => {
                // Creep while turning: 0.1–0.3 m/s at up to 40°/s.
                let v = uniform(rng, 0.1, 0.35);
                let yaw = uniform(rng, 5.0, 40.0).to_radians();
                Leg::new(uniform(rng, 2.0, 10.0), v, sign * yaw / v)
            }
            u if u < 0.85 => {
                let mut l = Leg::new(uniform(rng, 1.0, 20.0), 0.0, 0.0);
                if rng.random::<f64>() < p.platform_spin_share {
                    l.spin = sign * uniform(rng, spin_lo, spin_hi);
                    l.secs = uniform(rng, 20.0, 180.0) / l.spin.abs() + uniform(rng, 0.5, 3.0);
                }
                l
            }
            _ => Leg::new(uniform(rng, 1.0, 5.0), -uniform(rng, 0.2, 0.8), 0.0),
        };
        planned += leg.secs;
        legs.push(leg);
    }
    legs
}

/// The true motion at 10 Hz: (heading °, signed speed m/s) per step. Speed follows the
/// legs' targets with limited acceleration; heading follows signed speed × curvature,
/// plus the spin of a turn-in-place platform.
fn kinematics(rng: &mut ChaCha8Rng, legs: &[Leg], steps: usize) -> Vec<(f64, f64)> {
    let acc = uniform(rng, 1.0, 2.5);
    let dec = uniform(rng, 1.5, 3.5);
    let mut heading = uniform(rng, 0.0, 360.0);
    let mut v = 0.0f64;
    let mut out = Vec::with_capacity(steps);
    let mut legs = legs.iter();
    let mut leg = *legs.next().expect("a plan");
    let mut left = leg.secs;
    for _ in 0..steps {
        while left <= 0.0 {
            leg = *legs.next().unwrap_or(&Leg::new(1e9, 0.0, 0.0));
            left = leg.secs;
        }
        left -= DT;
        // Changing direction passes through zero; braking is harder than accelerating.
        let target = if leg.speed * v < 0.0 { 0.0 } else { leg.speed };
        let limit = if target.abs() < v.abs() { dec } else { acc };
        v += (target - v).clamp(-limit * DT, limit * DT);
        let spin = if v.abs() < 0.05 { leg.spin } else { 0.0 };
        // Drivers keep lateral acceleration under ~0.4 g: a curve taken too fast widens.
        let yaw =
            (v * leg.curvature).clamp(-A_LAT_MAX / v.abs().max(0.1), A_LAT_MAX / v.abs().max(0.1));
        heading = (heading + yaw.to_degrees() * DT + spin * DT).rem_euclid(360.0);
        out.push((heading, v));
    }
    out
}

/// A receiver's settings for one track.
struct Receiver {
    kind: ReceiverKind,
    rate_hz: u32,
    sigma: f64,
    lag_s: f64,
    corr_s: f64,
    sacc_factor: f64,
    /// Antenna-to-body misalignment: the course of a vehicle driving straight, relative
    /// to where it points, degrees.
    boresight_deg: f64,
    /// Sideslip per lateral acceleration, °/(m/s²) (the velocity of the antenna turns
    /// away from the body in curves).
    slip_deg: f64,
    /// Where the antenna sits, metres forward and right of the point the vehicle turns
    /// about (a car's rear axle, a platform's wheel axis centre). Turning moves it
    /// sideways by `ω × r`: a car's course leads its heading by `atan(L·κ)` in a curve
    /// (the shared real drive: about 65° per 1/m of curvature, L ≈ 1.1 m, 8–10° in
    /// junction turns), and a platform spinning in place shows a velocity.
    lever_m: (f64, f64),
}

impl Receiver {
    fn draw(p: &DriveParams, platform: Platform, rng: &mut ChaCha8Rng) -> Self {
        let kind = *p.receivers.choose(rng).unwrap_or(&ReceiverKind::Ublox);
        Self {
            kind,
            rate_hz: *p.rates_hz.choose(rng).unwrap_or(&1),
            sigma: log_uniform(rng, p.sigma_min, p.sigma_max),
            // Only some receivers smooth; RTKLIB's epoch-by-epoch Doppler does not.
            lag_s: match kind {
                ReceiverKind::Rtklib | ReceiverKind::Snap => 0.0,
                ReceiverKind::Consumer | ReceiverKind::UbloxHold => {
                    uniform(rng, 0.5, p.lag_max_s.max(0.5))
                }
                _ if rng.random::<f64>() < 0.5 => 0.0,
                _ => uniform(rng, 0.2, p.lag_max_s),
            },
            corr_s: uniform(rng, 0.5, 3.0),
            sacc_factor: uniform(rng, 0.7, 1.5),
            boresight_deg: 0.4 * rng.sample::<f64, _>(StandardNormal),
            slip_deg: uniform(rng, -0.3, 0.3),
            // Roof antennas sit 0–2.5 m ahead of a car's rear axle (further on a truck's
            // cab); a robot's anywhere on its deck.
            lever_m: match platform {
                Platform::Car => (uniform(rng, 0.0, 2.5), uniform(rng, -0.3, 0.3)),
                Platform::TurnInPlace => (uniform(rng, -0.25, 0.25), uniform(rng, -0.25, 0.25)),
            },
        }
    }

    /// What the output style makes of velocity `v` (north, east; m/s) with `course` the
    /// course it holds (radians) and `snapped` whether it reads 0.000 now: the reported
    /// north and east velocity and sAcc (NaN: none).
    fn report(
        &self,
        p: &DriveParams,
        v: (f64, f64),
        course: f64,
        snapped: bool,
    ) -> (f64, f64, f64) {
        let (vn, ve) = v;
        let (mn, me) = if snapped {
            (0.0, 0.0)
        } else {
            (q(vn, 1e-3), q(ve, 1e-3))
        };
        match self.kind {
            ReceiverKind::Ublox | ReceiverKind::UbloxHold => (
                mn,
                me,
                q(self.sigma * self.sacc_factor * p.sacc_scale, 1e-3),
            ),
            ReceiverKind::Rtklib => (vn, ve, 0.07 * self.sacc_factor.sqrt()),
            ReceiverKind::Nmea => {
                let sp = q(vn.hypot(ve), 0.0514); // 0.1 knot
                let cd = q(course.to_degrees(), 0.1).to_radians();
                (sp * cd.cos(), sp * cd.sin(), f64::NAN)
            }
            ReceiverKind::Consumer | ReceiverKind::Snap => (mn, me, f64::NAN),
        }
    }
}

/// Simulate one track of `platform` for `secs` seconds.
pub fn simulate_track(
    p: &DriveParams,
    platform: Platform,
    secs: f64,
    rng: &mut ChaCha8Rng,
) -> (ReceiverKind, u32, Vec<DriveSample>) {
    let steps = (secs / DT).round() as usize;
    let legs = match platform {
        Platform::Car => car_plan(rng, secs),
        Platform::TurnInPlace => platform_plan(p, rng, secs),
    };
    let truth = kinematics(rng, &legs, steps);
    let rx = Receiver::draw(p, platform, rng);
    let gaps = gap_mask(p, rng, steps);
    let bad = bad_sky_mask(p, rng, steps);
    let samples = observe(p, &rx, &truth, &gaps, &bad, rng);
    (rx.kind, rx.rate_hz, samples)
}

/// `true` at the 10 Hz steps where the receiver has no fix.
fn gap_mask(p: &DriveParams, rng: &mut ChaCha8Rng, steps: usize) -> Vec<bool> {
    stretches(rng, steps, p.gaps_per_min, |rng| {
        match rng.random::<f64>() {
            u if u < 0.7 => uniform(rng, 1.0, 5.0),
            u if u < 0.95 => uniform(rng, 5.0, 30.0),
            _ => uniform(rng, 30.0, 180.0),
        }
    })
}

/// `true` at the 10 Hz steps under poor sky.
fn bad_sky_mask(p: &DriveParams, rng: &mut ChaCha8Rng, steps: usize) -> Vec<bool> {
    let max = p.bad_sky_max_s.max(10.0);
    stretches(rng, steps, p.bad_sky_per_min, |rng| uniform(rng, 10.0, max))
}

/// Stretches starting at `per_min` per minute (Poisson), each `len_s(rng)` seconds.
fn stretches(
    rng: &mut ChaCha8Rng,
    steps: usize,
    per_min: f64,
    mut len_s: impl FnMut(&mut ChaCha8Rng) -> f64,
) -> Vec<bool> {
    let mut mask = vec![false; steps];
    let rate = per_min / 60.0 * DT;
    let mut k = 0;
    while k < steps {
        if rng.random::<f64>() < rate {
            let end = (k + (len_s(rng) / DT) as usize).min(steps);
            mask[k..end].fill(true);
            k = end;
        }
        k += 1;
    }
    mask
}

/// Velocity glitches: rare everywhere, frequent under poor sky, where one lasts one
/// to a few epochs (a multipath reflection persists while the geometry does).
struct Glitches {
    left: u32,
    offset: (f64, f64),
}

impl Glitches {
    /// The glitch offset (m/s, north and east) of this output epoch.
    fn next(&mut self, p: &DriveParams, bad: bool, rng: &mut ChaCha8Rng) -> (f64, f64) {
        if self.left == 0 {
            let prob = if bad { p.p_glitch_bad } else { p.p_glitch };
            if rng.random::<f64>() >= prob {
                return (0.0, 0.0);
            }
            let m = if bad {
                uniform(rng, 0.5, 5.0)
            } else {
                uniform(rng, 1.0, 5.0)
            };
            let d = uniform(rng, 0.0, std::f64::consts::TAU);
            self.offset = (m * d.cos(), m * d.sin());
            self.left = 1;
            while bad && self.left < 4 && rng.random::<f64>() < 0.35 {
                self.left += 1;
            }
        }
        self.left -= 1;
        self.offset
    }
}

/// The antenna's velocity (north, east; m/s) from the vehicle turning at `yaw_rate`
/// (rad/s, clockwise seen from above) about a point `lever` (metres forward, right)
/// behind it, at heading `h_deg`: `ω × r`, sideways for a forward lever.
fn lever_velocity(h_deg: f64, yaw_rate: f64, lever: (f64, f64)) -> (f64, f64) {
    let (forward, right) = (-yaw_rate * lever.1, yaw_rate * lever.0);
    let (s, c) = h_deg.to_radians().sin_cos();
    (forward * c - right * s, forward * s + right * c)
}

/// The velocity noise of a receiver whose output is its navigation filter's (the
/// styles that hold static, [`ReceiverKind::Consumer`] and [`ReceiverKind::UbloxHold`]):
/// the raw noise (correlated and white, drawn at every 10 Hz step) passes through the
/// same first-order lag as the motion, then is scaled back to the track's σ. Such a
/// filter smooths its noise as it smooths the course, so its output's noise is
/// correlated over the lag, where raw Doppler velocity's white share is not: the sign
/// the model reads to tell a lagging receiver from one that does not lag. The other
/// styles' noise is added to the lagged motion at each output epoch.
struct SmoothedNoise {
    /// Filtered correlated and white parts, north and east.
    corr: [f64; 2],
    white: [f64; 2],
    /// Stationary standard deviation of the filtered sum for unit raw σ.
    scale: f64,
}

impl SmoothedNoise {
    /// `None` unless `rx` is a navigation filter's output that lags; `phi` is the raw
    /// correlated part's correlation over one step.
    fn new(rx: &Receiver, phi: f64) -> Option<Self> {
        let filters = matches!(rx.kind, ReceiverKind::Consumer | ReceiverKind::UbloxHold);
        if !filters || rx.lag_s <= 0.0 {
            return None;
        }
        // y = a·y + α·x: a white input of unit variance leaves α²/(1−a²), a first-order
        // one of correlation φ leaves that times (1+aφ)/(1−aφ).
        let alpha = 1.0 - (-DT / rx.lag_s).exp();
        let a = 1.0 - alpha;
        let white = alpha * alpha / (1.0 - a * a);
        let corr = white * (1.0 + a * phi) / (1.0 - a * phi);
        let var = NOISE_CORRELATED_SHARE.powi(2) * corr + NOISE_WHITE_SHARE.powi(2) * white;
        Some(Self {
            corr: [0.0; 2],
            white: [0.0; 2],
            scale: var.sqrt(),
        })
    }

    /// One 10 Hz step of the filter (`alpha` the lag's), `ar` the raw correlated part.
    fn step(&mut self, alpha: f64, ar: &[f64; 2], rng: &mut ChaCha8Rng) {
        for ((c, w), a) in self.corr.iter_mut().zip(&mut self.white).zip(ar) {
            let x: f64 = rng.sample(StandardNormal);
            *c += alpha * (a - *c);
            *w += alpha * (x - *w);
        }
    }

    /// The noise (north, east; m/s) of an output epoch for a track of noise `sigma`.
    fn out(&self, sigma: f64) -> (f64, f64) {
        let at = |i: usize| {
            sigma * (NOISE_CORRELATED_SHARE * self.corr[i] + NOISE_WHITE_SHARE * self.white[i])
                / self.scale
        };
        (at(0), at(1))
    }
}

/// The receiver's view of the true motion: lag, correlated + white noise, glitches,
/// output style, rate and gaps.
fn observe(
    p: &DriveParams,
    rx: &Receiver,
    truth: &[(f64, f64)],
    gaps: &[bool],
    bad: &[bool],
    rng: &mut ChaCha8Rng,
) -> Vec<DriveSample> {
    let every = (10 / rx.rate_hz.clamp(1, 10)) as usize;
    let alpha = if rx.lag_s > 0.0 {
        1.0 - (-DT / rx.lag_s).exp()
    } else {
        1.0
    };
    let phi = (-DT / rx.corr_s).exp();
    let (mut ln, mut le) = (0.0, 0.0);
    let mut ar = [0.0f64; 2];
    let mut smooth = SmoothedNoise::new(rx, phi);
    let mut course = f64::NAN;
    let mut glitches = Glitches {
        left: 0,
        offset: (0.0, 0.0),
    };
    let mut out = Vec::new();
    let mut h_prev = truth.first().map_or(0.0, |t| t.0);
    for (k, &(h, v)) in truth.iter().enumerate() {
        let yaw_rate = ((h - h_prev + 540.0).rem_euclid(360.0) - 180.0).to_radians() / DT;
        h_prev = h;
        let slip = rx.boresight_deg + rx.slip_deg * v.abs() * yaw_rate;
        let (s, c) = (h + slip).to_radians().sin_cos();
        let (an, ae) = lever_velocity(h, yaw_rate, rx.lever_m);
        ln += alpha * (v * c + an - ln);
        le += alpha * (v * s + ae - le);
        correlated_step(&mut ar, phi, rng);
        if let Some(sm) = smooth.as_mut() {
            sm.step(alpha, &ar, rng);
        }
        if k % every != 0 || gaps[k] {
            continue;
        }
        let (gn, ge) = glitches.next(p, bad[k], rng);
        let (nn, ne) = match &smooth {
            Some(sm) => sm.out(rx.sigma),
            None => {
                let mut white = || NOISE_WHITE_SHARE * rng.sample::<f64, _>(StandardNormal);
                (
                    rx.sigma * (NOISE_CORRELATED_SHARE * ar[0] + white()),
                    rx.sigma * (NOISE_CORRELATED_SHARE * ar[1] + white()),
                )
            }
        };
        let vn = ln + nn + gn;
        let ve = le + ne + ge;
        let speed = vn.hypot(ve);
        // Snaps to zero below its threshold (the track's sAcc factor sets it at
        // 0.3–0.6 m/s), so motion starts with a jump; its course holds while it does.
        let snapped = matches!(
            rx.kind,
            ReceiverKind::Consumer | ReceiverKind::UbloxHold | ReceiverKind::Snap
        ) && speed < 0.3 + 0.375 * (rx.sacc_factor - 0.7);
        if (speed >= 0.1 && !snapped) || course.is_nan() {
            course = ve.atan2(vn);
        }
        let (vn, ve, sacc) = rx.report(p, (vn, ve), course, snapped);
        out.push(DriveSample {
            t_s: k as f64 * DT,
            v_north: vn as f32,
            v_east: ve as f32,
            speed_acc: sacc as f32,
            truth_heading_deg: (h as f32).rem_euclid(360.0) % 360.0,
            true_speed: v.abs() as f32,
            receiver_course_deg: (course.to_degrees().rem_euclid(360.0) % 360.0) as f32,
            reversing: v < -0.05,
        });
    }
    out
}

fn q(v: f64, step: f64) -> f64 {
    (v / step).round() * step
}

/// Simulate `p.tracks` tracks with seed `seed`, whole tracks split into train,
/// validation and test.
pub fn simulate(p: &DriveParams, seed: u64) -> Vec<Track> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut tracks: Vec<Track> = (0..p.tracks)
        .map(|id| {
            let platform = if rng.random::<f64>() < p.platform_share {
                Platform::TurnInPlace
            } else {
                Platform::Car
            };
            let secs = uniform(&mut rng, p.track_min_s, p.track_max_s);
            let (receiver, rate_hz, samples) = simulate_track(p, platform, secs, &mut rng);
            Track {
                id: id as u32,
                platform,
                receiver,
                rate_hz,
                split: Split::Train,
                samples,
            }
        })
        .collect();
    let mut order: Vec<usize> = (0..tracks.len()).collect();
    order.shuffle(&mut rng);
    let n_test = (p.test_fraction * tracks.len() as f64).round() as usize;
    let n_val = (p.val_fraction * tracks.len() as f64).round() as usize;
    for (rank, &i) in order.iter().enumerate() {
        tracks[i].split = if rank < n_test {
            Split::Test
        } else if rank < n_test + n_val {
            Split::Val
        } else {
            Split::Train
        };
    }
    tracks
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::eval::{atan2_heading_deg, wrap_deg};

    fn small() -> DriveParams {
        DriveParams {
            tracks: 12,
            track_min_s: 200.0,
            track_max_s: 400.0,
            ..DriveParams::default()
        }
    }

    #[test]
    fn deterministic_per_seed() {
        // Debug text, because NaN (no sAcc) is not equal to itself.
        let run = |seed| format!("{:?}", simulate(&small(), seed));
        assert_eq!(run(3), run(3));
        assert_ne!(run(3), run(4));
    }

    /// An antenna ahead of the rear axle leads the heading by `atan(L·κ)` in a curve
    /// (right of it in a right turn), and backing up with the same steering swings it
    /// the same way about a heading that now turns left: course = heading − 180° +
    /// `atan(L·κ)`.
    #[test]
    fn an_antenna_ahead_of_the_axle_leads_in_curves() {
        let p = DriveParams {
            p_glitch: 0.0,
            ..DriveParams::default()
        };
        let rx = Receiver {
            kind: ReceiverKind::Ublox,
            rate_hz: 10,
            sigma: 0.0,
            lag_s: 0.0,
            corr_s: 1.0,
            sacc_factor: 1.0,
            boresight_deg: 0.0,
            slip_deg: 0.0,
            lever_m: (1.2, 0.0),
        };
        for (speed, lead) in [
            (5.0, (1.2f64 / 10.0).atan().to_degrees()),
            (-2.0, (1.2f64 / 10.0).atan().to_degrees() - 180.0),
        ] {
            // A right turn of radius 10 m: heading grows by speed/10 rad/s.
            let truth: Vec<(f64, f64)> = (0..50)
                .map(|k| ((k as f64 * DT * speed / 10.0).to_degrees(), speed))
                .collect();
            let none = vec![false; truth.len()];
            let mut rng = ChaCha8Rng::seed_from_u64(1);
            let out = observe(&p, &rx, &truth, &none, &none, &mut rng);
            for s in &out[1..] {
                let course = s.v_east.atan2(s.v_north).to_degrees();
                let d = wrap_deg(course - s.truth_heading_deg);
                assert!(
                    (d - lead as f32).abs() < 0.1,
                    "speed {speed}: course - heading {d}, expected {lead}"
                );
            }
        }
    }

    /// Lag-1 correlation of the 5 Hz changes of a noise series sampled every other
    /// 10 Hz step.
    fn change_correlation(x: &[f64]) -> f64 {
        let d: Vec<f64> = x
            .iter()
            .step_by(2)
            .collect::<Vec<_>>()
            .windows(2)
            .map(|w| w[1] - w[0])
            .collect();
        let num: f64 = d.windows(2).map(|w| w[0] * w[1]).sum();
        num / d.iter().map(|a| a * a).sum::<f64>()
    }

    /// A navigation filter's output noise keeps the track's σ but is smoothed over the
    /// lag: its 5 Hz changes no longer undo each other as raw noise's white share makes
    /// them (the sign the model reads to tell a lagging receiver that holds static from
    /// a raw one, `Vehicle::raw_velocity` in ghnet-inference).
    #[test]
    fn a_filtering_receivers_noise_is_smoothed_to_its_sigma() {
        let rx = Receiver {
            kind: ReceiverKind::Consumer,
            rate_hz: 5,
            sigma: 0.1,
            lag_s: 1.0,
            corr_s: 1.0,
            sacc_factor: 1.0,
            boresight_deg: 0.0,
            slip_deg: 0.0,
            lever_m: (0.0, 0.0),
        };
        let phi = (-DT / rx.corr_s).exp();
        let alpha = 1.0 - (-DT / rx.lag_s).exp();
        let mut sm = SmoothedNoise::new(&rx, phi).expect("a consumer receiver filters");
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        let mut ar = [0.0f64; 2];
        let (mut filtered, mut raw) = (Vec::new(), Vec::new());
        for k in 0..60_000 {
            correlated_step(&mut ar, phi, &mut rng);
            sm.step(alpha, &ar, &mut rng);
            if k >= 100 {
                filtered.push(sm.out(rx.sigma).0);
                let w: f64 = rng.sample(StandardNormal);
                raw.push(rx.sigma * (NOISE_CORRELATED_SHARE * ar[0] + NOISE_WHITE_SHARE * w));
            }
        }
        let sd = (filtered.iter().map(|x| x * x).sum::<f64>() / filtered.len() as f64).sqrt();
        assert!((sd - 0.1).abs() < 0.01, "σ {sd}");
        let (f, r) = (change_correlation(&filtered), change_correlation(&raw));
        assert!(f > -0.15 && r < -0.25, "filtered {f}, raw {r}");
        let snap = Receiver {
            kind: ReceiverKind::Snap,
            lag_s: 0.0,
            ..rx
        };
        assert!(
            SmoothedNoise::new(&snap, phi).is_none(),
            "raw velocity is not filtered"
        );
    }

    /// Cars stop, reverse with the velocity opposite the heading, and never turn in
    /// place; platforms do turn in place.
    #[test]
    fn cars_reverse_and_stop_platforms_spin() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let p = DriveParams {
            gaps_per_min: 0.0,
            rates_hz: vec![10],
            ..DriveParams::default()
        };
        let (_, _, car) = simulate_track(&p, Platform::Car, 3600.0, &mut rng);
        let stopped = car.iter().filter(|s| s.true_speed < 0.05).count() as f64;
        assert!(stopped / car.len() as f64 > 0.15, "stopped share");
        assert!(car.iter().any(|s| s.reversing));
        for w in car.windows(2) {
            if w[0].true_speed < 0.01 && w[1].true_speed < 0.01 {
                let d = (w[0].truth_heading_deg - w[1].truth_heading_deg).abs();
                assert!(d.min(360.0 - d) < 0.05, "a stopped car turned {d}°");
            }
        }
        let (_, _, pf) = simulate_track(&p, Platform::TurnInPlace, 1500.0, &mut rng);
        let spins = pf
            .windows(2)
            .filter(|w| w[0].true_speed < 0.01 && w[0].truth_heading_deg != w[1].truth_heading_deg)
            .count();
        assert!(spins > 50, "spins {spins}");
    }

    /// A consumer receiver that holds static (velocity snapped to 0.000) holds its
    /// course too, however the robot under it spins: the course baseline cannot know
    /// a heading the receiver's output does not carry.
    #[test]
    fn a_consumer_receivers_course_holds_while_it_snaps() {
        let p = DriveParams {
            tracks: 2,
            receivers: vec![ReceiverKind::Consumer],
            rates_hz: vec![5],
            ..DriveParams::default().robots()
        };
        let mut held = 0;
        for t in simulate(&p, 9) {
            for w in t.samples.windows(2) {
                if w[1].v_north == 0.0 && w[1].v_east == 0.0 && w[1].t_s - w[0].t_s < 0.3 {
                    assert_eq!(w[0].receiver_course_deg, w[1].receiver_course_deg);
                    held += 1;
                }
            }
        }
        assert!(held > 1000, "{held} snapped epochs");
    }

    /// The snap style reads 0.000 at rest as the consumer style does, and at steady
    /// speed its course is as near the heading as a raw receiver's (no lag trailing the
    /// turns): a consumer receiver of the same seed trails further.
    #[test]
    fn a_snap_receiver_snaps_without_lagging() {
        let of = |kind: ReceiverKind| {
            let p = DriveParams {
                tracks: 4,
                receivers: vec![kind],
                rates_hz: vec![5],
                sigma_min: 0.02,
                sigma_max: 0.02,
                ..DriveParams::default().robots()
            };
            let (mut zeros, mut err, mut n) = (0, 0.0f64, 0);
            for t in simulate(&p, 12) {
                for s in &t.samples {
                    zeros += usize::from(s.v_north == 0.0 && s.v_east == 0.0);
                    if s.true_speed > 1.0 && !s.reversing {
                        let course = atan2_heading_deg(s.v_north, s.v_east);
                        err += f64::from(wrap_deg(course - s.truth_heading_deg).abs());
                        n += 1;
                    }
                }
                assert!(t.samples.iter().all(|s| s.speed_acc.is_nan()), "no sAcc");
            }
            (zeros, err / f64::from(n.max(1)))
        };
        let (snap_zeros, snap_err) = of(ReceiverKind::Snap);
        let (_, consumer_err) = of(ReceiverKind::Consumer);
        assert!(snap_zeros > 1000, "{snap_zeros} snapped epochs");
        assert!(
            snap_err < 0.7 * consumer_err,
            "snap {snap_err}° against consumer {consumer_err}°"
        );
    }

    /// A u-blox with its static hold on snaps to 0.000 at rest as a consumer receiver
    /// does and reports its sAcc on every epoch, standing or moving; `sacc_scale`
    /// multiplies the u-blox sAcc and nothing else (the same seed draws the same track).
    #[test]
    fn a_static_hold_ublox_snaps_and_reports_its_sacc() {
        let p = DriveParams {
            tracks: 2,
            receivers: vec![ReceiverKind::UbloxHold],
            rates_hz: vec![5],
            ..DriveParams::default()
        };
        let scaled = DriveParams {
            sacc_scale: 3.0,
            ..p.clone()
        };
        let (a, b) = (simulate(&p, 4), simulate(&scaled, 4));
        let mut zeros = 0;
        for (ta, tb) in a.iter().zip(&b) {
            assert_eq!(ta.samples.len(), tb.samples.len());
            for (x, y) in ta.samples.iter().zip(&tb.samples) {
                assert!(x.speed_acc > 0.0, "an sAcc on every epoch");
                assert!(
                    (y.speed_acc - 3.0 * x.speed_acc).abs() <= 2e-3,
                    "{x:?} {y:?}"
                );
                assert_eq!((x.v_north, x.v_east), (y.v_north, y.v_east));
                zeros += usize::from(x.v_north == 0.0 && x.v_east == 0.0);
            }
        }
        assert!(zeros > 100, "{zeros} snapped epochs");
    }
}
