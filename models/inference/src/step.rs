//! The per-epoch math of the stateful engines, free of any history: the temporal
//! network's inputs, the Kalman filter's step, the state after an epoch (what a stop
//! holds included), the reported σ. [`crate::stream`] applies them to a source's history one epoch at a time; the
//! lab's training runs them over whole tracks.

use crate::head::{accuracy_sigma_base, KalmanBase, MAX_STD_DEG};
use crate::modes::{Step, StepState};
use crate::weights::ModelKind;

/// Per-epoch inputs of the temporal network (see [`inputs`]).
pub const INPUTS: usize = crate::weights::TEMPORAL_INPUTS;

/// Speed (m/s) above which an epoch counts as moving for the Kalman filter's clock of
/// time stopped, when the receiver's accuracy does not demand more.
pub const MOVING_SPEED: f32 = 0.5;

/// Largest σ in radians (a uniform error on the circle), as a log: the "no heading" σ.
pub(crate) fn log_sigma_cap() -> f32 {
    MAX_STD_DEG.to_radians().ln()
}

/// Whether an epoch counts as moving: over [`MOVING_SPEED`] and over 4 σ of the
/// receiver's reported noise.
#[inline]
pub fn moving(speed: f32, speed_acc: f32) -> bool {
    speed >= MOVING_SPEED && !(speed_acc.is_finite() && speed < 4.0 * speed_acc)
}

/// The Kalman step of an epoch for a model of `kind` (temporal or kf) from the
/// history's state: prior variance (previous σ² plus `q²·dt`; a uniform error without a
/// previous heading) and measurement variance `(σ_v/ŝ)²`.
pub fn kalman_base(
    kind: &ModelKind,
    state: &StepState,
    v_north: f32,
    v_east: f32,
    dt: f32,
) -> KalmanBase {
    let (q, sv) = match *kind {
        ModelKind::Temporal {
            q_deg_per_sqrt_s,
            sigma_v_mps,
            ..
        }
        | ModelKind::Kf {
            q_deg_per_sqrt_s,
            sigma_v_mps,
            ..
        } => (q_deg_per_sqrt_s.to_radians(), sigma_v_mps),
        ModelKind::Epoch => (0.0, f32::NAN),
    };
    let cap = MAX_STD_DEG.to_radians();
    let r = accuracy_sigma_base(v_north, v_east, sv).unwrap_or(cap);
    let p = if state.has_prior {
        crate::modes::random_walk_variance(state.log_sigma, q, dt)
    } else {
        cap * cap
    };
    KalmanBase { p, r2: r * r }
}

/// The temporal network's per-epoch inputs, all O(1), from the state before the epoch
/// (`prev`), the state after the mode filter's rules (`st`) and the prepared `step`:
/// the course relative to the step's prior `(cos, sin)`; log and linear speed; the log
/// sAcc and whether sAcc is known; the logs of the prior σ, the measurement σ, dt, the
/// time stopped and the time in the current mode; the Kalman gain; the rule's mode and
/// the previous mode; whether the vehicle is a car, the epoch moves, the glitch gate
/// fired, the step only holds (before the first motion); the log receiver-noise
/// estimate; and the log acceleration from the last used velocity. Relative angles make
/// the network rotation-invariant.
pub fn inputs(
    prev: &StepState,
    st: &StepState,
    step: &Step,
    v_north: f32,
    v_east: f32,
    speed_acc: f32,
    dt: f32,
) -> [f32; INPUTS] {
    let speed = step.speed;
    let (s, c) = (step.course - step.prior).sin_cos();
    let cap = log_sigma_cap();
    // Clamped both ways: a receiver may claim any finite accuracy (f32::MAX seeds the
    // noise estimate), and an infinite input would make every output NaN.
    let log = |v: f32| 0.5 * v.clamp(1e-12, 1e12).ln();
    let flag = |b: bool| if b { 1.0 } else { 0.0 };
    let accel = if prev.prev_v[0].is_finite() && dt > 0.0 {
        (v_north - prev.prev_v[0]).hypot(v_east - prev.prev_v[1]) / dt
    } else {
        0.0
    };
    [
        c,
        s,
        0.5 * (speed + 0.02).ln(),
        speed.min(40.0) / 10.0,
        if speed_acc.is_finite() {
            log(speed_acc * speed_acc)
        } else {
            0.0
        },
        flag(speed_acc.is_finite()),
        log(step.p).min(cap),
        log(step.r2).min(cap),
        step.k,
        0.5 * dt.clamp(0.01, 1000.0).ln(),
        0.5 * prev.t_still.min(1e4).ln_1p(),
        0.5 * prev.t_mode.min(1e4).ln_1p(),
        flag(step.rule_reverse),
        flag(prev.reverse),
        flag(st.vehicle.car),
        flag(step.moving),
        flag(step.glitch),
        flag(step.hold),
        log(st.vehicle.noise * st.vehicle.noise),
        0.5 * accel.min(1e3).ln_1p(),
    ]
}

/// The state after an epoch of the Kalman filter (or a per-epoch model) answered with
/// heading `psi` and raw `log_sigma`.
pub fn advance(
    state: &StepState,
    v_north: f32,
    v_east: f32,
    speed_acc: f32,
    dt: f32,
    psi: f32,
    log_sigma: f32,
) -> StepState {
    let mv = moving(v_north.hypot(v_east), speed_acc);
    StepState {
        psi: crate::head::wrap_rad(psi),
        log_sigma,
        has_prior: true,
        t_still: if mv { 0.0 } else { state.t_still + dt },
        ..*state
    }
}

/// The reported σ (degrees) of a temporal step: the filter's `log σ` plus the
/// network's correction `y2`, through the calibration map of the vehicle's class and
/// state; the uniform σ while the step only holds (before the first motion, as `kf`
/// answers). A moving car's σ leaves `y2` out when the maps say so
/// ([`crate::modes::SigmaMaps::moving_without_y2`]): the filter's σ follows the
/// receiver's noise, which `y2` had averaged away.
///
/// A standing car's heading cannot change, so the σ of a held heading is the one it
/// stopped with, growing with time (`q_still`): the filter's, corrected by the
/// network's `y2` of the last moving epoch (held in the state), not by each standing
/// epoch's (trained on noise it cannot see through, it would only make σ jitter).
/// Standing epochs of a [`crate::modes::clean`] receiver have a map of their own.
/// A car moving at speed then gains the turn term, a platform moving its share of it
/// ([`crate::modes::SigmaMaps::with_turn`]), and a car whose receiver reports no
/// speed accuracy its lag term ([`crate::modes::SigmaMaps::with_lag`]), in gentle
/// turns too when its velocity holds static (a navigation filter's output).
/// A moving epoch at [`crate::modes::TURN_SPEED`] or faster of a receiver whose sAcc
/// is more than twice the course scatter it has shown at speed has its raw σ divided by
/// the excess first ([`crate::modes::acc_overstatement`]): the maps are fitted on
/// receivers whose sAcc is about their noise.
/// A car or platform moving at [`crate::modes::TURN_SPEED`] or faster has a σ of at
/// least the course scatter the source has shown at speed over the speed
/// ([`crate::modes::SigmaMaps::scatter_k`]) when that scatter exceeds
/// the velocity noise the filter assumes (a receiver without sAcc, whose noise the
/// filter can only guess) or [`crate::modes::SCATTER_RATIO_ACC`] times it (a
/// receiver whose sAcc understates its noise by that much). Slower, the filter
/// averages several courses and the class map's σ, nearly flat in the raw σ there,
/// already spans the receivers' noise: a floor of one course's noise over-covered the
/// slow epochs of the shared real drive (models/reports/car-nagoya.md).
///
/// Until the history shows which way the vehicle faces ([`StepState::sense_known`]),
/// σ is at least [`crate::modes::SENSE_SIGMA_DEG`]: a car's first motion may be a
/// back-out, answered as forward until it drives on.
///
/// Otherwise a misread direction is not added as a variance: it is a 180° jump, not a
/// spread, and `p(1−p)·π²` of a confident decision (about 24° at the rule's prior)
/// swamped the filter's σ so that the map could no longer tell a good epoch from a
/// poor one; the calibration map's tails cover misreads instead.
pub fn reported_sigma(
    step: &Step,
    log_sigma: f32,
    y2: f32,
    st: &StepState,
    maps: &crate::modes::SigmaMaps,
) -> f32 {
    if step.hold {
        return MAX_STD_DEG;
    }
    // Moved by this step: a glitch the gate ignored is not motion (a car stays standing).
    let moved = st.moving_now();
    let y2 = if moved && st.vehicle.car && maps.moving_without_y2 {
        0.0
    } else if moved || !st.vehicle.car {
        y2
    } else {
        st.held_y2
    };
    let s = (log_sigma + y2)
        .clamp(crate::head::LOG_SIGMA_MIN, crate::head::LOG_SIGMA_MAX)
        .exp();
    let s = if moved && step.has_acc && step.speed >= crate::modes::TURN_SPEED {
        s / crate::modes::acc_overstatement(step.sigma_v, st.vehicle.scatter)
    } else {
        s
    };
    let car = st.vehicle.car;
    let mapped = maps.apply(car, moved, st.held_clean, s.to_degrees());
    let smoothing = crate::modes::Smoothing::of(step.has_acc, &st.vehicle);
    let sigma = maps.with_turn(car, moved, step.speed, mapped, st.yaw, smoothing);
    let sigma = maps.with_lag(smoothing, car, moved, step.speed, sigma, st.yaw);
    // Reversing, a car manoeuvres with its wheel turned: its antenna's course is off
    // its heading by up to `atan(k_max·L)`, which the lever correction takes out only
    // as far as a slow course's yaw rate shows it.
    let sigma = if moved && car && st.reverse && step.lever_max > 0.0 {
        sigma.hypot(step.lever_max.atan().to_degrees())
    } else {
        sigma
    };
    let sigma = if sense_unknown(st) {
        sigma.max(crate::modes::SENSE_SIGMA_DEG)
    } else {
        sigma
    };
    let scatter = st.vehicle.scatter;
    // Only a receiver noisier than the filter takes it to be: where the scatter is
    // within the σ_v in use, the maps (fitted on such receivers) already know it.
    let ratio = if step.has_acc {
        crate::modes::SCATTER_RATIO_ACC
    } else {
        1.0
    };
    if moved
        && maps.scatter_k > 0.0
        && scatter.is_finite()
        && step.speed >= crate::modes::TURN_SPEED
        && scatter.sqrt() > ratio * step.sigma_v
    {
        let floor = (maps.scatter_k * scatter.sqrt() / step.speed).to_degrees();
        sigma.max(floor.min(MAX_STD_DEG))
    } else {
        sigma
    }
}

/// Seconds the glitch gate must have skipped velocities at speed before the answer's σ
/// covers the skipped course. At 1 Hz one skipped epoch is a second: the gate cannot
/// tell a junction turn sharper than `a_max` from a glitch, and on simulated 1 Hz
/// u-blox cars fewer than half of such answers (a second-old heading) were within 2σ of
/// the truth, three quarters once σ covers the course. At 5–10 Hz a glitch burst that
/// short is skipped rightly, nearly always.
pub const GATED_SIGMA_S: f32 = 0.5;

/// Half the angle between a skipped course (at [`crate::modes::TURN_SPEED`] or faster,
/// after [`GATED_SIGMA_S`] of skipping) and the answer, degrees, so that the course
/// lies within 2σ; 0 otherwise.
fn gated_floor_deg(step: &Step, st: &StepState) -> f32 {
    if !(step.glitch && step.speed >= crate::modes::TURN_SPEED && st.t_used >= GATED_SIGMA_S) {
        return 0.0;
    }
    let z = crate::head::facing(step.course, st.reverse);
    (0.5 * crate::head::wrap_rad(z - st.psi).abs())
        .to_degrees()
        .min(MAX_STD_DEG)
}

/// Whether `st`'s vehicle has moved without showing which way it faces
/// ([`StepState::sense_known`]; a robot, declared, drives the way it faces at first),
/// or left its last stand against its held heading as a platform
/// ([`StepState::sense_doubt`]: backing up or turned in place, either may be).
#[inline]
fn sense_unknown(st: &StepState) -> bool {
    (st.moved && !st.sense_known && st.vehicle.platform != crate::modes::Platform::Robot)
        || st.sense_doubt
}

/// A car's stop held from its approach reads, as its raw σ, this many times the spread
/// of the approach's answers (in quadrature with [`APPROACH_FLOOR_DEG`]), not the
/// last epoch's σ: the stop's σ map (`car_still`) is fitted on it. The spread is what
/// tells a held heading's error: on simulated car stops the error's 90th percentile
/// grows about tenfold from the quietest eighth of approaches to the noisiest, while
/// the last epoch's σ was nearly the same at every stop (it is taken at walking pace).
/// 1.5 keeps the held-out stops within the bars per stop as well as per epoch
/// (`models/reports/ghnet-temporal.md`).
const APPROACH_SPREAD_K: f32 = 1.5;

/// Floor (degrees) of a stop's raw σ from its approach: answers that agreed exactly
/// (a lone one, a receiver that repeats its course) do not make a heading exact.
const APPROACH_FLOOR_DEG: f32 = 0.3;

/// The filter's update of `st` by `step` with the network's outputs `y`, what a stop
/// holds (the last moving epoch's `y₂` and receiver class; a car's approach and its
/// spread as the held σ), and the reported σ (degrees); `acc` is the epoch's sAcc (NaN
/// when absent). An answer the glitch gate has held for [`GATED_SIGMA_S`] at speed
/// reports a σ that covers the course it skipped within 2σ: that course may be a sharp
/// turn.
pub(crate) fn step_and_sigma(
    st: &mut StepState,
    step: &Step,
    y: &[f32],
    acc: f32,
    dt: f32,
    maps: &crate::modes::SigmaMaps,
) -> (crate::modes::Decision, f32) {
    let was_moving = st.moving_now();
    let mut d = crate::modes::commit(st, step, y, dt);
    if st.moving_now() {
        // What a stop starting after this epoch holds.
        st.held_y2 = y[2];
        st.held_clean = crate::modes::clean(st.vehicle.noise, acc);
    } else if was_moving {
        // A stop begins: a car's holds its approach ([`crate::modes::Approach`]); any
        // stand empties it.
        // Not an approach the car has since left behind, manoeuvring.
        let left = st.approach.left_behind(st.psi);
        if let Some((a, spread)) = st.approach.take().filter(|_| st.vehicle.car && !left) {
            // Held as surely as its answers agreed: the raw σ the stop's map reads.
            let raw = (APPROACH_SPREAD_K * spread).hypot(APPROACH_FLOOR_DEG.to_radians());
            (st.psi, d.psi) = (a, a);
            (st.log_sigma, d.log_sigma, st.held_y2) = (raw.ln(), raw.ln(), 0.0);
        }
    }
    let std = reported_sigma(step, d.log_sigma, y[2], st, maps);
    // A stand that saw motion off its axis: the held heading may be stale.
    let std = std.max(crate::modes::stand_doubt(st, step, dt));
    // Driving answers only: not a glitch burst that has not (yet) released a stand,
    // nor a release off a stand's axis that may still give the stand its heading back.
    if st.moving_now() && st.driving && st.before_release.is_none() {
        st.approach.add(st.psi, std, dt);
    } else if st.moving_now() && !step.glitch {
        // Manoeuvring, not a glitch burst at the stop (which the approach is there to
        // outlast).
        st.approach.idle(dt);
    }
    // Only the answer's: an approach weighing a held answer by the floor lost the
    // heading those answers held rightly through a glitch near a stop.
    (d, std.max(gated_floor_deg(step, st)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::modes::{SigmaMaps, Step, StepState};

    /// A platform moving at 1.5 m/s through a 20 °/s turn: its σ carries its share of
    /// the turn term, led or not (the lead takes out only the least lag a filtering
    /// receiver has).
    #[test]
    fn a_led_platform_answer_keeps_the_turn_share() {
        let maps = SigmaMaps {
            yaw_s: 1.0,
            ..SigmaMaps::default()
        };
        let mut st = StepState::EMPTY;
        st.yaw = 20f32.to_radians();
        st.t_still = 0.0;
        let step = |lead_s: f32| Step {
            k: 0.5,
            moving: true,
            hold: false,
            sigma_v: 0.1,
            lead_s,
            ..Step::holding(0.0, 0.0, 0.0, 1.5, f32::NAN)
        };
        let log_sigma = 5f32.to_radians().ln();
        let map = maps.apply(false, true, false, 5.0);
        let plain = reported_sigma(&step(0.0), log_sigma, 0.0, &st, &maps);
        let led = reported_sigma(&step(0.5), log_sigma, 0.0, &st, &maps);
        assert!(
            plain > map + 1.0,
            "unled: {plain}° against the map's {map}°"
        );
        assert!(
            (led - plain).abs() < 1e-3,
            "led: {led}° against the unled {plain}°"
        );
    }

    /// A platform in doubt of its sense (it left a stand against its held heading)
    /// reports at least `SENSE_SIGMA_DEG`, however small its filter's σ: backing up
    /// answered as driving forward is off by a half turn.
    #[test]
    fn a_platform_in_doubt_of_its_sense_covers_the_half_turn() {
        let maps = SigmaMaps::default();
        let mut st = StepState::fresh(crate::modes::Platform::Robot);
        (st.moved, st.t_still) = (true, 0.0);
        let step = Step {
            k: 0.5,
            moving: true,
            hold: false,
            sigma_v: 0.1,
            ..Step::holding(0.0, 0.0, 0.0, 0.5, 0.1)
        };
        let log_sigma = 5f32.to_radians().ln();
        let sure = reported_sigma(&step, log_sigma, 0.0, &st, &maps);
        st.sense_doubt = true;
        let doubt = reported_sigma(&step, log_sigma, 0.0, &st, &maps);
        assert!(sure < 10.0, "sure of its sense: {sure}°");
        assert_eq!(doubt, crate::modes::SENSE_SIGMA_DEG, "in doubt");
    }

    /// A car that has driven and knows its sense, heading north.
    fn driving_car() -> StepState {
        let mut st = StepState::EMPTY;
        (st.vehicle.car, st.sense_known, st.t_still, st.psi) = (true, true, 0.0, 0.0);
        st
    }

    /// A moving step along `course` (radians) at `speed` from a prior of 0, sAcc known.
    fn moving_step(course: f32, speed: f32) -> Step {
        Step {
            k: 0.5,
            moving: true,
            hold: false,
            sigma_v: 0.1,
            ..Step::holding(course, 0.0, 0.0, speed, 0.1)
        }
    }

    /// A car reversing at 1 m/s (the lever's whole `k_max·L` = 0.2) reports at least
    /// the antenna's largest lead, `atan(0.2)` = 11.3°, in quadrature with its own σ;
    /// driving forward, the same epoch keeps the map's σ.
    #[test]
    fn a_reversing_cars_sigma_covers_its_antennas_lead() {
        let maps = SigmaMaps::default();
        let mut st = driving_car();
        let step = Step {
            lever_s: 1.0,
            lever_max: 0.2,
            ..moving_step(0.0, 1.0)
        };
        let log_sigma = 3f32.to_radians().ln();
        let forward = reported_sigma(&step, log_sigma, 0.0, &st, &maps);
        st.reverse = true;
        let reversing = reported_sigma(&step, log_sigma, 0.0, &st, &maps);
        let lead = 0.2f32.atan().to_degrees();
        assert!(forward < lead, "forward: {forward}°");
        assert!(
            (reversing - forward.hypot(lead)).abs() < 1e-3,
            "reversing: {reversing}° against {forward}° and the lead's {lead}°"
        );
    }

    /// A car the gate has held for a second at 7 m/s, its skipped course 40° off the
    /// answer: σ covers that course within 2σ (20°), since the gate cannot tell a
    /// sharp turn from a glitch. One 5 Hz epoch into a burst it does not.
    #[test]
    fn a_long_gated_answer_covers_the_skipped_course() {
        let step = Step {
            k: 0.0,
            glitch: true,
            ..moving_step(40f32.to_radians(), 7.0)
        };
        // The floor under σ after `t_used` s of skipping.
        let floor_after = |t_used: f32| {
            let st = StepState {
                t_used,
                ..driving_car()
            };
            gated_floor_deg(&step, &st)
        };
        let (short, long) = (floor_after(0.2), floor_after(1.0));
        assert_eq!(short, 0.0, "one 5 Hz epoch skipped: {short}°");
        assert!((long - 20.0).abs() < 1e-3, "a second skipped: {long}°");
    }
}
