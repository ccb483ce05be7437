//! The course scatter a source shows at speed, the floor under a moving epoch's σ for
//! receivers noisier than they say.

use super::commit::YAW_TAU_S;
use super::state::StepState;
use crate::head::wrap_rad;

/// Speed (m/s) from which courses feed [`Vehicle::scatter`]: slower, the course's
/// scatter is the speed's business, which σ already knows.
///
/// [`Vehicle::scatter`]: crate::modes::Vehicle::scatter
pub const SCATTER_SPEED: f32 = 3.0;

/// Longest epoch interval (s) over which the filter averages several courses, so that
/// its prediction is smooth beside one course's noise. Over a longer interval (a 1 Hz
/// receiver) the filter follows each course and its prediction, the previous heading
/// turned at the yaw rate, extrapolates the last two courses: their noise is in the
/// residual too, and the scatter update takes it out ([`extrapolation_share`]).
pub const SCATTER_SMOOTH_DT: f32 = 0.55;

/// Longest epoch interval (s) whose course feeds [`Vehicle::scatter`]: a 1 Hz
/// receiver's with its jitter. After a missed epoch the vehicle's own turning (a
/// junction) outweighs the receiver's noise.
///
/// [`Vehicle::scatter`]: crate::modes::Vehicle::scatter
pub const SCATTER_MAX_DT: f32 = 1.5;

/// How many times the σ_v from its sAcc a receiver's course scatter must reach for the
/// scatter floor to apply ([`SigmaMaps::scatter_k`]): the σ maps are fitted on
/// receivers whose sAcc is rough (0.7–1.5× the truth, or RTKLIB's formal value near
/// 0.07 m/s), so they cover those; a floor from twice the sAcc on took the median
/// held-out car drive from 69% to 75% within 1σ, from three times 72%. Receivers
/// without sAcc get the floor as soon as the scatter exceeds the σ_v the filter
/// guessed for them.
///
/// [`SigmaMaps::scatter_k`]: crate::modes::SigmaMaps::scatter_k
pub const SCATTER_RATIO_ACC: f32 = 3.0;

/// How many times its course scatter at speed ([`Vehicle::scatter`]) a receiver's sAcc
/// may be before a moving epoch's σ is taken to be overstated by it
/// ([`acc_overstatement`]). The σ maps are fitted on receivers whose sAcc is 0.7–1.5
/// times their noise; a u-blox reporting three times its sAcc made the filter's σ, and
/// with it the reported σ at speed, three times what its courses showed: without this
/// division its cars' answers at 2 m/s and faster were 77–86% within 1σ and 95–98%
/// within 2σ (the sAcc × 3 car sections of `models/reports/unmet.md`). From 1.5 times the
/// scatter the rough sAcc of ordinary u-blox and RTKLIB cars narrowed their σ too (by
/// up to two points within 1σ on simulated drives); from twice it, by under one.
///
/// [`Vehicle::scatter`]: crate::modes::Vehicle::scatter
pub const ACC_OVERSTATED_RATIO: f32 = 2.0;

/// Largest factor [`acc_overstatement`] divides a moving epoch's raw σ by. The scatter
/// shows the receiver's noise but not what else the filter's σ carries at speed (its
/// walk between courses, which is most of it above 10 m/s): divided by up to three,
/// simulated sAcc × 3 static-hold cars above 10 m/s fell under 90% within 2σ; by up to
/// two they kept it.
pub const ACC_OVERSTATED_MAX: f32 = 2.0;

/// The factor (at least 1, at most [`ACC_OVERSTATED_MAX`]) by which the σ_v the filter
/// weighed a course by (`sigma_v`, m/s, from the receiver's sAcc) overstates the noise
/// the source's courses have shown at speed (`scatter`, m²/s², [`Vehicle::scatter`]),
/// beyond [`ACC_OVERSTATED_RATIO`]; 1 until the scatter is measured. What a moving
/// epoch's raw σ is divided by before the σ maps read it, for a receiver whose sAcc is
/// pessimistic. Only the reported σ: the filter keeps weighing by the sAcc (weighed by
/// at most twice the scatter instead, simulated sAcc × 3 u-blox cars answered 1–3%
/// better at 1 and 10 Hz but 1% worse at 5 Hz, and worse at 5 m/s and faster at every
/// rate).
///
/// [`Vehicle::scatter`]: crate::modes::Vehicle::scatter
#[inline]
pub fn acc_overstatement(sigma_v: f32, scatter: f32) -> f32 {
    if !(scatter.is_finite() && scatter > 0.0) {
        return 1.0;
    }
    (sigma_v / (ACC_OVERSTATED_RATIO * scatter.sqrt())).clamp(1.0, ACC_OVERSTATED_MAX)
}

/// Seconds of driving [`Vehicle::scatter`] averages over.
///
/// [`Vehicle::scatter`]: crate::modes::Vehicle::scatter
pub const SCATTER_TAU_S: f32 = 30.0;

/// How many times one course's noise variance the residual against the prediction
/// carries over an interval of `dt` s. At most [`SCATTER_SMOOTH_DT`] the prediction is
/// smooth: 1. Over longer intervals the heading is the last course `c₁` and the yaw
/// rate moved by `a = min(dt/YAW_TAU_S, 1)` of the last change `c₁ − c₂`, so the
/// residual is `c₀ − (1+a)·c₁ + a·c₂`: `1 + (1+a)² + a²` courses' worth of white noise
/// (6 at 1 Hz).
#[inline]
pub fn extrapolation_share(dt: f32) -> f32 {
    if dt <= SCATTER_SMOOTH_DT {
        return 1.0;
    }
    let a = (dt / YAW_TAU_S).min(1.0);
    1.0 + (1.0 + a) * (1.0 + a) + a * a
}

/// Feed [`Vehicle::scatter`] with this epoch's course against the previous heading
/// turned at the yaw rate, when both epochs moved at speed (no stop, gap or glitch in
/// between: `t_still` and `prev_speed` say so) and not in reverse, as one course's
/// share of the residual ([`extrapolation_share`]).
///
/// [`Vehicle::scatter`]: crate::modes::Vehicle::scatter
#[inline]
pub(super) fn update_scatter(st: &mut StepState, vn: f32, ve: f32, dt: f32) {
    let speed = vn.hypot(ve);
    if !(st.has_prior
        && st.moving_now()
        && !st.reverse
        && speed >= SCATTER_SPEED
        && st.prev_speed >= SCATTER_SPEED
        && dt > 0.0
        && dt <= SCATTER_MAX_DT)
    {
        return;
    }
    let e = wrap_rad(ve.atan2(vn) - (st.psi + st.yaw * dt));
    // A glitch or a misread direction is not scatter: cap one epoch's share.
    let x = (speed * e.sin()).powi(2).min(1.0) / extrapolation_share(dt);
    let v = &mut st.vehicle.scatter;
    *v = if v.is_finite() {
        *v + (dt / SCATTER_TAU_S).min(1.0) * (x - *v)
    } else {
        x
    };
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The residual's share is one course where the filter smooths and six at 1 Hz
    /// (`c₀ − 2c₁ + c₂`), growing in between.
    #[test]
    fn extrapolation_share_counts_the_courses_in_the_residual() {
        assert_eq!(extrapolation_share(0.1), 1.0);
        assert_eq!(extrapolation_share(SCATTER_SMOOTH_DT), 1.0);
        assert!((extrapolation_share(1.0) - 6.0).abs() < 1e-6);
        assert!((extrapolation_share(1.4) - 6.0).abs() < 1e-6);
        let mid = extrapolation_share(0.8);
        assert!(mid > 4.0 && mid < 6.0, "{mid}");
    }

    /// An sAcc within twice the scatter is believed; beyond, the σ is divided by how far
    /// beyond, up to the cap; an unmeasured scatter changes nothing.
    #[test]
    fn an_overstated_acc_divides_by_how_far_it_overstates_up_to_the_cap() {
        let scatter = 0.1f32 * 0.1;
        assert_eq!(acc_overstatement(0.15, scatter), 1.0);
        assert_eq!(acc_overstatement(0.2, scatter), 1.0);
        assert!((acc_overstatement(0.3, scatter) - 1.5).abs() < 1e-5);
        assert_eq!(acc_overstatement(0.9, scatter), ACC_OVERSTATED_MAX);
        assert_eq!(acc_overstatement(0.9, f32::INFINITY), 1.0);
        assert_eq!(acc_overstatement(0.9, 0.0), 1.0);
    }

    /// On a straight at 1 Hz the scatter measures one course's noise across the track:
    /// white courses of σ 0.01 rad at 10 m/s (0.1 m/s across) read as about 0.1 m/s
    /// once the residual's extrapolated share is taken out.
    #[test]
    fn scatter_at_1hz_reads_one_course() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let mut st = StepState::EMPTY;
        let (mut c1, mut c2) = (0.0f32, 0.0f32);
        for _ in 0..2000 {
            // Uniform in ±√3σ: σ = 0.01 rad.
            let c0: f32 = rng.random_range(-0.01732f32..0.01732);
            // The filter following each course, the yaw rate the last change.
            st.has_prior = true;
            st.prev_speed = 10.0;
            st.psi = c1;
            st.yaw = c1 - c2;
            update_scatter(&mut st, 10.0 * c0.cos(), 10.0 * c0.sin(), 1.0);
            (c2, c1) = (c1, c0);
        }
        let across = st.vehicle.scatter.sqrt();
        assert!((0.07..0.13).contains(&across), "{across} m/s");
    }
}
