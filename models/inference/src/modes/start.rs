//! The start of a history: when the model stops answering the first epoch's course
//! (the `kf` convention) and starts following the vehicle.

use super::noise::{measurement, platform_sigma_v};
use super::params::ModeParams;
use super::release::RELEASE_COURSE_DEG;
use super::state::StepState;
use crate::head::{wrap_rad, MAX_STD_DEG};

/// Seconds of steady slow motion (moving by the receiver's own accuracy, course within
/// [`RELEASE_COURSE_DEG`] from epoch to epoch) that start a history which `kf`'s gate
/// has not started yet, for a vehicle not known to be a car.
///
/// `kf`'s gate (its tuned σ_v, about 0.8 m/s) keeps a platform that creeps from its
/// first stand at walking pace answered with its first course (noise) for as long as it
/// creeps. Starting on the receiver's accuracy alone answers that creep, but also a car
/// backing out of its parking space, whose course is then a half turn off its heading:
/// nothing tells a back-out from forward motion at the start, while the first course is
/// a quarter turn off on average. A back-out is one leg of a parking manoeuvre, a car
/// length or two at walking pace, and ends in a stop within a few seconds; steady motion
/// that lasts longer than that is the vehicle going somewhere, and its course is the
/// heading (the shared real drive's back-out has four seconds of steady motion).
pub const START_S: f32 = 10.0;

/// The start run after this epoch: whether the history starts here. Feeds
/// [`StepState::start_s`], [`StepState::start_course`] and [`StepState::start_skips`];
/// a car's start keeps `kf`'s gate alone (it may be backing out however long it creeps).
///
/// An epoch continues the run when its speed passes `kf`'s gate on the receiver's own
/// accuracy (its course carries information) along the run's course (within
/// [`RELEASE_COURSE_DEG`]); the run's course follows it over about a second, as a
/// creeping platform turns. Up to `max_skips` epochs in a row may fail that (slow
/// creep dips into the noise now and then) before the run ends.
pub(super) fn started(
    mp: &ModeParams,
    st: &mut StepState,
    speed: f32,
    course: f32,
    acc: f32,
    dt: f32,
) -> bool {
    if st.vehicle.car {
        (st.start_s, st.start_course, st.start_skips) = (0.0, f32::NAN, 0);
        return false;
    }
    let (_, r) = measurement(speed, platform_sigma_v(mp, acc));
    let informative = r < MAX_STD_DEG.to_radians();
    let off = wrap_rad(course - st.start_course);
    if informative && st.start_course.is_finite() && off.abs() <= RELEASE_COURSE_DEG.to_radians() {
        st.start_s += dt;
        st.start_course = wrap_rad(st.start_course + (dt / START_TURN_TAU_S).min(1.0) * off);
        st.start_skips = 0;
    } else if st.start_course.is_finite() && st.start_skips < mp.max_skips {
        st.start_skips += 1;
    } else {
        st.start_s = 0.0;
        st.start_course = if informative { course } else { f32::NAN };
        st.start_skips = 0;
    }
    // Tolerance for the sum of many short intervals (50 at 5 Hz).
    st.start_s + 1e-3 >= START_S
}

/// Time constant (s) over which the start run's course follows the epochs' courses.
const START_TURN_TAU_S: f32 = 1.0;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::modes::{commit, prepare, Platform};

    /// Epochs at 5 Hz from rest, then `secs` of motion at `speed` along `course_deg`
    /// (sAcc 0.05 m/s, small alternating noise), through the filter alone; the last
    /// answer (degrees) and whether the history started.
    fn creep(platform: Platform, speed: f32, course_deg: f32, secs: f32) -> (f32, bool) {
        let mp = ModeParams::default();
        let mut st = StepState::fresh(platform);
        let mut psi = f32::NAN;
        let mut step_at = |st: &mut StepState, vn: f32, ve: f32| {
            let step = prepare(&mp, 0.5, st, vn, ve, 0.05, 0.2);
            psi = commit(st, &step, &[0.0, 0.0, 0.0], 0.2).psi;
        };
        // Standing: the first course is noise pointing east.
        for k in 0..10 {
            let e = if k % 2 == 0 { 0.02 } else { -0.02 };
            step_at(&mut st, 0.01, e + 0.02);
        }
        let (s, c) = course_deg.to_radians().sin_cos();
        for k in 0..(secs / 0.2).round() as usize {
            let wobble = if k % 2 == 0 { 0.03 } else { -0.03 };
            step_at(&mut st, speed * c - wobble * s, speed * s + wobble * c);
        }
        (wrap_rad(psi).to_degrees(), st.moved)
    }

    /// A platform creeping north at 0.4 m/s (under `kf`'s gate) is answered along its
    /// course once it has crept for [`START_S`], not with its first course (east).
    #[test]
    fn a_steady_creep_starts_the_history() {
        let (psi, moved) = creep(Platform::Auto, 0.4, 0.0, START_S + 1.0);
        assert!(moved && psi.abs() < 10.0, "answered {psi}°");
        let (psi, moved) = creep(Platform::Auto, 0.4, 0.0, START_S - 1.0);
        assert!(!moved && psi > 45.0, "not yet: {psi}°");
    }

    /// A car's back-out under `kf`'s gate keeps the start convention: a short one from
    /// any vehicle, a long one from a known car.
    #[test]
    fn a_back_out_keeps_the_first_course() {
        let (psi, moved) = creep(Platform::Auto, 0.6, 180.0, 6.0);
        assert!(!moved && psi > 45.0 && psi < 135.0, "{psi}°");
        let (psi, moved) = creep(Platform::Car, 0.6, 180.0, 3.0 * START_S);
        assert!(!moved && psi > 45.0 && psi < 135.0, "{psi}°");
    }
}
