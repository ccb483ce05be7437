//! How a standing car stays put and when it leaves: the glitch gate (stricter at a
//! stand) and the release rule, whose clock of plain motion on a steady course ends
//! any stand.

use super::params::ModeParams;
use super::state::StepState;
use super::vehicle::Platform;
use crate::head::wrap_rad;

/// Speed (m/s) from which an epoch is plain motion for the release rule
/// ([`StepState::t_motion`]), whatever the noise estimate says: a receiver at rest does
/// not read this fast for a second with a steady course, unless its sAcc says it may
/// (then `3·sAcc` is the bar).
pub const RELEASE_SPEED: f32 = 0.8;

/// Seconds of plain motion on a steady course that end any stand ([`StepState::t_motion`]):
/// once a vehicle has shown this much consistent motion, its answer follows the course,
/// whatever the stand's rules (a car's axis, a glitch burst's confirmation, a noise
/// estimate inflated by slow driving) would still say. Longer than the glitch bursts of
/// poor sky at 5 Hz and faster, short enough that no answer carries a stop's heading
/// for more than about a second of driving.
pub const RELEASE_S: f32 = 0.8;

/// Largest receiver noise σ (m/s) the release rule's bar takes from the running
/// estimate (the bar is 4σ): beyond it the estimate is more likely slow driving read
/// as noise than a receiver that noisy at rest.
pub const RELEASE_NOISE_CAP: f32 = 0.3;

/// Fewest epochs of plain motion that end a stand (with [`RELEASE_S`]): at 1 and 2 Hz
/// a burst of two equal glitches under poor sky spans a second, and releasing a parked
/// car on it turned its held heading.
pub const RELEASE_EPOCHS: u16 = 3;

/// Largest course change (°) between successive epochs of plain motion: a steadier
/// course than this is motion, not noise or a glitch burst's scatter.
pub const RELEASE_COURSE_DEG: f32 = 30.0;

impl StepState {
    /// Whether the release rule ends a stand on this epoch: a second of plain motion
    /// on a steady course ([`RELEASE_S`], and at least two epochs).
    #[inline]
    pub fn released(&self) -> bool {
        self.t_motion >= RELEASE_S && self.n_motion >= RELEASE_EPOCHS
    }
}

/// Whether the glitch gate rejects this velocity: a change from the last used velocity
/// that a car cannot make in the time since.
///
/// At speed that is `a_max·dt` (at most `max_skips` epochs in a row). A standing car is
/// stricter, because a held heading is only as good as the epochs it ignores: a burst
/// of glitches at a stop used to turn it once `max_skips` ran out, and a single spike of
/// 1–3 m/s at 1 Hz is within `a_max·dt`. So a standing car leaves rest only on a
/// velocity reachable from rest in the time since the last used one (no count limit:
/// a real departure always is), only when the next epoch confirms it (a spike does
/// not repeat; a departure does, one epoch later), and for `axis_secs` only along the
/// axis of a sure held heading (a car cannot leave a stand sideways; most glitches
/// point elsewhere).
#[inline]
#[allow(clippy::too_many_arguments)] // one epoch's numbers
pub(super) fn glitch(
    mp: &ModeParams,
    st: &mut StepState,
    vn: f32,
    ve: f32,
    speed: f32,
    sig: f32,
    dt: f32,
    moving: bool,
    p: f32,
    r: f32,
) -> bool {
    let standing = st.vehicle.car && st.t_still > 0.0;
    let gated = speed > mp.gate_speed || standing;
    // A car cannot change its velocity by more than `a_max` per second (plus the noise).
    let prev = st.prev_v;
    let unreachable = |secs: f32| (vn - prev[0]).hypot(ve - prev[1]) > mp.a_max * secs + 3.0 * sig;
    let reject = if !(st.prev_v[0].is_finite() && gated && dt > 0.0) {
        false
    } else if standing && st.released() {
        // A second of plain motion on a steady course ends any stand: a car that did
        // not leave along its axis turned in place (or its held heading was wrong).
        if off_axis_of_held(mp, st, vn, ve, p, r) && st.vehicle.platform == Platform::Auto {
            st.vehicle.car = false;
            (st.t_fast, st.n_fast) = (0.0, 0);
        }
        false
    } else if standing {
        let elapsed = st.t_used + dt;
        let pending = st.pending_v;
        let confirmed = pending[0].is_finite()
            && (vn - pending[0]).hypot(ve - pending[1]) <= mp.a_max * dt + 3.0 * sig;
        st.pending_v = if moving { [vn, ve] } else { [f32::NAN; 2] };
        let sideways = off_axis_of_held(mp, st, vn, ve, p, r);
        let reject = unreachable(elapsed)
            || (moving && (!confirmed || (sideways && elapsed <= mp.axis_secs)));
        if !reject && moving && sideways && st.vehicle.platform == Platform::Auto {
            // It kept leaving sideways: it turned in place, so it is no car (a car
            // shows itself again by driving fast).
            st.vehicle.car = false;
            (st.t_fast, st.n_fast) = (0.0, 0);
        }
        reject
    } else {
        unreachable(dt) && st.skips < mp.max_skips
    };
    if reject {
        st.skips = st.skips.saturating_add(1);
        st.t_used += dt;
    } else {
        st.skips = 0;
        st.t_used = 0.0;
        st.pending_v = [f32::NAN; 2];
    }
    reject
}

/// Whether a velocity leaves a sure held heading's axis (further than `axis_deg` plus
/// 2σ of the course): a car cannot leave a stand sideways.
fn off_axis_of_held(mp: &ModeParams, st: &StepState, vn: f32, ve: f32, p: f32, r: f32) -> bool {
    let sure = p < mp.confident_deg.to_radians().powi(2);
    let off = wrap_rad(ve.atan2(vn) - st.psi).abs();
    let off_axis = off.min(std::f32::consts::PI - off);
    sure && off_axis > mp.axis_deg.to_radians() + 2.0 * r
}

/// The release rule's clock ([`StepState::t_motion`]): runs while epochs are plain
/// motion (at least [`RELEASE_SPEED`] and `3·sAcc`) on a steady course.
#[inline]
pub(super) fn track_motion(
    mp: &ModeParams,
    st: &mut StepState,
    vn: f32,
    ve: f32,
    acc: f32,
    dt: f32,
) {
    let speed = vn.hypot(ve);
    // The receiver's noise at rest as measured, capped: slow driving inflates the
    // estimate (it reads slow speeds as noise), and that must not hide real motion.
    let noise = (st.vehicle.noise / mp.quantile_factor()).min(RELEASE_NOISE_CAP);
    let acc = if acc.is_finite() { acc } else { 0.0 };
    let bar = RELEASE_SPEED.max(3.0 * acc).max(4.0 * noise);
    let plain = speed >= bar;
    st.motion_dt += dt;
    // Steady: the course within RELEASE_COURSE_DEG and the velocity within what a
    // vehicle can change since the run's last epoch (glitch bursts come back to back
    // with other sizes).
    let [pn, pe] = st.motion_v;
    let since = st.motion_dt;
    let steady = st.n_motion > 0
        && since <= 2.0
        && wrap_rad(ve.atan2(vn) - pe.atan2(pn)).abs() <= RELEASE_COURSE_DEG.to_radians()
        && (vn - pn).hypot(ve - pe) <= mp.a_max * since + 0.3;
    if plain && steady {
        // Skipped epochs' time does not count: two glitch bursts alike, apart, are not
        // a departure.
        st.t_motion += dt;
        st.n_motion = st.n_motion.saturating_add(1);
    } else if plain && st.n_motion > 0 && st.motion_skips < mp.max_skips {
        // A glitch inside a departure neither counts nor ends the run (the run's time
        // goes on, measured from its last steady epoch).
        st.motion_skips += 1;
        return;
    } else {
        st.t_motion = 0.0;
        st.n_motion = u16::from(plain);
    }
    st.motion_skips = 0;
    st.motion_dt = 0.0;
    st.motion_v = [vn, ve];
}
