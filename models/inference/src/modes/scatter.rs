//! The course scatter a source shows at speed, the floor under a moving epoch's σ for
//! receivers noisier than they say.

use super::state::StepState;
use crate::head::wrap_rad;

/// Speed (m/s) from which courses feed [`Vehicle::scatter`]: slower, the course's
/// scatter is the speed's business, which σ already knows.
///
/// [`Vehicle::scatter`]: crate::modes::Vehicle::scatter
pub const SCATTER_SPEED: f32 = 3.0;

/// Longest epoch interval (s) whose course feeds [`Vehicle::scatter`]: over a longer
/// one the vehicle's own turning (a junction at 1 Hz) outweighs the receiver's noise,
/// and a floor built on it doubled a 1 Hz car's σ on straights.
///
/// [`Vehicle::scatter`]: crate::modes::Vehicle::scatter
pub const SCATTER_MAX_DT: f32 = 0.55;

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

/// Seconds of driving [`Vehicle::scatter`] averages over.
///
/// [`Vehicle::scatter`]: crate::modes::Vehicle::scatter
pub const SCATTER_TAU_S: f32 = 30.0;

/// Feed [`Vehicle::scatter`] with this epoch's course against the previous heading
/// turned at the yaw rate, when both epochs moved at speed (no stop, gap or glitch in
/// between: `t_still` and `prev_speed` say so) and not in reverse.
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
    let x = (speed * e.sin()).powi(2).min(1.0);
    let v = &mut st.vehicle.scatter;
    *v = if v.is_finite() {
        *v + (dt / SCATTER_TAU_S).min(1.0) * (x - *v)
    } else {
        x
    };
}
