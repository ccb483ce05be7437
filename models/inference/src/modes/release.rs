//! How a standing car stays put and when it leaves: the glitch gate (stricter at a
//! stand) and the release rule, whose clock of plain motion on a steady course ends
//! any stand.

use super::params::ModeParams;
use super::state::{HeldHeading, MotionRun, StepState};
use super::vehicle::Platform;
use crate::head::wrap_rad;

/// Speed (m/s) from which an epoch is plain motion for the release rule
/// ([`StepState::motion`]), whatever the noise estimate says: a receiver at rest does
/// not read this fast for a second with a steady course, unless its sAcc says it may
/// (then `3·sAcc` is the bar).
pub const RELEASE_SPEED: f32 = 0.8;

/// Seconds of plain motion on a steady course that end any stand ([`StepState::motion`]):
/// once a vehicle has shown this much consistent motion, its answer follows the course,
/// whatever the stand's rules (a car's axis, a glitch burst's confirmation, a noise
/// estimate inflated by slow driving) would still say. Longer than the glitch bursts of
/// poor sky at 5 Hz and faster, short enough that no answer carries a stop's heading
/// for more than about a second of driving. A run of [`RELEASE_BURST_EPOCHS`] epochs
/// ends a stand sooner, after [`RELEASE_S_MIN`].
pub const RELEASE_S: f32 = 0.8;

/// Epochs of plain motion on a steady course, one more than the longest glitch burst
/// under poor sky, from which [`RELEASE_S_MIN`] of it ends a stand: at 10 Hz
/// [`RELEASE_S`] is nine epochs, twice a burst, and a burst inside a departure pauses
/// its clock: by [`RELEASE_S`] alone, simulated 10 Hz cars held a stand's heading for
/// up to 1.1 s of driving (the `Held` column of models/reports/unmet.md). At 5 Hz five
/// epochs are [`RELEASE_S`] already; at 1 and 2 Hz [`RELEASE_EPOCHS`] and [`RELEASE_S`]
/// decide.
pub const RELEASE_BURST_EPOCHS: u16 = 5;

/// Seconds of plain motion that end a stand once the run has [`RELEASE_BURST_EPOCHS`]
/// epochs. From 0.6 s no simulated 10 Hz car section of models/reports/unmet.md holds
/// a stand for over a second of driving, and their MAE moved by at most 1% (NMEA's
/// stopped row worse, the others as well or better); from 0.5 s, on sections of other
/// seeds, the u-blox cars with three times their sAcc lost 1%.
pub const RELEASE_S_MIN: f32 = 0.6;

/// Largest receiver noise σ (m/s) the release rule's bar takes from the running
/// estimate (the bar is 4σ, or [`RELEASE_NOISE_K_AXIS`]σ along a sure held heading's
/// axis): beyond it the estimate is more likely slow driving read as noise than a
/// receiver that noisy at rest.
pub const RELEASE_NOISE_CAP: f32 = 0.3;

/// [`RELEASE_NOISE_CAP`] at low rates (epochs [`RELEASE_LOW_RATE_DT`] apart or more):
/// four times it is 1 m/s, the speed from which a held answer counts as a stop
/// outliving the motion, so no noise estimate keeps a steady 1 m/s from releasing on
/// its second epoch. At such rates a receiver's noise at rest is independent from one
/// epoch to the next, and two epochs agreeing on the course are rare without motion;
/// at 5 Hz and faster it is correlated over several epochs, and the lower bar released
/// standing cars (the stopped rows of `reports/unmet.md`).
pub const RELEASE_NOISE_CAP_LOW_RATE: f32 = 0.25;

/// Times the capped noise σ that is plain motion along a sure held heading's axis, and
/// anywhere out of an unsure stand ([`UNSURE_HELD_DEG`]); elsewhere 4: a departure
/// along the body is what a car does, and a noisy receiver (σ near
/// [`RELEASE_NOISE_CAP`]) driving off at 1–1.5 m/s dips under 4σ often enough to keep
/// its stand for seconds.
pub const RELEASE_NOISE_K_AXIS: f32 = 3.5;

/// A standing car's held heading is unsure from this σ (degrees) on: the filter's σ
/// with the network's correction `y₂` at the stop (the raw σ the standing σ map
/// reads), twice the default `confident_deg` under which a heading is sure. Such a
/// stand (after a fix gap, or a stop the network doubted) keeps little worth guarding,
/// so a departure from it needs only [`RELEASE_NOISE_K_AXIS`] times the noise, in any
/// direction. At 4σ, noisy receivers' departures at 1–1.5 m/s on simulated 5 Hz NMEA
/// and RTKLIB cars dipped under the bar often enough to hold such stands for over 2 s,
/// tens of degrees off. The release clock stays [`RELEASE_S`]: a shorter one let
/// glitch bursts at 5 Hz release these stands.
pub const UNSURE_HELD_DEG: f32 = 60.0;

/// Times the reported sAcc under which an epoch no longer continues a started run of
/// plain motion (where `3·sAcc` starts one), until the run releases the stand; with
/// [`RELEASE_CONT_NOISE_K`] a hysteresis of the release bar. A car leaving a stand at
/// 1–1.5 m/s on a receiver whose sAcc is near 0.35 m/s reads under `3·sAcc` one epoch
/// in a few; without the hysteresis each such dip restarts the release clock, and on
/// simulated 5 and 10 Hz u-blox and RTKLIB cars a stop's heading is held for well over
/// a second of driving (the `Held` column of models/reports/unmet.md). Once the run
/// has released, the start bars apply again: a lower bar there keeps a braking car
/// driving into its stop and moves what its stop holds (the 5 Hz u-blox cars'
/// stopped row falls under the 2σ goal).
pub const RELEASE_CONT_ACC_K: f32 = 2.5;

/// Times the capped noise σ under which an epoch no longer continues a started run of
/// plain motion before it releases (at most the start's multiple): see
/// [`RELEASE_CONT_ACC_K`]. A lower multiple let noise release the stands of simulated
/// 10 Hz NMEA cars (their 1–2 m/s row got worse).
pub const RELEASE_CONT_NOISE_K: f32 = 3.0;

/// Shortest epoch interval (s) at which [`RELEASE_NOISE_CAP_LOW_RATE`] applies.
pub const RELEASE_LOW_RATE_DT: f32 = 0.5;

/// Fewest epochs of plain motion that end a stand (with [`RELEASE_S`]): two that agree
/// (course within [`RELEASE_COURSE_DEG`], velocity within `a_max·dt`), so that at 1 Hz
/// the second second of driving is answered and a single spike never releases.
pub const RELEASE_EPOCHS: u16 = 2;

/// Epochs of plain motion off the axis of a car's sure held heading, or backwards
/// along it faster than a car backs out (`escape_speed`), that make its release
/// final: at 1 and 2 Hz a burst of two equal glitches under poor sky spans a second,
/// and releasing a parked car on it for good turned its held heading. A car leaves a
/// stand along its body and most glitches point elsewhere, so a shorter run off the
/// axis releases the car but keeps what the stand held, and gives it back if the run
/// ends ([`StepState::before_release`]): the held heading is not lost, and a departure
/// whose held heading was wrong is not held a second longer. The glitches that pass
/// the stand's gate point along the axis; those pointing backwards at 2–5 m/s (a
/// back-out that stops a second later) turned held headings by a half turn, then held
/// with the σ of a sure stop (simulated 1 Hz cars of every receiver style,
/// `models/reports/unmet.md`). Slower backward runs stay final at once: at 1 Hz under
/// 0.2 m/s of noise, a car reversing into its space at 0.7–1 m/s breaks its run, and
/// giving the stand back there held the heading from before the manoeuvre. Forward
/// along the axis a glitch changes the heading little.
pub const RELEASE_EPOCHS_OFF_AXIS: u16 = 3;

/// Seconds of standing from which a car is parked or waiting rather than creeping
/// through a manoeuvre, so that a short run off its axis or backwards is more likely
/// a glitch burst than motion: its release becomes final after
/// [`RELEASE_EPOCHS_LONG_STAND`] epochs instead of [`RELEASE_EPOCHS_OFF_AXIS`].
pub const LONG_STAND_S: f32 = 10.0;

/// Epochs of plain motion off a sure held heading's axis, or backwards along it faster
/// than a car backs out, that make the release of a car that stood [`LONG_STAND_S`]
/// final. Under poor sky at 1 and 2 Hz, glitch bursts of three and four epochs released
/// parked cars for good: one turned the held heading, or took the car for a platform
/// that had turned in place, whose answers were then the noise's courses for the rest
/// of the stop. With five
/// after every stand, simulated 1 and 2 Hz cars of seeds no table uses lost 1.5–5% of
/// their MAE (four gave about half of that, six and eight no more), but a creeping car
/// got back the heading it held before a slow turn (the shared real drive with 0.2 m/s
/// of added noise, `models/reports/noisy-real.md`, 4–9% worse on four of six logs,
/// their stands 4–5 s). After a long stand alone, those cars lost 1–4%, and the noisy
/// real drive did not move.
pub const RELEASE_EPOCHS_LONG_STAND: u16 = 5;

/// Largest course change (°) between successive epochs of plain motion: a steadier
/// course than this is motion, not noise or a glitch burst's scatter.
pub const RELEASE_COURSE_DEG: f32 = 30.0;

/// Hardest braking (m/s²) a car's velocity can show, about 1 g: a moving car whose
/// velocity drops by more than this per second (plus 3σ of the noise) did not stop,
/// its receiver glitched. NMEA receivers print 0.0 m/s on a bad fix; taken as a stop,
/// one such epoch at 4–5 m/s started a stand that the gate then kept for over a second
/// of driving (a standing car leaves rest only as fast as `a_max` allows).
pub const BRAKE_MAX: f32 = 10.0;

/// Seconds a car stands, at least, to change between forward and reverse gear: with
/// [`REVERSAL_MIN_SPEED`], what the glitch gate allows a moving car that turns its
/// velocity around.
pub const GEAR_CHANGE_S: f32 = 1.0;

/// Speed (m/s, and 3σ of the noise) over which a moving car's velocity pointing
/// against the one it drove at (more than a quarter turn off, the car's last two used
/// velocities agreeing) is a glitch, unless there was time to brake ([`BRAKE_MAX`]),
/// change gear ([`GEAR_CHANGE_S`]) and speed up again (`a_max`), whether the gate
/// bounds the velocity's change or not. Within `a_max` alone a reversed spike of 3 m/s a second
/// after 1.2 m/s is reachable, and one of 2 m/s after 3.5 m/s is under `gate_speed`,
/// which the gate does not look at: at 1 Hz the filter took them (the network's gain
/// near 1), its answer turned by a half turn, and a stop that followed held that
/// (simulated NMEA and consumer cars at 1 Hz lost to atan2 at 2–5 m/s,
/// `models/reports/unmet.md`). A car that reverses stands in between, and a standing
/// epoch is under this speed.
pub const REVERSAL_MIN_SPEED: f32 = 0.5;

/// How far (m/s, plus 2σ of the noise) a moving car's speed may differ from its last
/// used velocity's for the glitch gate to take the epoch as a turn at steady speed,
/// bounded by `a_max` over all the time since that velocity rather than over one
/// epoch (the glitch gate). A junction turn changes the velocity's direction, not its
/// size: at 1 Hz a 90° turn at 6–7 m/s (about 4 m/s² sideways) is more than `a_max`
/// per epoch, and each later epoch of the turn, compared with the velocity before it
/// over one epoch's allowance, was rejected too until `max_skips` ran out, three
/// seconds of a frozen heading. The receiver glitches of the shared real drive at
/// 8–11 m/s change the speed by 2–4 m/s and stay rejected.
pub const TURN_SPEED_CHANGE: f32 = 0.5;

/// Whether velocities `a` and `b` point within [`RELEASE_COURSE_DEG`] of each other.
#[inline]
fn same_course(a: [f32; 2], b: [f32; 2]) -> bool {
    within_deg(a, b, RELEASE_COURSE_DEG)
}

/// Whether velocities `a` and `b` point within `deg` (under 90) degrees of each other,
/// from their dot and cross products (no arctangent on the streaming path).
#[inline]
pub(super) fn within_deg(a: [f32; 2], b: [f32; 2], deg: f32) -> bool {
    let (dot, cross) = (a[0] * b[0] + a[1] * b[1], a[0] * b[1] - a[1] * b[0]);
    dot > 0.0 && cross.abs() <= dot * deg.to_radians().tan()
}

/// What an epoch did to the run of plain motion ([`StepState::motion`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum RunStep {
    /// It continued the run.
    Extended,
    /// It was skipped (a glitch inside the run, or the start of another).
    Skipped,
    /// It ended the run: no run, or another one.
    New,
}

impl MotionRun {
    /// A run that starts with this epoch.
    fn start(v: [f32; 2], on_axis: bool) -> MotionRun {
        MotionRun {
            n: 1,
            v,
            on_axis,
            ..Self::NONE
        }
    }

    /// Whether velocity `v` continues the run: the course within
    /// [`RELEASE_COURSE_DEG`] and the velocity within what a vehicle can change since
    /// the run's last epoch (glitch bursts come back to back with other sizes).
    fn steady(&self, mp: &ModeParams, v: [f32; 2]) -> bool {
        let [pn, pe] = self.v;
        self.n > 0
            && self.since <= 2.0
            && same_course(self.v, v)
            && (v[0] - pn).hypot(v[1] - pe) <= mp.a_max * self.since + 0.3
    }

    /// The run continued by an epoch `dt` after the one before it.
    fn extend(self, v: [f32; 2], dt: f32, on_axis: bool) -> MotionRun {
        MotionRun {
            t: self.t + dt,
            n: self.n.saturating_add(1),
            v,
            since: 0.0,
            on_axis: self.on_axis && on_axis,
        }
    }
}

impl StepState {
    /// Whether the release rule ends a stand on this epoch: about a second of plain
    /// motion on a steady course ([`RELEASE_S`], and at least [`RELEASE_EPOCHS`]), or
    /// [`RELEASE_S_MIN`] of it over [`RELEASE_BURST_EPOCHS`] or more. A car released
    /// off its held heading's axis by fewer than [`RELEASE_EPOCHS_OFF_AXIS`] keeps what
    /// it held ([`StepState::before_release`]).
    #[inline]
    pub fn released(&self) -> bool {
        let MotionRun { t, n, .. } = self.motion;
        n >= RELEASE_EPOCHS && (t >= RELEASE_S || (n >= RELEASE_BURST_EPOCHS && t >= RELEASE_S_MIN))
    }
}

/// A car's stand released by a run shorter than [`RELEASE_EPOCHS_OFF_AXIS`] off the
/// axis of its held heading, or backwards along it ([`RELEASE_EPOCHS_LONG_STAND`] after
/// a long stand), keeps what it held ([`StepState::before_release`]): if that run ends
/// or gives way to another before it is long enough, it was a glitch burst and the
/// stand gets its heading back; once it is long enough, it was a departure.
pub(super) fn keep_or_restore_held(mp: &ModeParams, st: &mut StepState, step: RunStep) {
    if let Some(h) = st.before_release {
        let n = st.motion.n;
        if step == RunStep::Extended && n >= h.epochs {
            st.before_release = None;
        } else if step == RunStep::New {
            st.psi = h.psi;
            st.log_sigma = h.log_sigma;
            st.reverse = h.reverse;
            // Only a car's stand is kept; an off-axis release may have unmade it one.
            st.vehicle.car = true;
            st.before_release = None;
        }
    }
    if st.before_release.is_none()
        && st.car_stands()
        && st.has_prior
        && st.released()
        && (!st.motion.on_axis || backward(mp, st))
    {
        let epochs = off_axis_epochs(st);
        if st.motion.n < epochs {
            st.before_release = Some(HeldHeading {
                psi: st.psi,
                log_sigma: st.log_sigma,
                reverse: st.reverse,
                epochs,
            });
        }
    }
}

/// The epochs of plain motion that make a release from a car's stand final, off its
/// axis or backwards ([`RELEASE_EPOCHS_OFF_AXIS`], after a long stand
/// [`RELEASE_EPOCHS_LONG_STAND`]).
fn off_axis_epochs(st: &StepState) -> u16 {
    if st.t_still >= LONG_STAND_S {
        RELEASE_EPOCHS_LONG_STAND
    } else {
        RELEASE_EPOCHS_OFF_AXIS
    }
}

/// Whether the run of plain motion points against the held heading (the body's) faster
/// than a car backs out (`escape_speed`, the speed that ends a reversal).
fn backward(mp: &ModeParams, st: &StepState) -> bool {
    let [vn, ve] = st.motion.v;
    vn * st.psi.cos() + ve * st.psi.sin() < 0.0 && vn.hypot(ve) > mp.escape_speed
}

/// Whether the glitch gate rejects this velocity: a change from the last used velocity
/// that a car cannot make in the time since.
///
/// At speed that is `a_max·dt` (at most `max_skips` epochs in a row), and so it is for
/// a car whose last used velocity was slow (under `gate_speed`), whatever its speed
/// now: a spike out of a slow creep or a stop's lagging tail turned held headings that
/// the car then had to leave along. Such a car coming down to rest (under
/// [`RELEASE_SPEED`]) is bounded by [`BRAKE_MAX`] instead: it brakes. (A drop that
/// stays above that speed may be a glitch: taken, on a simulated RTKLIB car, one made
/// the next real velocity, back at the car's speed, look unreachable, and the gate then
/// took the glitches that followed.) Bounded by `a_max`, a glitch pair taken for a
/// departure from a stand (confirmed, along the held axis) made the drop back to rest
/// look unreachable, so the gate skipped the car's real rest until `max_skips` ran out
/// and then took whatever came next, often the next spike, which turned the held
/// heading (simulated NMEA and u-blox cars at 10 Hz, models/reports/unmet.md). At
/// speed, an epoch whose speed is within [`TURN_SPEED_CHANGE`] of the last used
/// velocity's (a turn) may have changed direction at `a_max` over all the time since
/// that velocity, not just this epoch's interval, so the second epoch of a sharp turn
/// is taken. A car coming down from speed below `gate_speed` is gated only by
/// [`BRAKE_MAX`] (braking reaches 1 g, beyond `a_max`), also at most `max_skips` epochs
/// in a row, and only when its last used epoch was driving ([`StepState::driving`]): a
/// drop faster than that is a glitch, not a stop (a stop it started would hold the
/// heading while the car drives on); but right after a glitch burst ended a stand, the
/// last used velocity is the burst's, and the drop back to rest is real. So is a moving
/// car's velocity that turns around sooner than a car stops, changes gear and speeds up
/// again, at any speed ([`REVERSAL_MIN_SPEED`]). A standing car
/// is stricter, because a held heading is only as good as the epochs it ignores: a
/// burst of glitches at a stop used to turn it once `max_skips` ran out, and a single
/// spike of 1–3 m/s at 1 Hz is within `a_max·dt`. So a standing car leaves rest only on
/// a velocity reachable from rest in the time since the last used one (no count limit:
/// a real departure always is), only when the next epoch confirms it (a spike does not
/// repeat; a departure does, one epoch later), and for `axis_secs` only along the axis
/// of a sure held heading (a car cannot leave a stand sideways; most glitches point
/// elsewhere).
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
    let standing = st.car_stands();
    let prev = st.prev_v;
    let prev_speed = prev[0].hypot(prev[1]);
    // A car near rest cannot jump either: from a slow velocity it gains at most
    // `a_max` per second, whatever its speed after. Coming down from speed, a car
    // brakes harder than `a_max`: below `gate_speed` only `BRAKE_MAX` bounds it.
    let from_slow = st.vehicle.car && prev_speed <= mp.gate_speed;
    let gated = speed > mp.gate_speed || standing || from_slow;
    // A car cannot change its velocity by more than `a_max` per second (plus the noise),
    // nor brake harder than `BRAKE_MAX`: whether the change outruns `accel` over `secs`.
    let change = (vn - prev[0]).hypot(ve - prev[1]);
    let unreachable = |accel: f32, secs: f32| change > accel * secs + 3.0 * sig;
    let braked_too_hard = st.vehicle.car
        && !standing
        && st.driving
        && speed < prev_speed
        && unreachable(BRAKE_MAX, dt);
    let reject = if !(prev[0].is_finite() && dt > 0.0) {
        false
    } else if braked_too_hard
        || (!standing && turned_around(mp, st, [vn, ve], [speed, prev_speed], sig, dt))
    {
        st.skips < mp.max_skips
    } else if !gated {
        false
    } else if standing && st.released() {
        // A second of plain motion on a steady course ends any stand: a car that did
        // not leave along its axis turned in place (or its held heading was wrong).
        if off_axis_of_held(mp, st, vn, ve, p, r) && demotable(st) {
            demote(st);
        }
        false
    } else if standing {
        let elapsed = st.t_used + dt;
        let pending = st.pending_v;
        let confirmed = pending[0].is_finite()
            && (vn - pending[0]).hypot(ve - pending[1]) <= mp.a_max * dt + 3.0 * sig;
        st.pending_v = if moving { [vn, ve] } else { [f32::NAN; 2] };
        let sideways = off_axis_of_held(mp, st, vn, ve, p, r);
        let reject = unreachable(mp.a_max, elapsed)
            || (moving && (!confirmed || (sideways && elapsed <= mp.axis_secs)));
        if !reject && moving && sideways && demotable(st) {
            // It kept leaving sideways: it turned in place, so it is no car (a car
            // shows itself again by driving fast).
            demote(st);
        }
        reject
    } else {
        let steady = (speed - prev_speed).abs() <= TURN_SPEED_CHANGE + 2.0 * sig;
        let secs = if steady && !from_slow {
            st.t_used + dt
        } else {
            dt
        };
        // A slow car coming down to rest brakes: only `BRAKE_MAX` bounds that.
        let braking = from_slow && speed < prev_speed && speed < RELEASE_SPEED;
        let limit = if braking { BRAKE_MAX } else { mp.a_max };
        unreachable(limit, secs)
            && st.skips < mp.max_skips
            && !outlier_before(mp, st, [vn, ve], sig, dt)
    };
    count_skip(st, reject, prev, dt);
    reject
}

/// Whether a moving car's velocity `v` (`dt` s after the last epoch, noise σ `sig`)
/// points against the one it drove at, too soon after it for a stop and a change of
/// gear ([`REVERSAL_MIN_SPEED`]). `speeds` are `v`'s and the last used velocity's, as
/// the gate measured them. The last used velocity must agree with the one used before
/// it: measured from a glitch the gate took, the drive that follows points anywhere.
fn turned_around(
    mp: &ModeParams,
    st: &StepState,
    v: [f32; 2],
    speeds: [f32; 2],
    sig: f32,
    dt: f32,
) -> bool {
    let (prev, before) = (st.prev_v, st.prev_v0);
    let dot = |a: [f32; 2], b: [f32; 2]| a[0] * b[0] + a[1] * b[1];
    let [speed, prev_speed] = speeds;
    let bar = (3.0 * sig).max(REVERSAL_MIN_SPEED);
    st.vehicle.car
        && dot(prev, v) < 0.0
        && dot(prev, before) > 0.0
        && prev_speed > bar
        && speed > bar
        && st.t_used + dt < prev_speed / BRAKE_MAX + GEAR_CHANGE_S + speed / mp.a_max
}

/// The gate's books after an epoch `dt` s after the last: a rejected one adds to the
/// skips and the time since the last used velocity; a used one clears them, and the
/// velocity used before it (`prev`) becomes the gate's second reference.
fn count_skip(st: &mut StepState, reject: bool, prev: [f32; 2], dt: f32) {
    if reject {
        st.skips = st.skips.saturating_add(1);
        st.t_used += dt;
    } else {
        (st.prev_v0, st.gap0) = (prev, st.t_used + dt);
        st.skips = 0;
        st.t_used = 0.0;
        st.pending_v = [f32::NAN; 2];
    }
}

/// Whether the last velocity the gate let through (`prev_v`) was itself the glitch,
/// judged by this one (`v`, `dt` seconds after the last epoch, noise σ `sig`), which
/// the gate would reject. A glitch that reads slow (under `gate_speed`, where a moving
/// vehicle's velocity is not gated) or just inside the reach passes the gate; measured
/// from it, the motion that follows looks unreachable, and at 1 Hz the answer kept the
/// glitch's course for up to `max_skips` seconds of plain driving (the 1 Hz car rows of
/// models/reports/unmet.md at 2 m/s and faster).
///
/// So when the velocity used before `prev_v` (`prev_v0`), `prev_v` and `v` are three
/// epochs in a row, `prev_v0` and `v` both over `gate_speed`, and `v` is within reach
/// of `prev_v0` (`a_max` over all the time since) and nearer to it than `prev_v` came,
/// `prev_v` was the glitch. In a row: under poor sky a chain of glitches with skipped
/// epochs between them turned a backing car's answer forward. Over `gate_speed`: a
/// reading near rest is near any slow velocity, and a glitch burst at a stop was
/// answered by its next glitch.
fn outlier_before(mp: &ModeParams, st: &StepState, v: [f32; 2], sig: f32, dt: f32) -> bool {
    let (v0, v1) = (st.prev_v0, st.prev_v);
    let fast = |v: [f32; 2]| v[0].hypot(v[1]) > mp.gate_speed;
    // Three epochs in a row: nothing skipped between them.
    let in_a_row = st.t_used == 0.0 && st.gap0 <= 1.5 * dt;
    if !(in_a_row && v0[0].is_finite() && v1[0].is_finite() && fast(v) && fast(v0)) {
        return false;
    }
    let back = (v[0] - v0[0]).hypot(v[1] - v0[1]);
    let glitch = (v1[0] - v0[0]).hypot(v1[1] - v0[1]);
    // In a row, all the time since `prev_v0` is its gap to `prev_v` and this epoch's.
    back < glitch && back <= mp.a_max * (st.gap0 + dt) + 3.0 * sig
}

/// Whether a car that leaves its stand sideways may be demoted: an `auto` vehicle that
/// has not driven faster than any robot ([`Vehicle::sure_car`]).
///
/// [`Vehicle::sure_car`]: crate::modes::Vehicle::sure_car
fn demotable(st: &StepState) -> bool {
    st.vehicle.platform == Platform::Auto && !st.vehicle.sure_car
}

/// A car that left its stand sideways turned in place: it is no car (it shows itself
/// again by driving fast), and a platform has no reverse mode, so a reversing car's
/// heading becomes the direction it moves in (its course), not the one it held.
fn demote(st: &mut StepState) {
    st.vehicle.car = false;
    (st.t_fast, st.n_fast) = (0.0, 0);
    if st.reverse {
        st.reverse = false;
        st.t_mode = 0.0;
        st.psi = wrap_rad(st.psi + std::f32::consts::PI);
    }
}

/// Whether a velocity leaves a sure held heading's axis (further than `axis_deg` plus
/// 2σ of the course): a car cannot leave a stand sideways.
fn off_axis_of_held(mp: &ModeParams, st: &StepState, vn: f32, ve: f32, p: f32, r: f32) -> bool {
    if !mp.sure(p) {
        return false;
    }
    off_axis(ve.atan2(vn), st.psi) > mp.axis_deg.to_radians() + 2.0 * r
}

/// How far (radians, 0 to π/2) a course points off the axis of `heading`, ahead or
/// behind alike: a vehicle leaving along its axis may drive forward or back up.
#[inline]
pub(super) fn off_axis(course: f32, heading: f32) -> f32 {
    let off = wrap_rad(course - heading).abs();
    off.min(std::f32::consts::PI - off)
}

/// Whether `st` is a standing car whose held heading is unsure ([`UNSURE_HELD_DEG`]).
fn unsure_stand(st: &StepState) -> bool {
    let held =
        (st.log_sigma + st.held_y2).clamp(crate::head::LOG_SIGMA_MIN, crate::head::LOG_SIGMA_MAX);
    st.has_prior && st.car_stands() && held.exp() >= UNSURE_HELD_DEG.to_radians()
}

/// The release rule's clock ([`StepState::motion`]): runs while epochs are plain
/// motion (at least [`RELEASE_SPEED`] and `3·sAcc`; to continue a run that has not yet
/// released, [`RELEASE_CONT_ACC_K`] and [`RELEASE_CONT_NOISE_K`]) on a steady course.
///
/// An unsteady epoch inside a run (a glitch inside a departure) neither counts nor ends
/// it, up to `max_skips` in a row; the skipped epochs form a run of their own
/// ([`StepState::motion_alt`]), which takes over once it is the longer or the skips
/// run out: a glitch burst that started the run does not delay the real departure
/// right after it. The run it displaces becomes the alternative in turn, so a burst
/// one epoch longer than the skips inside a departure (the longest the simulator
/// makes) does not restart the departure's clock when it ends; the burst's own time
/// still does not count. A longer burst, once it continues its own run, drops the
/// departure's: with it kept, no `Held` run of models/reports/unmet.md got shorter. The
/// longest `Held` column there shows what this did for 10 Hz consumer cars.
#[inline]
pub(super) fn track_motion(
    mp: &ModeParams,
    st: &mut StepState,
    vn: f32,
    ve: f32,
    acc: f32,
    dt: f32,
) -> RunStep {
    let speed = vn.hypot(ve);
    // The receiver's noise at rest as measured, capped: slow driving inflates the
    // estimate (it reads slow speeds as noise), and that must not hide real motion.
    let cap = if dt >= RELEASE_LOW_RATE_DT {
        RELEASE_NOISE_CAP_LOW_RATE
    } else {
        RELEASE_NOISE_CAP
    };
    let noise = mp.rest_noise(&st.vehicle).min(cap);
    let acc = if acc.is_finite() { acc } else { 0.0 };
    let v = [vn, ve];
    st.motion.since += dt;
    st.motion_alt.since += dt;
    let course_sigma = noise.max(acc).max(mp.sigma_floor) / speed.max(f32::MIN_POSITIVE);
    let (noise, acc) = bar_terms(st, noise, acc);
    let floor = RELEASE_SPEED.max(3.0 * acc);
    let p = (2.0 * st.log_sigma).exp();
    let on_axis = !(st.has_prior && off_axis_of_held(mp, st, vn, ve, p, course_sigma));
    // Along a sure held heading's axis the bar is a lower multiple of the noise: a
    // receiver at rest rarely points its noise along the body for a second, and a
    // departure along it changes the answer little if it was noise after all. Out of
    // an unsure stand it changes little either way.
    let along = on_axis && st.has_prior && mp.sure(p);
    let k = if along || unsure_stand(st) {
        RELEASE_NOISE_K_AXIS
    } else {
        4.0
    };
    // A run on its way to releasing a stand is continued by a lower bar (a
    // hysteresis): one dip under the start bar does not restart the clock.
    let bar = if st.motion.n > 0 && !st.released() && st.motion.steady(mp, v) {
        RELEASE_SPEED
            .max(RELEASE_CONT_ACC_K * acc)
            .max(RELEASE_CONT_NOISE_K.min(k) * noise)
    } else {
        floor.max(k * noise)
    };
    if speed < bar {
        (st.motion, st.motion_alt, st.motion_skips) = (MotionRun::NONE, MotionRun::NONE, 0);
        return RunStep::New;
    }
    if st.motion.steady(mp, v) {
        // Skipped epochs' time does not count: two glitch bursts alike, apart, are not
        // a departure.
        st.motion = st.motion.extend(v, dt, on_axis);
        (st.motion_alt, st.motion_skips) = (MotionRun::NONE, 0);
        return RunStep::Extended;
    }
    let alt = if st.motion_alt.steady(mp, v) {
        st.motion_alt.extend(v, dt, on_axis)
    } else {
        MotionRun::start(v, on_axis)
    };
    if st.motion.n > 0 && st.motion_skips < mp.max_skips && alt.n <= st.motion.n {
        // A glitch inside a departure: the run's time goes on, measured from its last
        // steady epoch.
        st.motion_skips += 1;
        st.motion_alt = alt;
        RunStep::Skipped
    } else {
        // The run it displaces waits as the alternative: a glitch burst one epoch longer
        // than the skips inside a departure gives way to the departure when it ends.
        let displaced = st.motion;
        (st.motion, st.motion_alt, st.motion_skips) = (alt, displaced, 0);
        RunStep::New
    }
}

/// The receiver's noise at rest and sAcc as the release rule's bars take them. A car's
/// receiver that holds static reads exactly zero at rest, so neither its sAcc nor the
/// noise guess it keeps says what it reads standing: its bar is [`RELEASE_SPEED`] (the
/// release clock and a steady course sort out its blips). With `3·sAcc`, a u-blox with
/// its static hold on kept a car backing out at 1 m/s `Held` for seconds (the
/// u-blox-hold sections of models/reports/unmet.md). A platform's stand holds nothing,
/// and one whose receiver's sAcc nears its speed, released, answered a heading its
/// filter could no longer feed as `Held` for seconds.
#[inline]
fn bar_terms(st: &StepState, noise: f32, acc: f32) -> (f32, f32) {
    if st.vehicle.holds_static() && st.vehicle.car {
        (0.0, 0.0)
    } else {
        (noise, acc)
    }
}
