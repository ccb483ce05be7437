//! A platform's creep at a stand: when a `Stationary` answer gives the epoch's course
//! rather than the heading the history holds.

use super::params::ModeParams;
use super::release::{off_axis, within_deg, RELEASE_COURSE_DEG};
use super::vehicle::{Platform, Vehicle, ACC_RATIO_MIN_EPOCHS, TURN_IN_PLACE_DEG};

/// Times its receiver's noise (the sAcc it has earned, else the σ measured at rest) a
/// robot's speed (declared, or `auto` seen to turn in place) must exceed, this epoch
/// and the one before on a steady course, for a `Stationary` answer to point along its
/// course ([`stationary_course`]). At true rest the course is noise and the held heading
/// the better guess (answering the course at any speed made simulated RTKLIB robots
/// worse than holding). The steadiness does most of the sorting: a robot
/// creeping at 0.1–0.4 m/s (a slow arc, a departure a lagging receiver reports late)
/// keeps its course from one epoch to the next, noise does not. Once the noise itself
/// rather than twice it, every robot section of `reports/unmet.md` and of 100 drives of
/// other seeds got better or stayed (by up to 0.5%), the robots' 0.05–0.5 m/s rows
/// most; under it (half the noise, or none) RTKLIB and NMEA robots lost. What the
/// receiver's noise is when it comes from the noise shown at rest (which a robot's
/// creeps lift): [`ROBOT_REST_NOISE_SHARE`].
pub const ROBOT_COURSE_NOISE_K: f32 = 1.0;

/// The share of the noise a platform's receiver has shown at rest (the running low
/// quantile of its slow speeds, [`Vehicle::noise`]) that [`stationary_course`]
/// takes for the noise of a receiver that reports an sAcc, once
/// [`ACC_RATIO_MIN_EPOCHS`] slow epochs have shown it (at most the sAcc); and the share
/// of the sAcc of a receiver that holds static (which shows no noise at rest to bound
/// it). A robot's slow epochs are filled by its creeps and by the spin of an antenna
/// off its axis, which lift that quantile over the noise itself: on the robot sections
/// of `models/reports/unmet.md` it read 1.5–3 times the noise at the truth's rest
/// epochs, so over a pessimistic sAcc steady creeps at two or three times the noise
/// were answered with the heading from before a spin. At 0.6, on simulated drives of
/// two sets of seeds, the u-blox sAcc × 3 robots answered 1.1–2.9% better (the
/// static-hold ones, declared robots, 1.6–3.7%), RTKLIB and u-blox robots moved by
/// under 0.5% either way, and no car section moved. Before those slow epochs (a cold
/// start) the bar is the noise at rest whole: at 5 Hz a fifth of pairs of a standing
/// honest receiver's noise velocities point within a creep's turn of each other, and
/// over 0.6 of the noise they were answered as creeps. Nor does a receiver without
/// sAcc get the share: NMEA robots moved by up to 0.4% either way with it, at no gain;
/// the held-out platforms of `models/reports/ghnet-temporal.md` moved by 0.1%.
pub const ROBOT_REST_NOISE_SHARE: f32 = 0.6;

/// How far (°/s) a creeping platform's course may turn from one epoch to the next
/// beyond [`RELEASE_COURSE_DEG`], for a `Stationary` answer to give it
/// ([`stationary_course`]): robots turn at 20–60°/s, so at 1 Hz two courses of a
/// real creep in an arc lie further apart than a 5 or 10 Hz receiver's. With the
/// bare 30°, 1 Hz robots held a stale heading through such creeps; widened by 45°/s
/// (75° at 1 Hz, 39° at 5 Hz), every 1 Hz robot section of models/reports/unmet.md
/// and of 100 drives of other seeds got better or stayed (by up to 0.5% with
/// `--platform robot`), the 5 and 10 Hz sections moved by at most 0.03% either way,
/// and no car section moved (60°/s gained no more). Noise at rest seldom passes: both
/// speeds must be over the receiver's noise.
pub const ROBOT_COURSE_TURN_DEG_S: f32 = 45.0;

/// Speed (m/s) both epochs of a steady creep must exceed for an `auto` vehicle known to
/// be neither a car nor a robot to answer it with its course, off the axis of the
/// heading it holds ([`stationary_course`]): the noise bar alone, before the noise at
/// rest is measured, let pairs of a quiet receiver's noise pass. Without it, simulated
/// 1 Hz RTKLIB robots (models/reports/unmet.md) answered 0.1% worse; with it no car
/// section moved by more than 0.01°, and on the shared drive's copies with 0.05 m/s of
/// added noise and no sAcc (models/reports/noisy-real.md) one standing epoch each,
/// just over it, is answered with its noise's course (about 0.05° of their MAE).
pub const AUTO_CREEP_MIN_SPEED: f32 = 0.1;

/// Whether a `Stationary` answer (no heading known) of `vehicle` gives this epoch's
/// course (velocity `v`, m/s north and east), with σ [`SENSE_SIGMA_DEG`] (a creep may
/// be a back-up), rather than the heading the history holds with the uniform σ.
///
/// For a declared [`Platform::Robot`], or an `auto` vehicle not known to be a car that
/// has shown it turns in place ([`Vehicle::turns`]): such a platform turns in place at
/// its stops, so what it holds is stale, while a car's held heading is right however it
/// creeps or reverses. (Every `auto` vehicle not known to be a car, from its cold
/// start, made the car sections of models/reports/unmet.md worse: half the simulated
/// cars back out of their space first, answered a half turn off.)
///
/// And for an `auto` vehicle known to be neither, once it has moved (`held`, the
/// heading its history holds, is NaN before): a steady creep faster than
/// [`AUTO_CREEP_MIN_SPEED`] that points more than [`TURN_IN_PLACE_DEG`] off the axis of
/// `held` (neither along it nor against it) shows a turn since, which no car makes
/// standing; a car's creep or back-up runs along its axis. Seeing a robot turn in place
/// takes a departure and seconds of steady motion at the release rule's bars, which a
/// slow robot on a receiver reporting a pessimistic sAcc seldom clears: until then its
/// creeps off a spin kept the heading from before it (on the u-blox sAcc × 3 robots of
/// models/reports/unmet.md, nearly all of what `auto` lost to a declared robot).
///
/// Only when `v` and the velocity the epoch before used (`prev_v`, `dt` seconds
/// earlier) are both over [`ROBOT_COURSE_NOISE_K`] times the receiver's noise (below)
/// and point within [`RELEASE_COURSE_DEG`] plus [`ROBOT_COURSE_TURN_DEG_S`] over `dt`
/// of each other (at most 85°): a creeping robot's velocity keeps its direction, or
/// turns it as fast as a robot turns, a noisy receiver at rest before its noise is
/// measured does not for long, and neither, at 5 and 10 Hz, does the velocity a spin
/// in place gives an antenna off its axis. Without that steadiness, a cold start on a
/// noisy NMEA receiver and a robot spinning at 1 Hz were answered sideways. At 1 Hz a
/// spin slower than 75°/s now passes when its antenna's velocity is over the noise;
/// the 1 Hz robot sections measured for [`ROBOT_COURSE_TURN_DEG_S`] (robots spinning
/// at 20–60°/s, antennas up to 0.25 m off the axis) count that cost in.
///
/// The receiver's noise: without an sAcc (`acc` NaN), the noise measured at rest; with
/// one, the sAcc the receiver has earned ([`ModeParams::trusted_acc`]), and once
/// enough slow epochs have shown the noise at rest, at most [`ROBOT_REST_NOISE_SHARE`]
/// of it; for a receiver that holds static, that share of its sAcc: a u-blox
/// reporting three times its sAcc kept robots creeping off a spin at 0.1–0.5 m/s on
/// their stale heading (the sAcc × 3 robot sections of models/reports/unmet.md), and
/// an `auto` robot, once seen to turn in place, as much as a declared one (with the
/// reported sAcc such sections answered 0.2–0.7% worse).
///
/// [`SENSE_SIGMA_DEG`]: crate::modes::SENSE_SIGMA_DEG
#[inline]
#[allow(clippy::too_many_arguments)] // one epoch's numbers
pub fn stationary_course(
    mp: &ModeParams,
    vehicle: &Vehicle,
    v: [f32; 2],
    prev_v: [f32; 2],
    acc: f32,
    dt: f32,
    held: f32,
) -> bool {
    let turns = vehicle.turns_in_place();
    if !turns && (vehicle.platform != Platform::Auto || vehicle.car || !held.is_finite()) {
        // A car, or an `auto` vehicle that has not moved: its stand holds.
        return false;
    }
    let bar = creep_noise(mp, vehicle, acc) * ROBOT_COURSE_NOISE_K;
    if turns {
        return steady_creep(v, prev_v, bar, dt);
    }
    steady_creep(v, prev_v, bar.max(AUTO_CREEP_MIN_SPEED), dt)
        && off_axis(v[1].atan2(v[0]), held) > TURN_IN_PLACE_DEG.to_radians()
}

/// The receiver noise (m/s) a creep must exceed ([`stationary_course`]).
#[inline]
fn creep_noise(mp: &ModeParams, vehicle: &Vehicle, acc: f32) -> f32 {
    if !acc.is_finite() {
        mp.rest_noise(vehicle)
    } else if vehicle.holds_static() {
        ROBOT_REST_NOISE_SHARE * acc
    } else {
        // The sAcc earned at rest (as `ModeParams::trusted_acc`), by the share once shown.
        let share = if vehicle.acc_ratio_n >= ACC_RATIO_MIN_EPOCHS {
            ROBOT_REST_NOISE_SHARE
        } else {
            1.0
        };
        acc.min((share * mp.rest_noise(vehicle)).max(mp.sigma_floor))
    }
}

/// Whether velocity `v` (m/s north and east) and the one `dt` s before it (`prev_v`)
/// are both over `bar` (m/s) and point within [`RELEASE_COURSE_DEG`] plus
/// [`ROBOT_COURSE_TURN_DEG_S`] over `dt` of each other (at most 85°): a creep keeps its
/// direction, or turns it as fast as a robot turns, while noise at rest seldom does.
#[inline]
pub(super) fn steady_creep(v: [f32; 2], prev_v: [f32; 2], bar: f32, dt: f32) -> bool {
    let turn = (RELEASE_COURSE_DEG + ROBOT_COURSE_TURN_DEG_S * dt.max(0.0)).min(85.0);
    v[0].hypot(v[1]) > bar && prev_v[0].hypot(prev_v[1]) > bar && within_deg(prev_v, v, turn)
}
