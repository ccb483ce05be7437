//! The recurrent state of one history and one epoch's step before the network's
//! corrections.

use super::approach::Approach;
use super::vehicle::{Platform, Vehicle};

/// The recurrent state one step reads and writes. Public for the lab's training, which
/// records it from recurrent runs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepState {
    /// Previous heading, radians (not wrapped).
    pub psi: f32,
    /// Previous `log σ` of the filter (σ in radians; the prior variance is `σ² + q²dt`).
    pub log_sigma: f32,
    /// Whether `psi` exists (false on the first epoch of a history).
    pub has_prior: bool,
    /// Seconds since the last moving epoch.
    pub t_still: f32,
    /// Seconds in the current mode while moving.
    pub t_mode: f32,
    /// Reversing (course = heading + 180°).
    pub reverse: bool,
    /// Whether the history has started: its first epoch the tuned `kf` would use, or
    /// [`START_S`] of steady slow motion (a vehicle not known to be a car).
    ///
    /// [`START_S`]: crate::modes::START_S
    pub moved: bool,
    /// Seconds of steady slow motion before the start (see [`START_S`]).
    ///
    /// [`START_S`]: crate::modes::START_S
    pub start_s: f32,
    /// Course of that motion (following its epochs over about a second), radians;
    /// NaN when none.
    pub start_course: f32,
    /// Epochs in a row that did not continue that motion.
    pub start_skips: u8,
    /// Seconds continuously above `fast_speed`.
    pub t_fast: f32,
    /// Epochs continuously above `fast_speed`.
    pub n_fast: u16,
    /// Previous epoch's speed, m/s.
    pub prev_speed: f32,
    /// Last velocity the filter used (north, east), for the glitch gate; NaN when none.
    pub prev_v: [f32; 2],
    /// The velocity the filter used before `prev_v` (north, east), NaN when none: the
    /// glitch gate's second reference, which tells a glitch it let through from the
    /// motion that follows it.
    pub prev_v0: [f32; 2],
    /// Seconds from the velocity in `prev_v0` to the one in `prev_v`.
    pub gap0: f32,
    /// Epochs ignored as glitches in a row.
    pub skips: u8,
    /// Seconds since the velocity in `prev_v` (the glitch gate's elapsed time).
    pub t_used: f32,
    /// A standing car's last rejected moving velocity, which the next epoch must
    /// confirm; NaN when none.
    pub pending_v: [f32; 2],
    /// The network's σ correction (`y₂`, log units) at the last moving epoch: a
    /// standing car's held heading keeps the uncertainty it stopped with, the network's
    /// share of it included (a car that stopped out of a slow turn or a parking
    /// manoeuvre holds a poorer heading than one that braked on a straight road).
    pub held_y2: f32,
    /// Whether the receiver was [`clean`] at the last moving epoch: a stop keeps the
    /// σ map it started with, so the noise measured during the stop cannot make a held
    /// σ jump down.
    ///
    /// [`clean`]: crate::modes::clean
    pub held_clean: bool,
    /// Yaw rate of the heading while moving, rad/s: the heading's change per second
    /// over moving epochs, smoothed over [`YAW_TAU_S`]; 0 while standing. A turn is
    /// where a receiver's lag (course trailing heading by ω·τ) and the antenna's
    /// lever arm show, so a moving epoch's σ grows with it ([`SigmaMaps::yaw_s`]).
    ///
    /// [`YAW_TAU_S`]: crate::modes::YAW_TAU_S
    /// [`SigmaMaps::yaw_s`]: crate::modes::SigmaMaps::yaw_s
    pub yaw: f32,
    /// The yaw rate smoothed over [`LEAD_YAW_TAU_S`] (rad/s; 0 while standing): what the
    /// answered heading leads a lagging receiver's course by ([`Step::lead_s`]). Slower
    /// than `yaw`: differencing a noisy course is what makes extrapolation worse.
    ///
    /// [`LEAD_YAW_TAU_S`]: crate::modes::LEAD_YAW_TAU_S
    pub turn: f32,
    /// Mean square (rad²/s²) of the moving epochs' yaw rates around `turn`, smoothed
    /// alike: how noisy `turn` is, so the lead can fade where the course is noise.
    pub turn_var: f32,
    /// The run of plain motion on a steady course up to this epoch (speed at least
    /// [`RELEASE_SPEED`] and `3·sAcc`, course within [`RELEASE_COURSE_DEG`] of the run's
    /// last epoch), none when this epoch is not plain motion: the release rule's clock.
    ///
    /// [`RELEASE_SPEED`]: crate::modes::RELEASE_SPEED
    /// [`RELEASE_COURSE_DEG`]: crate::modes::RELEASE_COURSE_DEG
    pub motion: MotionRun,
    /// The run the epochs skipped from `motion` since its last steady epoch form (a
    /// departure right after a glitch burst), which takes over from it; right after it
    /// has, the run it displaced (a departure a glitch burst cut into), which takes
    /// over again if the burst ends there.
    pub motion_alt: MotionRun,
    /// Unsteady epochs skipped since (glitches inside a departure), at most `max_skips`.
    pub motion_skips: u8,
    /// What a car's stand held while a short run off its axis has released it.
    pub before_release: Option<HeldHeading>,
    /// Whether the last used epoch was driving (in a second of steady motion,
    /// [`StepState::released`]): the glitch gate's braking bound applies only then,
    /// when its reference velocity was driven, not a glitch burst's.
    pub driving: bool,
    /// Metres driven since the last stand (moving, non-glitch epochs), while the
    /// sense of travel is not yet known ([`SENSE_RUN_M`]).
    ///
    /// [`SENSE_RUN_M`]: crate::modes::SENSE_RUN_M
    pub run_m: f32,
    /// Whether the history has shown which way the vehicle faces: it drove faster than
    /// a car reverses (`escape_speed` and the receiver's noise,
    /// [`ESCAPE_NOISE_K`]), or [`SENSE_RUN_M`] without a stand, longer
    /// than a back-out. Until then a car may be backing out of a space, and its
    /// answer's σ covers the half turn ([`SENSE_SIGMA_DEG`]).
    ///
    /// [`SENSE_RUN_M`]: crate::modes::SENSE_RUN_M
    /// [`SENSE_SIGMA_DEG`]: crate::modes::SENSE_SIGMA_DEG
    /// [`ESCAPE_NOISE_K`]: crate::modes::ESCAPE_NOISE_K
    pub sense_known: bool,
    /// Whether a vehicle not known to be a car left its last stand against the heading
    /// it held there (further off than `flip_stop_deg`), and has not since driven
    /// [`SENSE_RUN_M`] or faster than `escape_speed`: it may be backing up, or driving
    /// off after turning in place, and its velocity cannot say which. A car in that
    /// case flips its mode; a platform answers its course, and its σ covers the half
    /// turn ([`SENSE_SIGMA_DEG`]) as for a history whose sense is unknown.
    ///
    /// [`SENSE_RUN_M`]: crate::modes::SENSE_RUN_M
    /// [`SENSE_SIGMA_DEG`]: crate::modes::SENSE_SIGMA_DEG
    pub sense_doubt: bool,
    /// The car's approach to a stop: its driving answers of the last [`APPROACH_S`],
    /// whose mean a stop starting now holds ([`Approach::take`]).
    ///
    /// [`APPROACH_S`]: crate::modes::APPROACH_S
    pub approach: Approach,
    /// The heading (radians) held before the last fix gap emptied the history; NaN
    /// when none. After an outage the vehicle may have turned anywhere, so nothing is
    /// held from it (the answer's σ is the uniform one), but a car that stands after
    /// the gap most likely still faces about where it did: its `Stationary` answers
    /// give that heading, not the first course of its receiver's noise, until its
    /// course carries information. (A platform may have turned in place.)
    pub stale_psi: f32,
    /// The heading (radians) an `auto` vehicle not known to be a car drove on, sure
    /// ([`TURN_SURE_DEG`]), at the last epoch of a run of steady motion at least
    /// [`TURN_RUN_S`] long; NaN when none or not sure. Kept through a stand, it is what
    /// the departure is compared with ([`Vehicle::turns`]).
    ///
    /// [`TURN_SURE_DEG`]: crate::modes::TURN_SURE_DEG
    /// [`TURN_RUN_S`]: crate::modes::TURN_RUN_S
    pub stand_psi: f32,
    /// Whether the vehicle has stood [`TURN_STAND_S`] since `stand_psi`, its departure
    /// not yet compared.
    ///
    /// [`TURN_STAND_S`]: crate::modes::TURN_STAND_S
    pub stood: bool,
    /// Whether the departure after that stand left off the axis of `stand_psi`, not
    /// yet confirmed by [`TURN_RUN_S`] of steady motion.
    ///
    /// [`TURN_RUN_S`]: crate::modes::TURN_RUN_S
    pub turn_seen: bool,
    /// The vehicle and its receiver.
    pub vehicle: Vehicle,
    /// A car not driving: its velocity (north, east; m/s) averaged over
    /// [`STAND_DOUBT_TAU_S`], each epoch's speed clipped ([`stand_doubt`]); zero
    /// otherwise.
    ///
    /// [`STAND_DOUBT_TAU_S`]: crate::modes::STAND_DOUBT_TAU_S
    /// [`stand_doubt`]: crate::modes::stand_doubt
    pub stand_v: [f32; 2],
    /// Its square speed averaged alike (m²/s²; NaN until the average starts, then
    /// starting from the noise's `2σ_v²`): how steady `stand_v` is.
    pub stand_p: f32,
    /// The course (radians) `stand_v` last showed motion on in this stand, NaN when
    /// none: a car moves along its axis, so one off the held heading's says the car
    /// has turned.
    pub stand_axis: f32,
}

impl StepState {
    /// The state of an empty history.
    pub const EMPTY: StepState = StepState {
        psi: 0.0,
        log_sigma: 0.0,
        has_prior: false,
        t_still: 0.0,
        t_mode: 0.0,
        reverse: false,
        moved: false,
        start_s: 0.0,
        start_course: f32::NAN,
        start_skips: 0,
        t_fast: 0.0,
        n_fast: 0,
        prev_speed: 0.0,
        prev_v: [f32::NAN; 2],
        prev_v0: [f32::NAN; 2],
        gap0: 0.0,
        skips: 0,
        t_used: 0.0,
        pending_v: [f32::NAN; 2],
        held_y2: 0.0,
        held_clean: false,
        yaw: 0.0,
        turn: 0.0,
        turn_var: 0.0,
        motion: MotionRun::NONE,
        motion_alt: MotionRun::NONE,
        motion_skips: 0,
        before_release: None,
        driving: false,
        run_m: 0.0,
        sense_known: false,
        sense_doubt: false,
        approach: Approach::EMPTY,
        stale_psi: f32::NAN,
        stand_psi: f32::NAN,
        stood: false,
        turn_seen: false,
        vehicle: Vehicle::UNKNOWN,
        stand_v: [0.0; 2],
        stand_p: f32::NAN,
        stand_axis: f32::NAN,
    };

    /// An empty history of a source on `platform`.
    pub fn fresh(platform: Platform) -> StepState {
        let mut st = Self::EMPTY;
        st.vehicle.platform = platform;
        st.vehicle.car = platform == Platform::Car;
        st
    }

    /// Whether the last epoch moved (its clock of time stopped is at zero): the one
    /// definition that picks the moving σ maps, records what a stop will hold
    /// (`held_y2`, `held_clean`) and sorts epochs when the maps are fitted. A glitch
    /// leaves it as it was.
    #[inline]
    pub fn moving_now(&self) -> bool {
        self.t_still == 0.0
    }

    /// Whether this is a car standing (time has passed since its last moving epoch):
    /// the stand the glitch gate, the release rule and an off-axis release act on.
    #[inline]
    pub fn car_stands(&self) -> bool {
        self.vehicle.car && self.t_still > 0.0
    }

    /// The heading an epoch starts from: the history's; on its first epoch the course
    /// (`kf`'s convention), or, after a fix gap, the heading before it
    /// ([`StepState::stale_psi`]) while `course_is_noise`.
    pub fn prior(&self, course: f32, course_is_noise: bool) -> f32 {
        if self.has_prior {
            self.psi
        } else if course_is_noise && self.stale_psi.is_finite() {
            self.stale_psi
        } else {
            course
        }
    }

    /// An empty history that keeps what it knew about the vehicle (after a fix gap),
    /// and its heading as [`StepState::stale_psi`].
    pub fn after_gap(&self) -> StepState {
        StepState {
            vehicle: self.vehicle,
            stale_psi: if self.has_prior {
                self.psi
            } else {
                self.stale_psi
            },
            ..Self::EMPTY
        }
    }
}

/// One epoch's filter step before the network's corrections: what [`commit`] needs and
/// what the network's inputs describe.
///
/// [`commit`]: crate::modes::commit
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Step {
    /// Course atan2(v_E, v_N), radians.
    pub course: f32,
    /// Heading the step starts from (after the rules' direction changes), radians.
    pub prior: f32,
    /// Prior variance, radians².
    pub p: f32,
    /// Measurement variance, radians² (the uniform cap when the velocity is noise).
    pub r2: f32,
    /// Kalman gain `P/(P + R²)`; 0 when the measurement carries nothing or is a glitch.
    pub k: f32,
    /// The rule's mode for this epoch.
    pub rule_reverse: bool,
    /// The epoch moves (measurement σ under `moving_r`).
    pub moving: bool,
    /// Before the first motion: answer the prior with the uniform σ (the `kf` convention).
    pub hold: bool,
    /// The glitch gate rejected this epoch.
    pub glitch: bool,
    /// Velocity noise σ used, m/s.
    pub sigma_v: f32,
    /// Speed, m/s.
    pub speed: f32,
    /// The receiver reported a speed accuracy (sAcc) with this epoch.
    pub has_acc: bool,
    /// The sAcc (m/s) the rules that decide whether the vehicle moves went by
    /// ([`ModeParams::trusted_acc`]); NaN when none was reported.
    ///
    /// [`ModeParams::trusted_acc`]: crate::modes::ModeParams::trusted_acc
    pub acc: f32,
    /// The receiver's course lag (s) the answer leads by ([`ModeParams::lead_s`]).
    ///
    /// [`ModeParams::lead_s`]: crate::modes::ModeParams
    pub lead_s: f32,
    /// A car's lever arm over its speed (s; 0 for other vehicles): turning at yaw rate
    /// ω, the antenna's course leads the heading by `atan(ω·lever_s)` (trails it
    /// reversing), which the answer takes out; faded with speed where a receiver's
    /// lag may outweigh it ([`ModeParams::lever_m`]).
    ///
    /// [`ModeParams::lever_m`]: crate::modes::ModeParams
    pub lever_s: f32,
    /// `ω·lever_s` a car can reach (`k_max·L`, faded alike): a car turns no tighter
    /// than it steers, so a larger product is capped and, from twice it, read as
    /// not a car's turn (a robot spinning, a noisy crawl) and not corrected.
    pub lever_max: f32,
}

impl Step {
    /// A step that holds `prior` with the uniform variance `cap2` (what an epoch is
    /// until the filter finds it moves): no gain, no mode, no lead. `acc` is the sAcc the
    /// rules go by, NaN when none was reported.
    pub(crate) fn holding(course: f32, prior: f32, cap2: f32, speed: f32, acc: f32) -> Step {
        Step {
            course,
            prior,
            p: cap2,
            r2: cap2,
            k: 0.0,
            rule_reverse: false,
            moving: false,
            hold: true,
            glitch: false,
            sigma_v: f32::NAN,
            speed,
            has_acc: acc.is_finite(),
            acc,
            lead_s: 0.0,
            lever_s: 0.0,
            lever_max: 0.0,
        }
    }
}

/// A run of plain motion on a steady course (at least [`RELEASE_SPEED`] and `3·sAcc`,
/// course within [`RELEASE_COURSE_DEG`] of the run's last epoch): the release rule's
/// clock ([`StepState::motion`]).
///
/// [`RELEASE_SPEED`]: crate::modes::RELEASE_SPEED
/// [`RELEASE_COURSE_DEG`]: crate::modes::RELEASE_COURSE_DEG
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MotionRun {
    /// Seconds of the run up to its last epoch (0 at its first; skipped epochs' time
    /// does not count).
    pub t: f32,
    /// Epochs in the run; 0 for no run.
    pub n: u16,
    /// Velocity (north, east; m/s) of the run's last epoch.
    pub v: [f32; 2],
    /// Seconds since that epoch.
    pub since: f32,
    /// Whether every epoch of the run lay along the axis of a sure held heading (true
    /// when the heading was not sure).
    pub on_axis: bool,
}

impl MotionRun {
    /// No run.
    pub const NONE: MotionRun = MotionRun {
        t: 0.0,
        n: 0,
        v: [0.0; 2],
        since: 0.0,
        on_axis: true,
    };
}

/// What a car's stand held when a short run off its axis (or backwards) released it
/// ([`StepState::before_release`]): back in place if the run ends at once (a glitch
/// burst at rest), forgotten once the run reaches [`HeldHeading::epochs`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HeldHeading {
    /// Held heading, radians.
    pub psi: f32,
    /// Its `log σ`.
    pub log_sigma: f32,
    /// Its mode (reversing).
    pub reverse: bool,
    /// Epochs of the run that make the release final ([`RELEASE_EPOCHS_OFF_AXIS`], or
    /// [`RELEASE_EPOCHS_LONG_STAND`] after a long stand).
    ///
    /// [`RELEASE_EPOCHS_OFF_AXIS`]: crate::modes::RELEASE_EPOCHS_OFF_AXIS
    /// [`RELEASE_EPOCHS_LONG_STAND`]: crate::modes::RELEASE_EPOCHS_LONG_STAND
    pub epochs: u16,
}
