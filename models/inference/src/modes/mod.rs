//! The mode filter: the deterministic half of the temporal model, a circular Kalman
//! filter that knows how vehicles move.
//!
//! A plain Kalman filter on atan2 treats every course as the heading. Vehicles break
//! that in three ways, and each has a physical rule here:
//!
//! * **Cars back up.** After a stop, a car moves off either along its held heading or
//!   opposite to it; opposite means reversing (course = heading + 180°), not a 180° turn.
//!   The filter keeps a *mode* (forward or reversing) and measures `course + π·mode`.
//!   Flipping into reverse takes a sure held heading; leaving a stop along the held
//!   heading ends a reversal on any heading, since forward is the likelier way out.
//!   Two escapes keep a wrong mode from lasting: a car never reverses at sustained speed
//!   (above `escape_speed` by more than the receiver's noise, `ESCAPE_NOISE_K`, the
//!   mode ends and the heading turns by 180°), and a vehicle that has not yet shown
//!   car-like speed has no reverse mode at all (next point), nor does the network's
//!   reverse correction give it one: a platform that turned in place at a stop and
//!   drives off the other way is driving forward. Such a departure may also be backing
//!   up, and its σ says so ([`StepState::sense_doubt`]).
//! * **Cars do not turn in place; platforms do.** A vehicle counts as a car once it has
//!   driven above `fast_speed` for `fast_secs` and `FAST_EPOCHS` epochs, the first of
//!   them turned from the slower course before no more than a car steers
//!   ([`STEER_IN_NOISE_K`]; kept across fix gaps: it is the same vehicle). Until then
//!   it is treated as a platform that turns in place: its heading random-walks while
//!   it stands (`q_tip`), there is no reverse mode, and slow motion is trusted. A
//!   car's heading random-walks only with distance driven, as much as its steering
//!   allows (`k_max`, `a_lat`), so a stopped car holds its heading exactly. One that
//!   leaves a stand off the axis it stood on and keeps going has shown that it turns in
//!   place ([`Vehicle::turns`]): at its stands, a steady creep is answered with its
//!   course, as a declared robot's is; a car that leaves a stand so is taken for a
//!   platform again until it drives fast, unless it has driven faster than any robot
//!   ([`SURE_CAR_SPEED`]: then the stand's heading was stale, not the class).
//! * **Receivers lie.** The measurement σ is the receiver's noise over the speed, with
//!   the noise taken as the larger of the reported sAcc and a running estimate from the
//!   speeds the receiver reports when slow (a low quantile: a stopped vehicle's speed is
//!   pure noise; a receiver that holds static keeps the first guess, its zeros showing
//!   no noise). At speed, a velocity change a car cannot make in `dt` (over
//!   `a_max·dt`) is a glitch and is not used (at most `max_skips` in a row).
//! * **Receivers lag.** A receiver that holds static (exact zeros at rest, hardly ever a
//!   creeping speed) runs a navigation filter, and its course trails a turn by the
//!   yaw rate times its lag. Such a vehicle, car or not, and any vehicle not known to
//!   be a car is answered ahead of the filter's heading by `atan(ω·τ)`: ω the yaw rate
//!   smoothed over `LEAD_YAW_TAU_S` and shrunk by its own scatter (a noisy course is
//!   not differentiated), τ the model's `lag_s`, or `hold_lag_s` for such a receiver,
//!   or `no_acc_lag_s` for a vehicle not known to be a car whose receiver gives no
//!   accuracy (NMEA: maybe a filter's output). The filter's own state follows the
//!   course; only the answer leads (the consumer and NMEA robot rows of
//!   models/reports/unmet.md).
//! * **A standing car stays put.** Its epochs within the noise (under 3σ, or under the
//!   release bar on a receiver that holds static, whose noise is a guess) feed nothing
//!   (no gain, no steering noise); it leaves rest only on a velocity reachable from rest since
//!   the last used epoch, confirmed by the next epoch, and (for `axis_secs`) along the
//!   axis of a sure held heading. On the simulator's validation cars this cut the
//!   standing epochs' error, median and tail: most of it had been glitches and noise
//!   turning a parked car (the stopped rows of models/reports/ghnet-temporal.md). A
//!   stand whose velocity, averaged over a few seconds, shows steady motion off that
//!   axis keeps its heading, and its σ covers the turn ([`stand_doubt`]).
//!
//! Until the history's first epoch that the tuned `kf` would use (its measurement gate
//! `σ_v/ŝ` below the uniform σ), the model answers exactly what `kf` answers: the first
//! epoch's course with the uniform σ. Nothing knows a parked car's heading; both share
//! one convention there, so comparisons measure what happens after the first motion.
//! One exception: a vehicle not known to be a car that creeps steadily for [`START_S`]
//! (moving by its receiver's own accuracy, slower than `kf`'s gate) has started: it is
//! going somewhere, not backing out of a parking space, and its course is its heading.
//!
//! The network ([`crate::stream`]) corrects this filter: `y₀` the gain in log-odds,
//! `y₁` the reverse decision as a logit around the rule's (`±REVERSE_PRIOR`), `y₂` the
//! reported `log σ`. Zero outputs are exactly the mode filter.

mod approach;
mod commit;
mod creep;
mod doubt;
mod noise;
mod params;
mod prepare;
mod release;
mod scatter;
mod sigma;
mod smooth;
mod start;
mod state;
mod vehicle;

pub use approach::{
    Approach, APPROACH_BUCKETS, APPROACH_IDLE_S, APPROACH_LEFT_DEG, APPROACH_S, APPROACH_TURN_DEG_S,
};
pub use commit::{
    commit, corrected_gain, reverse_logit, Decision, LEAD_YAW_TAU_S, REVERSE_PRIOR, SENSE_RUN_M,
    SENSE_SIGMA_DEG, YAW_TAU_S,
};
pub use creep::{
    stationary_course, AUTO_CREEP_MIN_SPEED, ROBOT_COURSE_NOISE_K, ROBOT_COURSE_TURN_DEG_S,
    ROBOT_REST_NOISE_SHARE,
};
pub use doubt::{
    stand_doubt, STAND_DOUBT_CLIP_K, STAND_DOUBT_NOISE_K, STAND_DOUBT_SIGMA_K, STAND_DOUBT_STEADY,
    STAND_DOUBT_TAU_S,
};
pub(crate) use noise::random_walk_variance;
pub use noise::{ACC_RATIO_WARMUP, GATE_REST_NOISE_K, HOLD_SCATTER_K};
pub use params::{ModeParams, LEVER_M, PESSIMISTIC_SACC_RATIO};
pub use prepare::{prepare, ESCAPE_NOISE_K, STEER_IN_NOISE_K};
pub use release::{
    BRAKE_MAX, GEAR_CHANGE_S, LONG_STAND_S, RELEASE_BURST_EPOCHS, RELEASE_CONT_ACC_K,
    RELEASE_CONT_NOISE_K, RELEASE_COURSE_DEG, RELEASE_EPOCHS, RELEASE_EPOCHS_LONG_STAND,
    RELEASE_EPOCHS_OFF_AXIS, RELEASE_LOW_RATE_DT, RELEASE_NOISE_CAP, RELEASE_NOISE_CAP_LOW_RATE,
    RELEASE_NOISE_K_AXIS, RELEASE_S, RELEASE_SPEED, RELEASE_S_MIN, REVERSAL_MIN_SPEED,
    TURN_SPEED_CHANGE, UNSURE_HELD_DEG,
};
pub use scatter::{
    acc_overstatement, extrapolation_share, ACC_OVERSTATED_MAX, ACC_OVERSTATED_RATIO,
    SCATTER_MAX_DT, SCATTER_RATIO_ACC, SCATTER_SMOOTH_DT, SCATTER_SPEED, SCATTER_TAU_S,
};
pub use sigma::{
    clean, SigmaMap, SigmaMaps, Smoothing, CAR_BEYOND_K, CLEAN_NOISE_RATIO, LAG_NONE_S,
    LAG_YAW_DEADBAND_DEG, PLATFORM_TURN_SHARE, PLATFORM_TURN_SPEED, SIGMA_KNOTS, TURN_SPEED,
};
pub use smooth::{SMOOTH_MAX_DT, SMOOTH_MIN_PAIRS, SMOOTH_SPEED, SMOOTH_WHITE_BAR, SMOOTH_WINDOW};
pub use start::START_S;
pub use state::{HeldHeading, MotionRun, Step, StepState};
pub use vehicle::{
    Platform, SmoothLink, Vehicle, ACC_RATIO_MIN_EPOCHS, ACC_RATIO_QUANTILE, FAST_EPOCHS,
    HOLD_CREEP_SPEED, HOLD_MIN_ZEROS, HOLD_ZEROS_PER_CREEP, SURE_CAR_SPEED, TURN_IN_PLACE_DEG,
    TURN_RUN_S, TURN_STAND_S, TURN_SURE_DEG,
};

#[cfg(test)]
mod tests {
    use super::*;
    use crate::head::wrap_rad;

    /// One 1 Hz epoch with sAcc 0.3 m/s through the filter alone (zero network outputs).
    fn epoch(st: &mut StepState, speed: f32) {
        let mp = ModeParams::default();
        let step = prepare(&mp, 0.5, st, speed, 0.0, 0.3, 1.0);
        commit(st, &step, &[0.0, 0.0, 0.0], 1.0);
    }

    /// Five fast epochs in a row make a car; the same five split by a stand do not (a
    /// platform's glitch bursts at a stop used to add up to a car).
    #[test]
    fn fast_epochs_make_a_car_only_in_a_row() {
        let mut st = StepState::EMPTY;
        epoch(&mut st, 0.05);
        for _ in 0..5 {
            epoch(&mut st, 4.0);
        }
        assert!(st.vehicle.car, "five fast epochs in a row");
        let mut st = StepState::EMPTY;
        epoch(&mut st, 0.05);
        for speed in [4.0, 4.0, 4.0, 0.05, 0.05, 0.05, 4.0, 4.0] {
            epoch(&mut st, speed);
        }
        assert!(!st.vehicle.car, "a stand ends the run: {st:?}");
    }

    /// Fast epochs that start by turning off a creep's course further than a car
    /// steers (a glitch burst at 1 Hz) make no car; the same epochs along the creep's
    /// course do. A robot creeping at 0.64 m/s (sAcc 0.168 m/s), then five epochs at
    /// 3.6 m/s, 92° off (the burst of a simulated u-blox robot) or 14° off.
    #[test]
    fn a_burst_turning_off_a_creep_makes_no_car() {
        for (course, car) in [(158.0, false), (80.0, true)] {
            let mut st = StepState::EMPTY;
            for _ in 0..5 {
                epoch_dt(&mut st, 0.64, 66.0, 0.168, 1.0);
            }
            for _ in 0..5 {
                epoch_dt(&mut st, 3.6, course, 0.168, 1.0);
            }
            assert_eq!(st.vehicle.car, car, "{course}°: {st:?}");
        }
    }

    /// One 1 Hz epoch along `course_deg` at `speed` (sAcc 0.1 m/s), filter alone: the
    /// answer.
    fn along(st: &mut StepState, speed: f32, course_deg: f32) -> Decision {
        along_acc(st, speed, course_deg, 0.1)
    }

    /// [`along`] on a receiver reporting sAcc `acc` (m/s).
    fn along_acc(st: &mut StepState, speed: f32, course_deg: f32, acc: f32) -> Decision {
        epoch_dt(st, speed, course_deg, acc, 1.0).0
    }

    /// The yaw rate follows a steady turn, fades on a straight and is 0 once stopped,
    /// so a turn's σ term ends with the turn.
    #[test]
    fn yaw_rate_follows_turns_and_ends_at_a_stop() {
        let mut st = StepState::EMPTY;
        along(&mut st, 0.0, 0.0);
        for _ in 0..12 {
            along(&mut st, 8.0, 0.0);
        }
        assert!(st.yaw.abs() < 0.2f32.to_radians(), "straight: {st:?}");
        for k in 1..=15 {
            along(&mut st, 8.0, 10.0 * k as f32);
        }
        let deg = st.yaw.to_degrees();
        assert!((7.0..=11.0).contains(&deg), "a 10°/s turn reads {deg}°/s");
        for _ in 0..8 {
            along(&mut st, 8.0, 150.0);
        }
        assert!(st.yaw.to_degrees().abs() < 1.0, "after the turn: {st:?}");
        for k in 1..=5 {
            along(&mut st, 8.0, 150.0 - 10.0 * k as f32);
        }
        assert!(st.yaw < 0.0, "a left turn is negative: {st:?}");
        along(&mut st, 0.01, 0.0);
        assert_eq!(st.yaw, 0.0, "standing");
    }

    /// A robot that drove north, spun in place and drives south is driving forward:
    /// however sure the network is that the course reversed, a vehicle not known to
    /// be a car answers along its course. A car that does the same is reversing when
    /// the network says so.
    #[test]
    fn only_a_car_reverses_on_the_networks_word() {
        let mp = ModeParams::default();
        for car in [false, true] {
            let mut st = StepState::fresh(if car { Platform::Car } else { Platform::Robot });
            along(&mut st, 0.0, 0.0);
            for _ in 0..10 {
                along(&mut st, 1.5, 0.0);
            }
            for _ in 0..5 {
                along(&mut st, 0.0, 0.0);
            }
            let step = prepare(&mp, 0.5, &mut st, -1.5, 0.0, 0.1, 1.0);
            let d = commit(&mut st, &step, &[0.0, 20.0, 0.0], 1.0);
            let off = wrap_rad(d.psi - std::f32::consts::PI).abs().to_degrees();
            if car {
                assert!(st.reverse && off > 170.0, "a car reverses: {off}° {st:?}");
            } else {
                assert!(
                    !st.reverse && off < 10.0,
                    "a robot drives on: {off}° {st:?}"
                );
            }
        }
    }

    /// A robot that drove north, stood and leaves against the heading it held (south,
    /// or east: over `flip_stop_deg` off) may be backing up or may have turned in
    /// place, so it doubts its sense until it has driven `SENSE_RUN_M` without a stand,
    /// however long it stood. One leaving along its heading drives forward; a car
    /// leaving against it reverses (its mode knows). Neither doubts.
    #[test]
    fn a_platform_leaving_a_stand_against_its_heading_doubts_its_sense() {
        let cases = [
            (Platform::Robot, 2, 180.0, true),
            (Platform::Robot, 1, 100.0, true),
            (Platform::Robot, 30, 180.0, true),
            (Platform::Robot, 2, 20.0, false),
            (Platform::Robot, 30, 20.0, false),
            (Platform::Car, 2, 180.0, false),
        ];
        for (platform, stand, course, doubt) in cases {
            let mut st = StepState::fresh(platform);
            along(&mut st, 0.0, 0.0);
            for _ in 0..10 {
                along(&mut st, 1.5, 0.0);
            }
            assert!(!st.sense_doubt, "driving: {st:?}");
            for _ in 0..stand {
                along(&mut st, 0.0, 0.0);
            }
            along(&mut st, 0.5, course);
            let what = format!("{platform:?} leaving at {course}° after {stand} s");
            assert_eq!(st.sense_doubt, doubt, "{what}: {st:?}");
            // 0.5 m/s at 1 Hz: SENSE_RUN_M in 20 epochs.
            for _ in 0..19 {
                along(&mut st, 0.5, course);
            }
            assert!(!st.sense_doubt, "{what}, after {} m: {st:?}", st.run_m);
        }
    }

    /// A car (1 Hz, filter alone) that drove north, stood, and backs up southwards
    /// for `epochs` epochs at 1 m/s: in reverse mode, heading north.
    fn reversing_car(epochs: usize) -> StepState {
        backing_up(epochs, 1.0, 0.1)
    }

    /// [`reversing_car`] backing up at `speed` on a receiver reporting sAcc `acc`.
    fn backing_up(epochs: usize, speed: f32, acc: f32) -> StepState {
        backing_up_after(8.0, epochs, speed, acc)
    }

    /// [`backing_up`] after driving north at `drive` m/s (8 s).
    fn backing_up_after(drive: f32, epochs: usize, speed: f32, acc: f32) -> StepState {
        let mut st = StepState::EMPTY;
        along_acc(&mut st, 0.0, 0.0, acc);
        for _ in 0..8 {
            along_acc(&mut st, drive, 0.0, acc);
        }
        for _ in 0..3 {
            along_acc(&mut st, 0.0, 0.0, acc);
        }
        for _ in 0..epochs {
            along_acc(&mut st, speed, 180.0, acc);
        }
        assert!(st.vehicle.car && st.reverse, "backing up: {st:?}");
        st
    }

    /// A car (it drove at 4 m/s, as fast as some robots) that backed out, stood, then
    /// drove off sideways for good turned in place: it is no car, and a platform has no
    /// reverse mode, so its answer is its course, not the course turned by the half turn
    /// it was reversing with.
    #[test]
    fn a_car_demoted_while_reversing_answers_its_course() {
        let mp = ModeParams::default();
        let mut st = backing_up_after(4.0, 3, 1.0, 0.1);
        for _ in 0..3 {
            along(&mut st, 0.0, 0.0);
        }
        let mut last = 0.0;
        for _ in 0..6 {
            let (s, c) = 90f32.to_radians().sin_cos();
            let step = prepare(&mp, 0.5, &mut st, 1.5 * c, 1.5 * s, 0.1, 1.0);
            last = commit(&mut st, &step, &[0.0, 0.0, 0.0], 1.0).psi;
        }
        assert!(!st.vehicle.car && !st.reverse, "turned in place: {st:?}");
        let off = wrap_rad(last - 90f32.to_radians()).to_degrees();
        assert!(off.abs() < 10.0, "{off}° off its course: {st:?}");
    }

    /// A car that stood after driving north and leaves its stand eastwards at 1.5 m/s
    /// (a turn the stand did not follow) is demoted when it drove at 4 m/s, which some
    /// robots do, and stays a car when it drove at 8 m/s, faster than any robot
    /// ([`SURE_CAR_SPEED`]); either way its answer follows the departure.
    #[test]
    fn a_car_that_drove_faster_than_robots_is_not_demoted() {
        let mp = ModeParams::default();
        for (drive, car) in [(4.0, false), (8.0, true)] {
            let mut st = StepState::EMPTY;
            along(&mut st, 0.0, 0.0);
            for _ in 0..8 {
                along(&mut st, drive, 0.0);
            }
            for _ in 0..5 {
                along(&mut st, 0.0, 0.0);
            }
            assert!(st.vehicle.car, "{drive} m/s: {st:?}");
            let mut last = 0.0;
            for _ in 0..8 {
                let (s, c) = 90f32.to_radians().sin_cos();
                let step = prepare(&mp, 0.5, &mut st, 1.5 * c, 1.5 * s, 0.1, 1.0);
                last = commit(&mut st, &step, &[0.0, 0.0, 0.0], 1.0).psi;
            }
            assert_eq!(st.vehicle.car, car, "{drive} m/s: {st:?}");
            let off = wrap_rad(last - 90f32.to_radians()).to_degrees();
            assert!(
                off.abs() < 10.0,
                "{drive} m/s: {off}° off its course: {st:?}"
            );
        }
    }

    /// A car that backed into a space and leaves it forward is answered forward: a
    /// departure along the held heading ends the reverse mode, however fast its first
    /// epoch (at 1 Hz, 3 m/s). A mode kept until sustained speed ends it turns the
    /// held heading by a half turn on the way.
    #[test]
    fn a_car_that_backed_in_leaves_forward() {
        let mp = ModeParams::default();
        let mut st = reversing_car(4);
        for _ in 0..20 {
            along(&mut st, 0.0, 0.0);
        }
        for speed in [3.0, 3.5, 4.0, 4.5] {
            let step = prepare(&mp, 0.5, &mut st, speed, 0.0, 0.1, 1.0);
            let d = commit(&mut st, &step, &[0.0, 0.0, 0.0], 1.0);
            let off = wrap_rad(d.psi).to_degrees();
            assert!(off.abs() < 10.0, "{off}° at {speed} m/s: {st:?}");
        }
        assert!(!st.reverse, "driving forward: {st:?}");
    }

    /// A car backing up at 1.7 m/s on a receiver with 0.4 m/s of noise, whose speed
    /// reads 2.15 m/s two epochs in a row, is still backing up: the reverse mode ends
    /// only at a speed clear of the noise (`ESCAPE_NOISE_K`), as it does when the car
    /// drives on at 4 m/s (then it was driving forward, and the heading turns).
    #[test]
    fn noise_over_the_escape_speed_does_not_end_a_reversal() {
        let mut st = backing_up(3, 1.7, 0.4);
        for _ in 0..2 {
            let off = wrap_rad(along_acc(&mut st, 2.15, 180.0, 0.4).psi).to_degrees();
            assert!(st.reverse && off.abs() < 10.0, "{off}° off: {st:?}");
        }
        for _ in 0..2 {
            along_acc(&mut st, 4.0, 180.0, 0.4);
        }
        let off = wrap_rad(st.psi - std::f32::consts::PI).to_degrees();
        assert!(
            !st.reverse && off.abs() < 10.0,
            "{off}° off at 4 m/s: {st:?}"
        );
    }

    /// One 5 Hz epoch of a receiver without sAcc along `course_deg` at `speed` (exact
    /// zeros at 0), filter alone: the answer and the course (radians).
    fn no_acc(st: &mut StepState, speed: f32, course_deg: f32) -> (Decision, f32) {
        epoch_acc(st, speed, course_deg, f32::NAN)
    }

    /// One 5 Hz epoch along `course_deg` at `speed` with sAcc `acc` (NaN: none),
    /// filter alone: the answer and the course (radians).
    fn epoch_acc(st: &mut StepState, speed: f32, course_deg: f32, acc: f32) -> (Decision, f32) {
        epoch_dt(st, speed, course_deg, acc, 0.2)
    }

    /// [`epoch_acc`] `dt` s after the last epoch.
    fn epoch_dt(
        st: &mut StepState,
        speed: f32,
        course_deg: f32,
        acc: f32,
        dt: f32,
    ) -> (Decision, f32) {
        let mp = ModeParams::default();
        let c = course_deg.to_radians();
        let step = prepare(&mp, 0.5, st, speed * c.cos(), speed * c.sin(), acc, dt);
        (commit(st, &step, &[0.0, 0.0, 0.0], dt), c)
    }

    /// `n` epochs of `no_acc` at one speed and course.
    fn run(st: &mut StepState, n: usize, speed: f32, course_deg: f32) {
        run_acc(st, n, speed, course_deg, f32::NAN);
    }

    /// `n` epochs of `epoch_acc` at one speed, course and sAcc.
    fn run_acc(st: &mut StepState, n: usize, speed: f32, course_deg: f32, acc: f32) {
        for _ in 0..n {
            epoch_acc(st, speed, course_deg, acc);
        }
    }

    /// A vehicle on `platform` stands (at `rest` m/s), drives straight at `speed`, then
    /// turns at 10°/s, its receiver reporting sAcc `acc` (NaN: none): how far (degrees)
    /// the last answer is ahead of the last course.
    fn lead_in_turn(platform: Platform, rest: f32, acc: f32, speed: f32) -> f32 {
        let mut st = StepState::fresh(platform);
        run_acc(&mut st, 10, rest, 0.0, acc);
        run_acc(&mut st, 10, speed, 0.0, acc);
        let mut last = (0.0, 0.0);
        for k in 1..=25 {
            let (d, c) = epoch_acc(&mut st, speed, 2.0 * k as f32, acc);
            last = (d.psi, c);
        }
        wrap_rad(last.0 - last.1).to_degrees()
    }

    /// A receiver that holds static but passes raw velocity through is not led once its
    /// noise has shown that: courses jittering from epoch to epoch (each change undoing
    /// the last, as white noise does) over 60 s of driving, then a turn at 10°/s, and
    /// the answer stays on the course. The same drive with a slow wander (a navigation
    /// filter's smoothed noise) is led as a static hold is.
    #[test]
    fn a_static_hold_whose_noise_is_white_is_not_led() {
        let lead = |jitter: fn(usize) -> f32| {
            let mut st = StepState::fresh(Platform::Robot);
            run(&mut st, 10, 0.0, 0.0);
            for k in 0..300 {
                epoch_acc(&mut st, 1.5, jitter(k), f32::NAN);
            }
            let mut last = (0.0, 0.0);
            for k in 1..=25 {
                let (d, c) = epoch_acc(&mut st, 1.5, 2.0 * k as f32, f32::NAN);
                last = (d.psi, c);
            }
            (wrap_rad(last.0 - last.1).to_degrees(), st.vehicle)
        };
        let (white, v) = lead(|k| if k % 2 == 0 { 1.5 } else { -1.5 });
        assert!(v.raw_hold(), "{v:?}");
        assert!(white.abs() < 1.0, "raw velocity behind a hold: {white}°");
        let (smooth, v) = lead(|k| 3.0 * (k as f32 * 0.05).sin());
        assert!(v.holds_static() && !v.raw_velocity(), "{v:?}");
        assert!((3.0..6.0).contains(&smooth), "a filter's output: {smooth}°");
    }

    /// A receiver that holds static (exact zeros at rest, no creeping speeds) runs a
    /// navigation filter whose course lags a turn: a robot's answer leads its course by
    /// the filtered yaw rate times `hold_lag_s` (10°/s × 0.5 s ≈ 5°). One that shows its
    /// noise at rest and gives no sAcc (NMEA) may filter too: led by `no_acc_lag_s`,
    /// half as far. One with an sAcc (raw Doppler, which does not lag) is answered
    /// along the course; a car's answer trails it by its antenna's lever arm (next
    /// test).
    #[test]
    fn a_static_hold_receivers_course_is_led_through_a_turn() {
        let lead = lead_in_turn(Platform::Robot, 0.0, f32::NAN, 1.5);
        assert!((3.0..6.0).contains(&lead), "static hold: {lead}°");
        let nmea = lead_in_turn(Platform::Robot, 0.1, f32::NAN, 1.5);
        assert!(
            (1.0..lead * 0.6).contains(&nmea),
            "no sAcc, creeping at rest: {nmea}°"
        );
        let raw = lead_in_turn(Platform::Robot, 0.1, 0.1, 1.5);
        assert!(raw.abs() < 1.0, "sAcc, creeping at rest: {raw}°");
        let mut v = Vehicle::UNKNOWN;
        v.observe_hold(0.0);
        assert!(!v.holds_static(), "one zero is a bad fix, not a hold");
        for _ in 1..HOLD_MIN_ZEROS {
            v.observe_hold(0.0);
        }
        assert!(v.holds_static());
        v.observe_hold(1.5);
        assert!(v.holds_static(), "motion starts with a jump");
        for _ in 0..HOLD_MIN_ZEROS {
            v.observe_hold(0.05f32.hypot(0.1));
        }
        assert!(!v.holds_static(), "as many creeping speeds as zeros");
        // A stop that creeps for an epoch on its way down, then stands for 2 s at 5 Hz.
        let mut v = Vehicle::UNKNOWN;
        for _ in 0..10 {
            v.observe_hold(0.0);
        }
        v.observe_hold(0.2);
        assert!(v.holds_static(), "an epoch of creeping among zeros: {v:?}");
    }

    /// A car turning at 10°/s at 1.5 m/s (a junction) on a receiver that shows its
    /// noise at rest, with its antenna [`LEVER_M`]
    /// ahead of the rear axle: the course leads the heading by `atan(ω·L/v)`, which
    /// the answer takes out as far as the lag's fade leaves it (`ModeParams::lever`;
    /// the filter's own heading stays on the course). Reversing out of a stand through
    /// the same turn, the course turned by a half turn trails the heading, and the
    /// answer leads it. At 3 m/s a receiver's lag may outweigh the lever: the answer
    /// keeps the course.
    #[test]
    fn a_cars_answer_takes_its_antennas_lever_arm_out() {
        let mut car = Vehicle::UNKNOWN;
        car.car = true;
        let (lever_s, _) = ModeParams::default().lever(&car, 1.5, false);
        assert!(lever_s > 0.0 && lever_s <= LEVER_M / 1.5);
        let want = (10f32.to_radians() * lever_s).atan().to_degrees();
        let lead = lead_in_turn(Platform::Car, 0.01, f32::NAN, 1.5);
        // The yaw rate is still growing (smoothed over 2 s) and shrunk by its scatter.
        let taken = 0.6 * want..want + 1.0;
        assert!(taken.contains(&-lead), "forward: {lead}°, want −{want}°");
        let mut st = StepState::fresh(Platform::Car);
        run(&mut st, 10, 0.01, 0.0);
        run(&mut st, 10, 1.5, 0.0);
        run(&mut st, 10, 0.01, 0.0);
        let mut last = (0.0, 0.0);
        for k in 1..=25 {
            let (d, c) = no_acc(&mut st, 1.5, 180.0 + 2.0 * k as f32);
            last = (d.psi, c);
        }
        assert!(st.reverse, "reversing: {st:?}");
        let lead = wrap_rad(last.0 - last.1 - std::f32::consts::PI).to_degrees();
        assert!(taken.contains(&lead), "reversing: {lead}°, want {want}°");
        let mut st = StepState::fresh(Platform::Car);
        run(&mut st, 10, 0.01, 0.0);
        run(&mut st, 10, 3.0, 0.0);
        for k in 1..=25 {
            let (d, c) = no_acc(&mut st, 3.0, 2.0 * k as f32);
            let off = wrap_rad(d.psi - c).to_degrees();
            assert!(off.abs() < 1.0, "3 m/s: {off}° off the course");
        }
    }

    /// A car whose receiver reports sAcc and shows its noise at rest gives raw Doppler
    /// velocity, which lags little: its antenna's lead is taken out up to `L/2τ` with
    /// τ = `acc_lag_s` (2 m/s), faded to none at `L/τ`, where a receiver without sAcc
    /// keeps the course from 2 m/s (previous test). At 3 m/s in a 10°/s turn the
    /// answer trails the course by about `atan(ω·lever_s)`.
    #[test]
    fn a_raw_doppler_cars_lever_is_taken_out_at_speed() {
        let mut car = Vehicle::UNKNOWN;
        car.car = true;
        let mp = ModeParams::default();
        assert_eq!(mp.lever(&car, 3.0, false), (0.0, 0.0));
        let (lever_s, _) = mp.lever(&car, 3.0, true);
        assert!(lever_s > 0.0 && lever_s < LEVER_M / 3.0, "{lever_s}");
        let whole = LEVER_M / (2.0 * mp.acc_lag_s);
        assert_eq!(mp.lever(&car, whole, true).0, LEVER_M / whole);
        assert_eq!(mp.lever(&car, 2.0 * whole, true), (0.0, 0.0));
        let want = (10f32.to_radians() * lever_s).atan().to_degrees();
        let lead = lead_in_turn(Platform::Car, 0.1, 0.1, 3.0);
        assert!(
            (0.6 * want..want + 1.0).contains(&-lead),
            "{lead}°, want −{want}°"
        );
    }

    /// A car whose receiver holds static (exact zeros at rest) runs behind a navigation
    /// filter's lag as a robot's does: its answer leads the course by the lag as well
    /// as taking out the lever arm, so it sits about `atan(10°/s × hold_lag_s)` ahead
    /// of the answer on a receiver that shows its noise at rest.
    #[test]
    fn a_static_hold_cars_answer_is_led_too() {
        let held = lead_in_turn(Platform::Car, 0.0, f32::NAN, 1.5);
        let noisy = lead_in_turn(Platform::Car, 0.01, f32::NAN, 1.5);
        let lag = (10f32.to_radians() * ModeParams::default().hold_lag_s)
            .atan()
            .to_degrees();
        let ahead = held - noisy;
        assert!(
            (0.6 * lag..lag + 1.0).contains(&ahead),
            "static hold {held}°, noisy {noisy}°: {ahead}° ahead, want about {lag}°"
        );
    }

    /// Leaving a stand, the step from the held heading to the first course (a spin in
    /// place) is no turn the course lags: the answers after it follow the new course.
    #[test]
    fn leaving_a_stand_is_not_led() {
        let mut st = StepState::fresh(Platform::Robot);
        run(&mut st, 10, 0.0, 0.0);
        run(&mut st, 10, 1.5, 0.0);
        run(&mut st, 10, 0.0, 0.0);
        for _ in 0..3 {
            let (d, c) = no_acc(&mut st, 1.5, 120.0);
            let off = wrap_rad(d.psi - c).to_degrees();
            assert!(
                off.abs() < 1.0,
                "{off}° off the course after a spin: {st:?}"
            );
        }
    }

    /// A car slowing to a stop (a lagging receiver's tail at walking pace) reads a spike
    /// of 1.8 m/s a quarter turn off: from 0.5 m/s no car gets there in 0.2 s, so the
    /// spike does not turn its heading, at any speed under `gate_speed`. Coming down
    /// from speed is gated only by [`BRAKE_MAX`]: braking is harder than `a_max`.
    #[test]
    fn a_spike_out_of_slow_motion_does_not_turn_a_car() {
        let mut st = StepState::fresh(Platform::Car);
        run(&mut st, 5, 0.0, 86.0);
        run(&mut st, 10, 3.5, 86.0);
        for speed in [2.0, 1.2, 0.9, 0.7, 0.5] {
            let (d, _) = no_acc(&mut st, speed, 86.0);
            let off = wrap_rad(d.psi - 86f32.to_radians()).to_degrees();
            assert!(off.abs() < 2.0, "braking at {speed} m/s: {off}° {st:?}");
        }
        let (d, _) = no_acc(&mut st, 1.8, 11.0);
        assert!(st.skips == 1, "the spike is a glitch: {st:?}");
        let off = wrap_rad(d.psi - 86f32.to_radians()).to_degrees();
        assert!(off.abs() < 2.0, "turned by a spike: {off}° {st:?}");
        let (d, _) = no_acc(&mut st, 0.4, 88.0);
        let off = wrap_rad(d.psi - 86f32.to_radians()).to_degrees();
        assert!(off.abs() < 3.0, "after the spike: {off}° {st:?}");
    }

    /// A car turning through a junction at 6.7 m/s, seen at 1 Hz: 42° in the first
    /// second is more than `a_max` allows, but the second epoch, as fast and another
    /// 34° on, is reachable over the two seconds since the last used velocity, and
    /// the answer follows it ([`TURN_SPEED_CHANGE`]). It was compared with one
    /// second's allowance, rejected twice more, and the heading stayed 68° behind for
    /// three seconds. The same courses with the speed falling by 2–3 m/s (a glitch
    /// burst, as on the shared real drive) are still rejected.
    #[test]
    fn a_sharp_turn_at_1hz_is_followed_from_its_second_epoch() {
        let turn = |speeds: [f32; 3]| {
            let mut st = StepState::fresh(Platform::Car);
            along(&mut st, 0.0, 68.0);
            for _ in 0..20 {
                along(&mut st, 6.7, 68.0);
            }
            let courses = speeds.into_iter().zip([26.0, -8.0, -8.0]);
            courses
                .map(|(speed, course)| wrap_rad(along(&mut st, speed, course).psi).to_degrees())
                .collect::<Vec<_>>()
        };
        let steady = turn([6.6, 6.6, 6.8]);
        assert!(
            (steady[0] - 68.0).abs() < 1.0,
            "first epoch gated: {steady:?}"
        );
        assert!(
            (steady[1] + 8.0).abs() < 3.0,
            "second epoch taken: {steady:?}"
        );
        let glitch = turn([4.4, 3.9, 6.7]);
        assert!(
            (glitch[1] - 68.0).abs() < 1.0,
            "a glitch burst is still gated: {glitch:?}"
        );
    }

    /// A car at 6.7 m/s, seen at 1 Hz, whose receiver reads one epoch at 2 m/s 34° off
    /// (under `gate_speed`, so the gate takes it): measured from that glitch, the next
    /// epoch, back at 6.8 m/s on the car's course, looks unreachable, and the answer
    /// kept the glitch's course for `max_skips` more seconds of driving (the 1 Hz car
    /// rows of models/reports/unmet.md at 2 m/s and faster lost to atan2 by up to 4%).
    /// Nearer the velocity before the glitch than the glitch came, it is taken; an
    /// epoch far from both is still gated.
    #[test]
    fn a_glitch_the_gate_took_does_not_hold_the_drive_after_it() {
        let after = |course: f32| {
            let mut st = StepState::fresh(Platform::Car);
            along(&mut st, 0.0, 196.0);
            for _ in 0..20 {
                along(&mut st, 6.7, 196.0);
            }
            along(&mut st, 2.0, 230.0);
            assert_eq!(st.skips, 0, "the slow glitch passes the gate: {st:?}");
            let psi = wrap_rad(along(&mut st, 6.8, course).psi).to_degrees();
            (psi, st.skips)
        };
        let (psi, skips) = after(196.0);
        assert_eq!(skips, 0, "the drive after the glitch is taken");
        let off = wrap_rad((psi - 196.0).to_radians()).to_degrees();
        assert!(off.abs() < 3.0, "{off}° off the course after the glitch");
        let (_, skips) = after(120.0);
        assert_eq!(skips, 1, "an epoch far from the drive is still gated");
    }

    /// A car standing at 21° creeps backwards, its course 187° off, at a speed just
    /// over three times its receiver's noise and under the motion bar (1 Hz, sAcc 0.1
    /// m/s): the small gain the course feeds the held heading with pulls it along the
    /// car's axis, not a fraction of the way across the half turn.
    #[test]
    fn a_standing_car_creeping_backwards_keeps_its_axis() {
        let mut st = StepState::fresh(Platform::Car);
        along(&mut st, 0.0, 21.0);
        for _ in 0..20 {
            along(&mut st, 8.0, 21.0);
        }
        for speed in [6.0, 4.0, 2.0, 1.0, 0.5] {
            along(&mut st, speed, 21.0);
        }
        for _ in 0..10 {
            along(&mut st, 0.05, 90.0);
        }
        assert!(st.car_stands(), "{st:?}");
        let d = along(&mut st, 0.35, 208.0);
        assert!(d.gain > 0.0, "the creep feeds the held heading: {d:?}");
        let off = wrap_rad(d.psi - 21f32.to_radians()).to_degrees();
        assert!(off.abs() < 2.0, "{off}° off the held heading: {st:?}");
    }

    /// A car standing at 84° reads, at 10 Hz, a glitch pair of 1 m/s along its axis
    /// backwards (confirmed and on the axis: taken for a back-out), then rest again,
    /// then a 4 m/s spike. The drop back to rest is braking ([`BRAKE_MAX`]), not a
    /// glitch. Bounded by `a_max`, the gate skipped it until `max_skips` ran out and
    /// then took the spike, a back-out at 4 m/s that turned the held heading by 70° (a
    /// simulated NMEA car, whose next departure was then held on the wrong heading).
    #[test]
    fn a_car_back_at_rest_after_a_glitch_pair_keeps_its_heading() {
        // One 10 Hz epoch of a receiver without sAcc: the answer.
        let at_10hz = |st: &mut StepState, speed: f32, course: f32| {
            epoch_dt(st, speed, course, f32::NAN, 0.1).0
        };
        let mut st = StepState::fresh(Platform::Car);
        at_10hz(&mut st, 0.0, 84.0);
        for _ in 0..80 {
            at_10hz(&mut st, 8.0, 84.0);
        }
        for k in (0..40).rev() {
            at_10hz(&mut st, 0.2 * k as f32, 84.0);
        }
        for k in 0..50 {
            at_10hz(&mut st, 0.05, 37.0 * k as f32);
        }
        at_10hz(&mut st, 0.98, 281.0);
        at_10hz(&mut st, 1.08, 270.0);
        for (speed, course) in [(0.15, 217.0), (0.15, 222.0), (0.21, 219.0)] {
            at_10hz(&mut st, speed, course);
            assert_eq!(st.skips, 0, "back at rest at {speed} m/s: {st:?}");
        }
        let mut psi = 0.0;
        for (speed, course) in [(4.01, 193.4), (0.15, 258.0), (0.15, 246.0), (0.1, 210.0)] {
            psi = at_10hz(&mut st, speed, course).psi;
        }
        let off = wrap_rad(psi - 84f32.to_radians()).to_degrees();
        assert!(off.abs() < 10.0, "{off}° off the held heading: {st:?}");
    }

    /// One 1 Hz epoch of a receiver without sAcc along `course` (degrees) at `speed`,
    /// filter alone: the answer in degrees.
    fn at_1hz(st: &mut StepState, speed: f32, course: f32) -> f32 {
        wrap_rad(epoch_dt(st, speed, course, f32::NAN, 1.0).0.psi).to_degrees()
    }

    /// A car slowing through 1.2 m/s at 1 Hz (no sAcc) whose receiver reads one epoch
    /// at 3 m/s a half turn off (within `a_max` of the epoch before): no car stops,
    /// changes gear and backs up that fast in a second ([`REVERSAL_MIN_SPEED`]), so
    /// the spike is a glitch and the heading stays. A car that stops first and then
    /// backs up along the same course is still answered reversing, along its body.
    #[test]
    fn a_reversed_spike_while_moving_is_a_glitch() {
        let mut st = StepState::fresh(Platform::Car);
        at_1hz(&mut st, 0.0, 50.0);
        for speed in [4.0, 6.0, 8.0, 8.0, 8.0, 8.0, 8.0, 6.0, 4.0, 2.0, 1.2, 1.2] {
            at_1hz(&mut st, speed, 50.0);
        }
        assert!(st.vehicle.car, "{st:?}");
        let psi = at_1hz(&mut st, 3.0, 230.0);
        assert_eq!(st.skips, 1, "the reversed spike is a glitch: {st:?}");
        assert!((psi - 50.0).abs() < 5.0, "turned by the spike: {psi}°");
        for _ in 0..3 {
            at_1hz(&mut st, 0.0, 50.0);
        }
        let mut psi = 0.0;
        for _ in 0..3 {
            psi = at_1hz(&mut st, 1.2, 230.0);
        }
        assert_eq!(st.skips, 0, "backing up after a stop is no glitch: {st:?}");
        assert!(st.reverse && (psi - 50.0).abs() < 10.0, "{psi}°: {st:?}");
    }

    /// A car parked at 50° on a 1 Hz receiver without sAcc reads two epochs at 4.8 m/s
    /// backwards along its axis (a glitch pair, which the stand's gate and the release
    /// rule take for a back-out), then rest: the stand gets its heading back
    /// ([`RELEASE_EPOCHS_OFF_AXIS`]). A back-out of four seconds at 1.2 m/s is final
    /// at once, answered along the body.
    #[test]
    fn a_backward_glitch_pair_does_not_turn_a_parked_car() {
        let parked = || {
            let mut st = StepState::fresh(Platform::Car);
            at_1hz(&mut st, 0.0, 50.0);
            for speed in [4.0, 6.0, 8.0, 8.0, 8.0, 8.0, 8.0, 6.0, 4.0, 2.0, 1.0] {
                at_1hz(&mut st, speed, 50.0);
            }
            for k in 0..20 {
                at_1hz(&mut st, 0.05, 37.0 * k as f32);
            }
            assert!(st.vehicle.car && st.car_stands(), "{st:?}");
            st
        };
        let mut st = parked();
        for _ in 0..2 {
            at_1hz(&mut st, 4.8, 230.0);
        }
        let mut psi = 0.0;
        for _ in 0..3 {
            psi = at_1hz(&mut st, 0.0, 0.0);
        }
        assert!(
            (psi - 50.0).abs() < 5.0,
            "{psi}° after the glitch pair: {st:?}"
        );
        let mut st = parked();
        for _ in 0..4 {
            at_1hz(&mut st, 1.2, 230.0);
        }
        assert!(st.before_release.is_none(), "the back-out is final: {st:?}");
        for _ in 0..3 {
            psi = at_1hz(&mut st, 0.0, 0.0);
        }
        assert!(
            (psi - 50.0).abs() < 10.0,
            "{psi}° after backing out: {st:?}"
        );
    }

    /// A car parked at 50° (1 Hz, no sAcc) for `stand` s reads a burst of three epochs
    /// at 1–1.4 m/s a quarter turn off its axis, then rest: after a long stand
    /// ([`LONG_STAND_S`]) the burst is too short to be final, and the car keeps its
    /// heading and stays a car; after a short one it has left (a creep's turn).
    #[test]
    fn a_burst_of_three_does_not_unmake_a_parked_car() {
        let after = |stand: usize| {
            let mut st = StepState::fresh(Platform::Auto);
            at_1hz(&mut st, 0.0, 50.0);
            for _ in 0..10 {
                at_1hz(&mut st, 8.0, 50.0);
            }
            for speed in [6.0, 4.0, 2.0, 1.0] {
                at_1hz(&mut st, speed, 50.0);
            }
            for k in 0..stand {
                at_1hz(&mut st, 0.05, 37.0 * k as f32);
            }
            assert!(st.vehicle.car && st.car_stands(), "{st:?}");
            for (speed, course) in [(0.95, 140.0), (1.4, 125.0), (1.05, 135.0)] {
                at_1hz(&mut st, speed, course);
            }
            let psi = at_1hz(&mut st, 0.05, 0.0);
            (psi, st.vehicle.car)
        };
        let (psi, car) = after(20);
        assert!(
            car && (psi - 50.0).abs() < 5.0,
            "long stand: {psi}°, car {car}"
        );
        let (psi, _) = after(5);
        assert!((psi - 50.0).abs() > 45.0, "short stand: {psi}°");
    }

    /// A car turning at 4.5 m/s whose receiver prints one 0.0 m/s epoch (a bad fix)
    /// did not stop: no car brakes that hard ([`BRAKE_MAX`]). Taken as a stop, the
    /// epoch started a stand that held the heading for a second of the turn.
    #[test]
    fn a_zero_epoch_at_speed_is_no_stop() {
        let mut st = StepState::fresh(Platform::Car);
        run(&mut st, 30, 4.5, 60.0);
        no_acc(&mut st, 0.0, 60.0);
        assert_eq!(st.skips, 1, "the zero epoch is a glitch: {st:?}");
        assert_eq!(st.t_still, 0.0, "no stand began: {st:?}");
        for k in 1..=10 {
            let course = 60.0 + 5.0 * k as f32;
            let (d, c) = no_acc(&mut st, 4.5, course);
            let off = wrap_rad(d.psi - c).to_degrees();
            assert!(off.abs() < 5.0, "epoch {k} of the turn: {off}° off: {st:?}");
        }
    }

    /// A car parked on a receiver that holds static (exact zeros at rest) whose
    /// receiver blips: pairs of epochs at 0.6 m/s 45° off its axis (within what the
    /// glitch gate lets a departure take) between its zeros. Its noise is a guess, so
    /// the blips are not motion: the held heading stays (fed with the gain their σ gave,
    /// they turn it 35° here). A departure at 1.5 m/s still leaves.
    #[test]
    fn blips_of_a_static_hold_receiver_do_not_turn_a_parked_car() {
        let mut st = StepState::fresh(Platform::Car);
        run(&mut st, 50, 5.0, 30.0);
        run(&mut st, 15, 0.0, 30.0);
        assert!(st.vehicle.holds_static() && st.car_stands(), "{st:?}");
        for _ in 0..10 {
            run(&mut st, 2, 0.6, 75.0);
            run(&mut st, 5, 0.0, 30.0);
        }
        let off = wrap_rad(st.psi - 30f32.to_radians()).to_degrees();
        assert!(
            off.abs() < 1.0,
            "blips turned the held heading by {off}°: {st:?}"
        );
        run(&mut st, 10, 1.5, 40.0);
        let off = wrap_rad(st.psi - 40f32.to_radians()).to_degrees();
        assert!(off.abs() < 3.0, "departed {off}° off its course: {st:?}");
    }

    /// A course that zig-zags ±15° about a straight line (a noisy receiver) reads as
    /// rates of ±150°/s; smoothed, they leave a few °/s of swing that a lead would turn
    /// into degrees of error. Shrunk by their scatter, the lead stays under half a degree.
    #[test]
    fn a_noisy_course_is_not_led() {
        let mut st = StepState::fresh(Platform::Robot);
        run(&mut st, 10, 0.0, 0.0);
        for k in 0..40 {
            let course = if k % 2 == 0 { 15.0 } else { -15.0 };
            let (d, _) = no_acc(&mut st, 1.5, course);
            if k >= 20 {
                let lead = wrap_rad(d.psi - st.psi).to_degrees();
                assert!(lead.abs() < 0.5, "epoch {k}: led by {lead}°: {st:?}");
            }
        }
    }

    /// A robot drives north at 1.5 m/s on a receiver with 0.25 m/s of noise per axis
    /// (its sAcc says so), the filter alone: RMS error (degrees) of the answers and of
    /// the courses over `n` epochs `dt` s apart, after a stand and two seconds of
    /// driving.
    fn noisy_robot_drive(mp: &ModeParams, dt: f32, n: usize) -> (f32, f32) {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let normal = rand_distr::Normal::new(0.0f32, 0.25).expect("a valid σ");
        let noise = |rng: &mut rand_chacha::ChaCha8Rng| rng.sample(normal);
        let mut st = StepState::fresh(Platform::Robot);
        let (mut sa, mut sc) = (0.0f32, 0.0f32);
        let settle = (2.0 / dt) as usize;
        for k in 0..10 + settle + n {
            let still = k < 10;
            let v = if still { 0.0 } else { 1.5 };
            let (vn, ve) = (v + noise(&mut rng), noise(&mut rng));
            let step = prepare(mp, 0.5, &mut st, vn, ve, 0.25, dt);
            let d = commit(&mut st, &step, &[0.0, 0.0, 0.0], dt);
            if k >= 10 + settle {
                sa += wrap_rad(d.psi).powi(2);
                sc += ve.atan2(vn).powi(2);
            }
        }
        let rms = |s: f32| (s / n as f32).sqrt().to_degrees();
        (rms(sa), rms(sc))
    }

    /// An `auto` vehicle at robot speeds (never a car) that drives, stands and drives
    /// off `off_deg` from the way it went, at 5 Hz with sAcc 0.05 m/s; then, when
    /// `burst`, a run of glitches as long as the release rule's second and under
    /// [`TURN_RUN_S`] instead of a departure: whether it was taken to turn in place.
    fn turned_in_place(off_deg: f32, burst: bool) -> StepState {
        let mut st = StepState::EMPTY;
        run_acc(&mut st, 10, 0.0, 0.0, 0.05);
        run_acc(&mut st, 25, 1.5, 0.0, 0.05);
        run_acc(&mut st, 10, 0.0, 0.0, 0.05);
        if burst {
            run_acc(&mut st, 8, 1.5, off_deg, 0.05);
            run_acc(&mut st, 20, 0.0, 0.0, 0.05);
        } else {
            run_acc(&mut st, 20, 1.5, off_deg, 0.05);
        }
        st
    }

    /// A vehicle that leaves a stand off the axis it stood on, and keeps going, turned in
    /// place: an `auto` vehicle not known to be a car is then answered as a robot at its
    /// stands (a steady creep gives its course). Leaving along the axis, backing up, or
    /// a glitch burst off it, shows nothing.
    #[test]
    fn a_departure_off_the_axis_shows_a_turn_in_place() {
        let mp = ModeParams::default();
        let creep = ([0.0, 0.3], [0.0, 0.3]);
        for (off, burst, turns) in [
            (90.0, false, true),
            (-60.0, false, true),
            (10.0, false, false),
            (180.0, false, false),
            (90.0, true, false),
        ] {
            let st = turned_in_place(off, burst);
            let what = format!("{off}° off, burst {burst}: {st:?}");
            assert!(!st.vehicle.car, "{what}");
            assert_eq!(st.vehicle.turns, turns, "{what}");
            let answered =
                stationary_course(&mp, &st.vehicle, creep.0, creep.1, 0.05, 0.2, f32::NAN);
            assert_eq!(answered, turns, "{what}");
        }
    }

    /// A robot's creep in an arc may turn its course by 50° between two epochs a second
    /// apart and is answered with its course; 0.2 s apart, 50° is no creep's turn. A
    /// velocity that reverses between epochs never is.
    #[test]
    fn a_robots_creep_may_turn_between_slow_epochs() {
        let mp = ModeParams::default();
        let robot = StepState::fresh(Platform::Robot).vehicle;
        let (s, c) = 50f32.to_radians().sin_cos();
        let (before, now) = ([0.3, 0.0], [0.3 * c, 0.3 * s]);
        assert!(stationary_course(
            &mp,
            &robot,
            now,
            before,
            0.05,
            1.0,
            f32::NAN
        ));
        assert!(!stationary_course(
            &mp,
            &robot,
            now,
            before,
            0.05,
            0.2,
            f32::NAN
        ));
        assert!(!stationary_course(
            &mp,
            &robot,
            [-0.3, 0.0],
            before,
            0.05,
            1.0,
            f32::NAN
        ));
    }

    /// On a receiver that reports 0.3 m/s as sAcc but has shown 0.1 m/s of noise per
    /// axis at rest, a steady creep at 0.2 m/s is answered with its course by a
    /// declared robot and by an `auto` vehicle seen to turn in place alike (by the
    /// reported sAcc, under its bar), and not by an `auto` vehicle not seen to turn.
    #[test]
    fn a_creep_under_a_pessimistic_sacc_is_answered_once_the_robot_turned() {
        let mp = ModeParams::default();
        let (before, now) = ([0.2, 0.0], [0.2, 0.01]);
        for (platform, turns, answered) in [
            (Platform::Robot, false, true),
            (Platform::Auto, true, true),
            (Platform::Auto, false, false),
        ] {
            let mut vehicle = StepState::fresh(platform).vehicle;
            vehicle.turns = turns;
            vehicle.noise = 0.1 * mp.quantile_factor();
            let got = stationary_course(&mp, &vehicle, now, before, 0.3, 0.2, f32::NAN);
            assert_eq!(got, answered, "{platform}, turns {turns}");
        }
    }

    /// An `auto` vehicle known to be neither a car nor a robot, standing on the heading
    /// it drove north with, answers a steady creep at 0.3 m/s with its course when it
    /// points east or north-west (a turn since, which no car makes standing), not when
    /// it runs along its axis either way (a car's creep or back-up), nor one under
    /// [`AUTO_CREEP_MIN_SPEED`], nor before the history moved (`held` NaN), nor once
    /// the vehicle is known to be a car.
    #[test]
    fn an_auto_vehicles_creep_off_its_held_axis_is_answered() {
        let mp = ModeParams::default();
        let mut vehicle = StepState::fresh(Platform::Auto).vehicle;
        vehicle.noise = 0.02 * mp.quantile_factor();
        let at = |deg: f32, speed: f32| {
            let (s, c) = deg.to_radians().sin_cos();
            [speed * c, speed * s]
        };
        let north = 0.0f32;
        for (deg, speed, held, answered) in [
            (90.0, 0.3, north, true),
            (-50.0, 0.3, north, true),
            (20.0, 0.3, north, false),
            (180.0, 0.3, north, false),
            (90.0, 0.08, north, false),
            (90.0, 0.3, f32::NAN, false),
        ] {
            let v = at(deg, speed);
            let got = stationary_course(&mp, &vehicle, v, v, 0.05, 0.2, held);
            assert_eq!(
                got, answered,
                "creep at {deg}° and {speed} m/s, held {held}"
            );
        }
        let mut car = vehicle;
        car.car = true;
        let v = at(90.0, 0.3);
        assert!(!stationary_course(&mp, &car, v, v, 0.05, 0.2, north));
    }

    /// A robot whose slow speeds read 0.3 m/s of noise at rest (its creeps lift that
    /// quantile over the noise itself) on a receiver reporting 0.5 m/s as sAcc answers
    /// a steady creep at 0.25 m/s with its course once enough slow epochs have shown
    /// that noise, and so it does on a receiver that holds static and reports 0.3 m/s; a
    /// creep at 0.15 m/s, under [`ROBOT_REST_NOISE_SHARE`] of either, it does not.
    /// Before those epochs the bar is the noise at rest whole.
    #[test]
    fn a_robots_steady_creep_over_the_noise_it_showed_is_answered() {
        let mp = ModeParams::default();
        let mut fresh = StepState::fresh(Platform::Robot).vehicle;
        fresh.noise = 0.3 * mp.quantile_factor();
        let mut seen = fresh;
        seen.acc_ratio_n = ACC_RATIO_MIN_EPOCHS;
        let mut holding = fresh;
        holding.zeros = HOLD_MIN_ZEROS;
        assert!(holding.holds_static() && !seen.holds_static());
        for (vehicle, acc, over) in [(seen, 0.5, true), (holding, 0.3, true), (fresh, 0.5, false)] {
            for (speed, answered) in [(0.25, over), (0.15, false)] {
                let (before, now) = ([speed, 0.0], [speed, 0.01]);
                let got = stationary_course(&mp, &vehicle, now, before, acc, 0.2, f32::NAN);
                let what = format!("sAcc {acc}, {} slow epochs", vehicle.acc_ratio_n);
                assert_eq!(got, answered, "{what}, creep at {speed} m/s");
            }
        }
    }

    /// The sAcc scale ([`Vehicle::acc_scale`]) and the noise at rest of a receiver
    /// with 0.1 m/s of noise per axis and sAcc `acc`, after `cycles` of a 20 s stand
    /// and a `creep_s` creep at 0.35 m/s, at 5 Hz.
    fn sacc_scale_after(cycles: usize, creep_s: usize, acc: f32) -> (f32, f32) {
        use rand::{Rng, SeedableRng};
        let mp = ModeParams::default();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let normal = rand_distr::Normal::new(0.0f32, 0.1).expect("a valid σ");
        let mut v = Vehicle::UNKNOWN;
        let creep = 5 * creep_s;
        for k in 0..cycles * (100 + creep) {
            let base = if k % (100 + creep) < 100 { 0.0 } else { 0.35 };
            let (n, e) = (base + rng.sample(normal), rng.sample(normal));
            noise::update_noise(&mp, &mut v, n.hypot(e), acc);
        }
        (v.acc_scale(), mp.rest_noise(&v))
    }

    /// The sAcc scale reads a receiver's pessimism at its stands (three times its
    /// noise: a third; honest: about one). Through a robot's 12 s creeps after each
    /// stand it reads the pessimist under [`PESSIMISTIC_SACC_RATIO`] still, half as
    /// inflated as the noise at rest, which more than doubles; before
    /// [`ACC_RATIO_MIN_EPOCHS`] it is 1.
    #[test]
    fn the_sacc_scale_reads_the_stand_through_creeps() {
        let (x3, _) = sacc_scale_after(3, 0, 0.3);
        assert!((0.25..0.45).contains(&x3), "sAcc × 3: {x3}");
        let (honest, _) = sacc_scale_after(3, 0, 0.1);
        assert!((0.75..1.3).contains(&honest), "honest: {honest}");
        let (crept, rest) = sacc_scale_after(5, 12, 0.3);
        assert!(crept * PESSIMISTIC_SACC_RATIO < 1.0, "creeping: {crept}");
        assert!(rest > 0.2, "the noise at rest through creeps: {rest}");
        assert!(3.0 * crept < 0.7 * rest / 0.1, "{crept} against {rest}");
        let mut v = Vehicle::UNKNOWN;
        let mp = ModeParams::default();
        for _ in 1..ACC_RATIO_MIN_EPOCHS {
            noise::update_noise(&mp, &mut v, 0.01, 0.3);
        }
        assert_eq!(v.acc_scale(), 1.0);
    }

    /// A moving platform does not spin, so at 5 Hz its filter averages successive
    /// courses ([`ModeParams::q_move_deg`]) instead of following each one with its
    /// noise, as it did with the spin's walk (`q_tip_deg`); at 1 Hz, where a robot's
    /// turn between two courses outruns any walk, it follows them as before.
    #[test]
    fn a_moving_robot_averages_its_courses_at_5hz() {
        let mp = ModeParams::default();
        let (answer, course) = noisy_robot_drive(&mp, 0.2, 300);
        assert!(
            answer < 0.85 * course,
            "answers {answer}° against courses {course}°"
        );
        let spin = ModeParams {
            q_move_deg: mp.q_tip_deg,
            ..mp
        };
        let (followed, _) = noisy_robot_drive(&spin, 0.2, 300);
        assert!(
            followed > 0.9 * course,
            "the spin's walk: {followed}° against {course}°"
        );
        let (at_1hz, course_1hz) = noisy_robot_drive(&mp, 1.0, 100);
        assert!(
            at_1hz > 0.9 * course_1hz,
            "1 Hz: {at_1hz}° against {course_1hz}°"
        );
    }

    /// A car parked after driving at 40°, the network's `y₂` at its last moving epoch
    /// `held_y2`, on a noisy receiver (0.3 m/s per axis at rest, 300 epochs of it),
    /// then driving off on `course` (degrees, jittered) at 1.1–1.3 m/s, under four
    /// times its noise on every other epoch: the departure epoch the stand is released
    /// on, if within 15.
    fn noisy_departure(seed: u64, held_y2: f32, course: f32) -> Option<usize> {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let mut st = StepState::fresh(Platform::Car);
        run(&mut st, 30, 10.0, 40.0);
        st.held_y2 = held_y2;
        run(&mut st, 10, 0.0, 40.0);
        for _ in 0..300 {
            let (n, e): (f32, f32) = (rng.random_range(-0.52..0.52), rng.random_range(-0.52..0.52));
            no_acc(&mut st, n.hypot(e), e.atan2(n).to_degrees());
        }
        assert!(!st.released(), "released at rest: {st:?}");
        (0..15).find(|&k| {
            let speed = if k % 2 == 0 { 1.3 } else { 1.1 };
            no_acc(&mut st, speed, course + if k % 3 == 0 { 4.0 } else { -3.0 });
            st.released()
        })
    }

    /// A parked car on a noisy receiver drives off along its body ([`noisy_departure`]):
    /// along the sure held heading's axis [`RELEASE_NOISE_K_AXIS`] times the noise is
    /// motion, so the stand ends within about a second instead of holding the
    /// departure for as long as it dips.
    #[test]
    fn a_noisy_car_driving_off_along_its_body_is_released() {
        let k =
            noisy_departure(3, 0.0, 40.0).expect("a departure along the body was never released");
        assert!(k <= 6, "released on departure epoch {k}");
    }

    /// The same, but the network doubted the stop (its `y₂` puts the held σ past
    /// [`UNSURE_HELD_DEG`]) and the car drives off 60° from the held heading: an unsure
    /// stand guards nothing, so [`RELEASE_NOISE_K_AXIS`] times the noise is motion in
    /// any direction and the stand ends within about a second; at four times the noise,
    /// the dips to 1.1 m/s held it for as long as the departure lasted.
    #[test]
    fn a_noisy_car_leaving_an_unsure_stand_is_released() {
        let k = noisy_departure(5, 4.0, 100.0)
            .expect("a departure from an unsure stand was never released");
        assert!(k <= 6, "released on departure epoch {k}");
    }
}
