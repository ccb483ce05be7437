//! A car's stand that saw motion off its axis: the held heading may be stale, and its
//! σ says so.
//!
//! A car standing still holds its heading exactly, and leaves the stand only on motion
//! the release rule trusts (at least [`RELEASE_SPEED`], steady, confirmed). A parking
//! manoeuvre on a noisy receiver can stay under that bar: reversing and turning at
//! 0.5–1 m/s, where single epochs of the receiver's noise read as fast. The stand then
//! holds its approach's heading while the car turns, and a held σ of a few degrees puts
//! a quarter-turn error far outside 2σ for as long as the car stays parked. The velocity
//! averaged over a few seconds shows such motion where single epochs do not; a car
//! moves along its axis, so an average well over the noise and off the held axis means
//! the car has turned. The answer keeps the held heading (turned to the average's axis
//! instead, it lost as much as it gained on the noisy copies and up to 19% on 1 Hz car
//! sections), but its σ covers the turn.
//!
//! [`RELEASE_SPEED`]: crate::modes::RELEASE_SPEED

use super::release::off_axis;
use super::state::{Step, StepState};
use crate::head::MAX_STD_DEG;

/// Seconds of the exponential average of a stand's velocity: a manoeuvre's leg lasts
/// several seconds, the receiver noise's correlation about two.
pub const STAND_DOUBT_TAU_S: f32 = 3.0;

/// The averaged velocity shows motion when it exceeds this multiple of the filter's
/// velocity σ (`Step::sigma_v`) and is steady ([`STAND_DOUBT_STEADY`]). On the car
/// sections of models/reports/unmet.md the share within 1σ grew by at most 0.7 points
/// (1 Hz NMEA: the shortest averages); on the shared drive's noisy copies
/// (models/reports/noisy-real.md) it covers the parking manoeuvre at 0.1 m/s of noise,
/// and on two copies of six at 0.2, where the noise estimate reads the manoeuvre as
/// noise.
pub const STAND_DOUBT_NOISE_K: f32 = 1.2;

/// An epoch's speed enters the average clipped at this multiple of the velocity σ: a
/// glitch burst at rest does not make a manoeuvre.
pub const STAND_DOUBT_CLIP_K: f32 = 4.0;

/// The averaged velocity is steady when its square is at least this share of the
/// averaged square speed: 1 for motion on one course, about a sixth for white noise at
/// 1 Hz. The noise estimate lags a receiver it has just met; where it reads low, this
/// keeps the noise from passing for motion.
pub const STAND_DOUBT_STEADY: f32 = 0.5;

/// The answer's σ is at least this share of the angle between the held axis and the
/// one the averaged velocity last showed motion on: the turn the car has made lies
/// within 2σ (the average lags the turn, so the angle reads short: at 0.6 the shared
/// drive's noisy copies left some parking turns just outside).
pub const STAND_DOUBT_SIGMA_K: f32 = 0.75;

/// Update a car's averaged velocity and the axis it last showed motion on while the
/// car stands, after `step`, and return the σ floor (degrees) that sets:
/// [`STAND_DOUBT_SIGMA_K`] times the angle between that axis and the held heading's, 0
/// when none. A moving car's answer follows its course, so no floor: it keeps the
/// average (a stand may follow) and forgets the axis. A car driving (a second of steady
/// motion) and any other vehicle clear both. A glitch the gate rejected does not enter
/// the average.
pub fn stand_doubt(st: &mut StepState, step: &Step, dt: f32) -> f32 {
    let driving = st.moving_now() && st.driving;
    if !st.vehicle.car || driving || !step.sigma_v.is_finite() {
        st.stand_v = [0.0; 2];
        st.stand_p = f32::NAN;
        st.stand_axis = f32::NAN;
        return 0.0;
    }
    if !step.glitch {
        let sigma = step.sigma_v;
        let speed = step.speed.min(STAND_DOUBT_CLIP_K * sigma);
        let a = 1.0 - (-dt.max(0.0) / STAND_DOUBT_TAU_S).exp();
        if !st.stand_p.is_finite() {
            st.stand_p = 2.0 * sigma * sigma;
        }
        let v = &mut st.stand_v;
        v[0] += a * (speed * step.course.cos() - v[0]);
        v[1] += a * (speed * step.course.sin() - v[1]);
        st.stand_p += a * (speed * speed - st.stand_p);
        let m2 = v[0] * v[0] + v[1] * v[1];
        if m2.sqrt() > STAND_DOUBT_NOISE_K * sigma && m2 >= STAND_DOUBT_STEADY * st.stand_p {
            st.stand_axis = v[1].atan2(v[0]);
        }
    }
    if st.moving_now() {
        // The answer follows the course: what the average showed before is behind it.
        st.stand_axis = f32::NAN;
    }
    if !st.stand_axis.is_finite() {
        return 0.0;
    }
    let off = off_axis(st.stand_axis, st.psi);
    (STAND_DOUBT_SIGMA_K * off.to_degrees()).min(MAX_STD_DEG)
}
