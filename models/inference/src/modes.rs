//! The mode filter: the deterministic half of the temporal model, a circular Kalman
//! filter that knows how vehicles move.
//!
//! A plain Kalman filter on atan2 treats every course as the heading. Vehicles break
//! that in three ways, and each has a physical rule here:
//!
//! * **Cars back up.** After a stop, a car moves off either along its held heading or
//!   opposite to it; opposite means reversing (course = heading + 180°), not a 180° turn.
//!   The filter keeps a *mode* (forward or reversing) and measures `course + π·mode`.
//!   Two escapes keep a wrong mode from lasting: a car never reverses at sustained speed
//!   (above `escape_speed`, the mode ends and the heading turns by 180°), and a vehicle
//!   that has not yet shown car-like speed has no reverse mode at all (next point).
//! * **Cars do not turn in place; platforms do.** A vehicle counts as a car once it has
//!   driven above `fast_speed` for `fast_secs` and `FAST_EPOCHS` epochs (kept across fix gaps: it is the same
//!   vehicle). Until then it is treated as a platform that turns in place: its heading
//!   random-walks while it stands (`q_tip`), there is no reverse mode, and slow motion is
//!   trusted. A car's heading random-walks only with distance driven, as much as its
//!   steering allows (`k_max`, `a_lat`), so a stopped car holds its heading exactly.
//! * **Receivers lie.** The measurement σ is the receiver's noise over the speed, with
//!   the noise taken as the larger of the reported sAcc and a running estimate from the
//!   speeds the receiver reports when slow (a low quantile: a stopped vehicle's speed is
//!   pure noise). At speed, a velocity change a car cannot make in `dt` (over
//!   `a_max·dt`) is a glitch and is not used (at most `max_skips` in a row).
//! * **A standing car stays put.** Its epochs within the noise (under 3σ) feed nothing
//!   (no gain, no steering noise); it leaves rest only on a velocity reachable from rest since
//!   the last used epoch, confirmed by the next epoch, and (for `axis_secs`) along the
//!   axis of a sure held heading. On the simulator's validation cars this took the
//!   standing epochs' error from a median of 4.1° and a 90th percentile of 43° to
//!   2.75° and 12° (shipped model): most of it had been glitches and noise turning a
//!   parked car.
//!
//! Until the history's first epoch that the tuned `kf` would use (its measurement gate
//! `σ_v/ŝ` below the uniform σ), the model answers exactly what `kf` answers: the first
//! epoch's course with the uniform σ. Nothing knows a parked car's heading; both share
//! one convention there, so comparisons measure what happens after the first motion.
//!
//! The network ([`crate::stream`]) corrects this filter: `y₀` the gain in log-odds,
//! `y₁` the reverse decision as a logit around the rule's (`±REVERSE_PRIOR`), `y₂` the
//! reported `log σ`. Zero outputs are exactly the mode filter.

use serde::{Deserialize, Serialize};

use crate::head::{wrap_rad, MAX_STD_DEG};

/// Logit the rule's reverse decision contributes (`+` reversing, `−` forward): the
/// network overrides the rule only when its own logit outweighs this.
pub const REVERSE_PRIOR: f32 = 4.0;

/// Time constant of the yaw rate's smoothing, s ([`StepState::yaw`]): long enough
/// that a 10 Hz receiver's course noise does not read as turning, short enough to
/// follow a junction turn (a few seconds).
pub const YAW_TAU_S: f32 = 1.0;

/// Speed (m/s) from which a moving epoch's σ gets the turn term
/// ([`SigmaMaps::yaw_s`]). Below it the speed sets the error and the first map's σ is
/// nearly flat in the raw σ, so a second map over both would mix slow epochs with
/// turns at speed (on simulated cars at 0.5–2 m/s that cost 4–8 points within 1σ).
pub const TURN_SPEED: f32 = 2.0;

/// Fewest epochs above `fast_speed` that make a vehicle a car.
pub const FAST_EPOCHS: u16 = 5;

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

/// What carries the receiver: whether the mode filter may take it for a car, and
/// whether it may turn in place. Set per source; `Auto` decides online.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Platform {
    /// Decide online: a vehicle that drives fast for a while is a car until it leaves a
    /// stand sideways (it turned in place).
    #[default]
    Auto,
    /// A car, truck or van: reverses, never turns in place, holds its heading at a stop.
    Car,
    /// A robot or other platform that turns in place (and may reverse): a stop holds
    /// nothing, its heading follows the course once it moves.
    Robot,
}

impl Platform {
    /// The lowercase name (`auto`, `car`, `robot`) used in configs and flags.
    pub fn as_str(&self) -> &'static str {
        match self {
            Platform::Auto => "auto",
            Platform::Car => "car",
            Platform::Robot => "robot",
        }
    }
}

impl std::fmt::Display for Platform {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

impl std::str::FromStr for Platform {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "auto" => Ok(Platform::Auto),
            "car" => Ok(Platform::Car),
            "robot" => Ok(Platform::Robot),
            other => Err(format!("unknown platform `{other}` (auto, car or robot)")),
        }
    }
}

/// The mode filter's constants (stored in the model's metadata).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ModeParams {
    /// Heading random walk of a standing car, °/√s (small: cars do not turn in place).
    pub q_still_deg: f32,
    /// Heading random walk of a platform that turns in place, °/√s.
    pub q_tip_deg: f32,
    /// Largest path curvature a car steers, 1/m (the heading noise at low speed).
    pub k_max: f32,
    /// Largest lateral acceleration, m/s² (the heading noise at speed: `a_lat/ŝ`).
    pub a_lat: f32,
    /// Smallest velocity noise σ, m/s.
    pub sigma_floor: f32,
    /// A car's velocity noise σ when the receiver reports no sAcc (NMEA), m/s.
    pub sigma_none: f32,
    /// Multiplier on sAcc for a car's σ.
    pub acc_k: f32,
    /// Multiplier on the running noise estimate for a car's σ.
    pub noise_k: f32,
    /// Quantile of slow speeds the noise estimate tracks.
    pub noise_quantile: f32,
    /// Step of the noise estimate (log units per epoch).
    pub noise_rate: f32,
    /// Speeds below this (m/s) feed the noise estimate.
    pub noise_speed: f32,
    /// Multiplier on sAcc for a platform's σ.
    pub tip_acc_k: f32,
    /// A platform's σ without sAcc, m/s.
    pub tip_sigma_none: f32,
    /// An epoch moves when its measurement σ (radians) is below this.
    pub moving_r: f32,
    /// A departure after a stop this far (°) from the held heading changes direction.
    pub flip_stop_deg: f32,
    /// Without a stop, a course this far (°) from the heading changes direction.
    pub flip_deg: f32,
    /// Direction changes happen below this speed, m/s.
    pub flip_speed: f32,
    /// The heading must be this sure (°, 1σ) for a direction change.
    pub confident_deg: f32,
    /// Cars do not reverse above this speed (m/s): the reverse mode ends there.
    pub escape_speed: f32,
    /// Driving above this speed (m/s) for `fast_secs` makes a vehicle a car.
    pub fast_speed: f32,
    /// Seconds above `fast_speed` that make a vehicle a car.
    pub fast_secs: f32,
    /// Glitch gate: above this speed, m/s (a standing car at any speed).
    pub gate_speed: f32,
    /// Glitch gate: largest plausible acceleration, m/s².
    pub a_max: f32,
    /// Glitch gate: at most this many epochs ignored in a row.
    pub max_skips: u8,
    /// A car leaves a stand along its body: a course further than this (°, plus 2σ of
    /// the course) off a sure held heading's axis is not a departure.
    pub axis_deg: f32,
    /// ...for at most this long (s), in case the held heading was wrong.
    pub axis_secs: f32,
    /// The platform a source has unless its configuration says otherwise
    /// (`ghnet train --platform` records it; `auto` in older files).
    pub platform: Platform,
}

impl Default for ModeParams {
    fn default() -> Self {
        Self {
            q_still_deg: 1.0,
            q_tip_deg: 90.0,
            k_max: 0.2,
            a_lat: 3.0,
            sigma_floor: 0.03,
            sigma_none: 0.1,
            acc_k: 1.0,
            noise_k: 1.5,
            noise_quantile: 0.2,
            noise_rate: 0.05,
            noise_speed: 0.8,
            tip_acc_k: 1.0,
            tip_sigma_none: 0.1,
            moving_r: 0.35,
            flip_stop_deg: 90.0,
            flip_deg: 135.0,
            flip_speed: 2.0,
            confident_deg: 30.0,
            escape_speed: 2.0,
            fast_speed: 2.5,
            fast_secs: 5.0,
            gate_speed: 3.0,
            a_max: 4.0,
            max_skips: 3,
            axis_deg: 30.0,
            axis_secs: 2.0,
            platform: Platform::Auto,
        }
    }
}

impl ModeParams {
    /// Rayleigh quantile factor: the `noise_quantile` quantile of a stopped receiver's
    /// speed is this times its per-axis σ.
    fn quantile_factor(&self) -> f32 {
        (-2.0 * (1.0 - self.noise_quantile).ln()).sqrt()
    }
}

/// What one history knows about the vehicle and its receiver: kept across fix gaps
/// (the same vehicle), cleared by other resets.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Vehicle {
    /// Driven above `fast_speed` for `fast_secs`: a car (reverses, never turns in place).
    /// Always true for [`Platform::Car`], never for [`Platform::Robot`].
    pub car: bool,
    /// Running low quantile of slow speeds, m/s (NaN until the first epoch).
    pub noise: f32,
    /// Mean square of the course's scatter at speed, as a velocity across the track
    /// (m²/s²): how far each course departs from the previous heading turned at the
    /// current yaw rate, times the speed, smoothed over [`SCATTER_TAU_S`] of driving
    /// (NaN until measured). Where a receiver's accuracy (or its absence) understates
    /// its noise, this is what σ has not met ([`SigmaMaps::scatter_k`]).
    pub scatter: f32,
    /// What the source's user says carries the receiver; kept through every reset.
    pub platform: Platform,
}

impl Vehicle {
    /// Nothing known yet.
    pub const UNKNOWN: Vehicle = Vehicle {
        car: false,
        noise: f32::NAN,
        scatter: f32::NAN,
        platform: Platform::Auto,
    };
}

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
    /// Whether the history has reached its first epoch the tuned `kf` would use.
    pub moved: bool,
    /// Seconds continuously above `fast_speed`.
    pub t_fast: f32,
    /// Epochs continuously above `fast_speed`.
    pub n_fast: u16,
    /// Previous epoch's speed, m/s.
    pub prev_speed: f32,
    /// Last velocity the filter used (north, east), for the glitch gate; NaN when none.
    pub prev_v: [f32; 2],
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
    pub held_clean: bool,
    /// Yaw rate of the heading while moving, rad/s: the heading's change per second
    /// over moving epochs, smoothed over [`YAW_TAU_S`]; 0 while standing. A turn is
    /// where a receiver's lag (course trailing heading by ω·τ) and the antenna's
    /// lever arm show, so a moving epoch's σ grows with it ([`SigmaMaps::yaw_s`]).
    pub yaw: f32,
    /// Seconds of plain motion on a steady course up to this epoch (speed at least
    /// [`RELEASE_SPEED`] and `3·sAcc`, course within [`RELEASE_COURSE_DEG`] of the
    /// previous epoch's), 0 when this epoch is not: the release rule's clock.
    pub t_motion: f32,
    /// Epochs in that run of plain motion.
    pub n_motion: u16,
    /// Velocity (north, east; m/s) of the run's last steady epoch, for the release
    /// rule's steadiness.
    pub motion_v: [f32; 2],
    /// Seconds since that epoch.
    pub motion_dt: f32,
    /// Unsteady epochs skipped since (glitches inside a departure), at most `max_skips`.
    pub motion_skips: u8,
    /// The vehicle and its receiver.
    pub vehicle: Vehicle,
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
        t_fast: 0.0,
        n_fast: 0,
        prev_speed: 0.0,
        prev_v: [f32::NAN; 2],
        skips: 0,
        t_used: 0.0,
        pending_v: [f32::NAN; 2],
        held_y2: 0.0,
        held_clean: false,
        yaw: 0.0,
        t_motion: 0.0,
        n_motion: 0,
        motion_v: [0.0; 2],
        motion_dt: 0.0,
        motion_skips: 0,
        vehicle: Vehicle::UNKNOWN,
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
    pub fn moving_now(&self) -> bool {
        self.t_still == 0.0
    }

    /// Whether the release rule ends a stand on this epoch: a second of plain motion
    /// on a steady course ([`RELEASE_S`], and at least two epochs).
    pub fn released(&self) -> bool {
        self.t_motion >= RELEASE_S && self.n_motion >= RELEASE_EPOCHS
    }

    /// An empty history that keeps what it knew about the vehicle (after a fix gap).
    pub fn after_gap(&self) -> StepState {
        StepState {
            vehicle: self.vehicle,
            ..Self::EMPTY
        }
    }
}

/// One epoch's filter step before the network's corrections: what [`commit`] needs and
/// what the network's inputs describe.
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
}

fn cap2() -> f32 {
    let c = MAX_STD_DEG.to_radians();
    c * c
}

/// Speed corrected for noise (`√(|v|² − 2σ²)`, 0 inside the noise) and the course's σ
/// `σ/ŝ` capped at the uniform σ.
fn measurement(speed: f32, sigma: f32) -> (f32, f32) {
    let cap = MAX_STD_DEG.to_radians();
    let s2 = speed * speed - 2.0 * sigma * sigma;
    if s2 > 0.0 {
        let shat = s2.sqrt();
        (shat, (sigma / shat).min(cap))
    } else {
        (0.0, cap)
    }
}

/// Track the low quantile of slow speeds (a stopped receiver's noise).
fn update_noise(mp: &ModeParams, v: &mut Vehicle, speed: f32, acc: f32) {
    if !v.noise.is_finite() {
        let init = if acc.is_finite() { acc } else { 0.1 };
        v.noise = init * mp.quantile_factor();
    }
    if speed < mp.noise_speed {
        let below = if speed < v.noise { 1.0 } else { 0.0 };
        let tau = mp.noise_quantile;
        v.noise *= (mp.noise_rate * (tau - below) / tau.max(1.0 - tau)).exp();
    }
}

/// The velocity noise σ (m/s) of this epoch.
fn sigma_v(mp: &ModeParams, v: &Vehicle, acc: f32) -> f32 {
    let known = acc.is_finite();
    if !v.car {
        return platform_sigma_v(mp, acc);
    }
    let est = mp.noise_k * v.noise / mp.quantile_factor();
    let rep = if known { mp.acc_k * acc } else { mp.sigma_none };
    est.max(rep).max(mp.sigma_floor)
}

/// A platform's velocity noise σ (m/s): its receiver's accuracy, or `tip_sigma_none`.
fn platform_sigma_v(mp: &ModeParams, acc: f32) -> f32 {
    if acc.is_finite() {
        (mp.tip_acc_k * acc).max(mp.sigma_floor)
    } else {
        mp.tip_sigma_none
    }
}

/// The direction rules on a moving epoch: a car's departure against a sure heading
/// changes its mode, sustained speed ends a reversal (the heading was wrong by 180°) and
/// makes the vehicle a car.
fn direction_rules(mp: &ModeParams, st: &mut StepState, course: f32, speed: f32, p: f32, dt: f32) {
    let pi = std::f32::consts::PI;
    let z = course + if st.reverse { pi } else { 0.0 };
    let d = wrap_rad(z - st.psi);
    let sure = p < mp.confident_deg.to_radians().powi(2);
    let limit = if st.t_still > 0.0 {
        mp.flip_stop_deg
    } else {
        mp.flip_deg
    };
    if sure && st.vehicle.car && d.cos() < limit.to_radians().cos() && speed < mp.flip_speed {
        st.reverse = !st.reverse;
        st.t_mode = 0.0;
    }
    let fast = speed > mp.escape_speed && st.prev_speed > 0.7 * mp.escape_speed && dt <= 2.0;
    (st.t_fast, st.n_fast) = if speed > mp.fast_speed {
        (st.t_fast + dt, st.n_fast.saturating_add(1))
    } else {
        (0.0, 0)
    };
    if fast && st.reverse {
        st.reverse = false;
        st.t_mode = 0.0;
        st.psi += pi;
    }
    // Several epochs as well as seconds: a run of glitches under poor sky lasts a few
    // epochs and must not make a slow platform a car.
    if st.t_fast >= mp.fast_secs
        && st.n_fast >= FAST_EPOCHS
        && st.vehicle.platform != Platform::Robot
    {
        st.vehicle.car = true;
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
#[allow(clippy::too_many_arguments)] // one epoch's numbers
fn glitch(
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

/// Speed (m/s) from which courses feed [`Vehicle::scatter`]: slower, the course's
/// scatter is the speed's business, which σ already knows.
pub const SCATTER_SPEED: f32 = 3.0;

/// Longest epoch interval (s) whose course feeds [`Vehicle::scatter`]: over a longer
/// one the vehicle's own turning (a junction at 1 Hz) outweighs the receiver's noise,
/// and a floor built on it doubled a 1 Hz car's σ on straights.
pub const SCATTER_MAX_DT: f32 = 0.55;

/// How many times the σ_v from its sAcc a receiver's course scatter must reach for the
/// scatter floor to apply ([`SigmaMaps::scatter_k`]): the σ maps are fitted on
/// receivers whose sAcc is rough (0.7–1.5× the truth, or RTKLIB's formal value near
/// 0.07 m/s), so they cover those; a floor from twice the sAcc on took the median
/// held-out car drive from 69% to 75% within 1σ, from three times 72%. Receivers
/// without sAcc get the floor as soon as the scatter exceeds the σ_v the filter
/// guessed for them.
pub const SCATTER_RATIO_ACC: f32 = 3.0;

/// Seconds of driving [`Vehicle::scatter`] averages over.
pub const SCATTER_TAU_S: f32 = 30.0;

/// Feed [`Vehicle::scatter`] with this epoch's course against the previous heading
/// turned at the yaw rate, when both epochs moved at speed (no stop, gap or glitch in
/// between: `t_still` and `prev_speed` say so) and not in reverse.
fn update_scatter(st: &mut StepState, vn: f32, ve: f32, dt: f32) {
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

/// The release rule's clock ([`StepState::t_motion`]): runs while epochs are plain
/// motion (at least [`RELEASE_SPEED`] and `3·sAcc`) on a steady course.
fn track_motion(mp: &ModeParams, st: &mut StepState, vn: f32, ve: f32, acc: f32, dt: f32) {
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

/// This epoch's velocity noise σ_v, noise-corrected speed, course σ (radians) and
/// whether it moves. Released ([`StepState::released`]), the motion is real even when
/// the noise estimate (inflated by slow driving) calls it noise: it is then measured as
/// a platform would measure it, by the receiver's own accuracy. (The held heading is
/// not forgotten: cars that turn as they pull away are released off its axis too, and
/// lost more than they gained.)
fn measured(mp: &ModeParams, st: &StepState, speed: f32, acc: f32) -> (f32, f32, f32, bool) {
    let released = st.released();
    let sig = sigma_v(mp, &st.vehicle, acc);
    let (shat, r) = measurement(speed, sig);
    if released && r >= mp.moving_r {
        let sig = platform_sigma_v(mp, acc);
        let (shat, r) = measurement(speed, sig);
        return (sig, shat, r, true);
    }
    (sig, shat, r, r < mp.moving_r || released)
}

/// The first half of an epoch: time, noise, the rules; mutates the non-heading parts of
/// `st` and returns the step the network corrects. `kf_sigma_v` is the tuned `kf`'s σ_v
/// (the start convention); `acc` is sAcc or NaN.
pub fn prepare(
    mp: &ModeParams,
    kf_sigma_v: f32,
    st: &mut StepState,
    vn: f32,
    ve: f32,
    acc: f32,
    dt: f32,
) -> Step {
    let speed = vn.hypot(ve);
    let course = ve.atan2(vn);
    update_noise(mp, &mut st.vehicle, speed, acc);
    track_motion(mp, st, vn, ve, acc, dt);
    let cap2 = cap2();
    let mut step = Step {
        course,
        prior: if st.has_prior { st.psi } else { course },
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
    };
    if !st.has_prior {
        return step;
    }
    if !st.moved {
        let (_, r) = measurement(speed, kf_sigma_v);
        if r >= MAX_STD_DEG.to_radians() {
            return step;
        }
        st.moved = true;
    }
    step.hold = false;
    update_scatter(st, vn, ve, dt);
    let (sig, shat, r, moving) = measured(mp, st, speed, acc);
    let p_still = still_variance(mp, st, dt);
    // The gate first: a glitch must neither change the direction nor count as driving.
    step.glitch = glitch(mp, st, vn, ve, speed, sig, dt, moving, p_still, r);
    // A car whose speed is within its receiver's noise (under 3σ: 1% of a standing
    // receiver's epochs, 37% under the `√2σ` that `measurement` uses) is taken to stand.
    let car_at_rest = st.vehicle.car && !moving && speed < 3.0 * sig;
    // Steering turns the heading with distance driven: not over a glitch, nor over a
    // car at rest (its noise speed is no distance).
    let p = if !step.glitch && !car_at_rest {
        driving_variance(mp, p_still, shat, dt)
    } else {
        p_still
    };
    if moving && !step.glitch {
        direction_rules(mp, st, course, speed, p, dt);
    }
    if speed <= mp.fast_speed {
        // "Continuously fast" ends at any slow epoch, moving or not: a platform's three
        // glitches, a stand, then two more made it a car.
        (st.t_fast, st.n_fast) = (0.0, 0);
    }
    step.prior = st.psi;
    step.p = p;
    step.r2 = r * r;
    // A car at rest has no course: feeding its noise in turned held headings. (A slow
    // car above the noise still feeds, with the small gain its σ gives.)
    step.k = if step.glitch || car_at_rest || step.r2 >= cap2 * 0.999 {
        0.0
    } else {
        p / (p + step.r2)
    };
    step.rule_reverse = st.reverse;
    step.moving = moving;
    step.sigma_v = sig;
    step
}

/// The prior variance (radians²) of a standing step from `st` after `dt`: the class's
/// random walk (a car's is small: cars do not turn in place).
fn still_variance(mp: &ModeParams, st: &StepState, dt: f32) -> f32 {
    let q = if st.vehicle.car {
        mp.q_still_deg
    } else {
        mp.q_tip_deg
    }
    .to_radians();
    random_walk_variance(st.log_sigma, q, dt)
}

/// The prior variance (radians², capped at the uniform one) of a heading with `log σ`
/// `log_sigma` after a random walk of `q` rad/√s for `dt`: the mode filter's and `kf`'s.
pub(crate) fn random_walk_variance(log_sigma: f32, q: f32, dt: f32) -> f32 {
    ((2.0 * log_sigma).exp() + q * q * dt).min(cap2())
}

/// `p_still` plus the steering noise of the distance driven at speed `shat` over `dt`
/// (path curvature `k_max` when slow, lateral acceleration `a_lat` at speed).
fn driving_variance(mp: &ModeParams, p_still: f32, shat: f32, dt: f32) -> f32 {
    let w = mp.k_max * shat.min(mp.a_lat / (mp.k_max * shat.max(1e-3)));
    (p_still + w * w * dt).min(cap2())
}

/// The gain from the Kalman gain `k` and the network's log-odds correction `y`:
/// `k·eʸ / (1 − k + k·eʸ)`; exactly 0 when `k` is 0 (a stop stays held) and `k` at `y = 0`.
#[inline]
pub fn corrected_gain(k: f32, y: f32) -> f32 {
    if k <= 0.0 {
        return 0.0;
    }
    let e = y.clamp(-30.0, 30.0).exp();
    k * e / (1.0 - k + k * e)
}

/// The reverse logit: the rule's `±REVERSE_PRIOR` plus the network's `y`.
#[inline]
pub fn reverse_logit(rule_reverse: bool, y: f32) -> f32 {
    if rule_reverse {
        REVERSE_PRIOR + y
    } else {
        y - REVERSE_PRIOR
    }
}

/// What [`commit`] decided.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Decision {
    /// Heading, radians (not wrapped).
    pub psi: f32,
    /// The filter's `log σ` after the step (σ in radians).
    pub log_sigma: f32,
    /// Gain used (1 after a jump).
    pub gain: f32,
}

/// The second half of an epoch: the network's outputs `y` (gain, reverse, σ) applied to
/// `step`, the heading state of `st` updated. Zero outputs are the mode filter itself.
pub fn commit(st: &mut StepState, step: &Step, y: &[f32], dt: f32) -> Decision {
    let cap = MAX_STD_DEG.to_radians();
    let logit = reverse_logit(step.rule_reverse, y[1]);
    let (psi, var, gain) = if step.hold {
        (step.prior, cap * cap, 0.0)
    } else {
        let reverse = logit > 0.0;
        let z = step.course + if reverse { std::f32::consts::PI } else { 0.0 };
        let d = wrap_rad(z - step.prior);
        st.t_mode = if reverse != st.reverse {
            0.0
        } else {
            st.t_mode
        };
        st.reverse = reverse;
        // Overruling the rule never averages across a half turn: the heading jumps.
        if reverse != step.rule_reverse
            && step.moving
            && !step.glitch
            && d.abs() > 0.5 * std::f32::consts::PI
        {
            (z, step.r2, 1.0)
        } else {
            let g = corrected_gain(step.k, y[0]);
            let v = (1.0 - g) * (1.0 - g) * step.p + g * g * step.r2;
            (step.prior + g * d, v, g)
        }
    };
    let log_sigma = 0.5 * var.max(1e-12).ln();
    update_yaw(st, step, psi, gain, dt);
    advance_clocks(st, step, dt);
    st.psi = wrap_rad(psi);
    st.log_sigma = log_sigma.min(cap.ln());
    st.has_prior = true;
    Decision {
        psi,
        log_sigma: st.log_sigma,
        gain,
    }
}

/// The yaw rate after a step to heading `psi` with gain `gain` (1 after a jump): the
/// heading's change since the step's prior (the rules' half turns are already in the
/// prior), smoothed; a jump across a half turn is a misread direction, not a turn,
/// and leaves it as it was; a glitch too; anything else not moving ends it.
fn update_yaw(st: &mut StepState, step: &Step, psi: f32, gain: f32, dt: f32) {
    if step.glitch || (gain >= 1.0 && step.moving) {
        return;
    }
    if !step.moving || step.hold || dt <= 0.0 {
        st.yaw = 0.0;
        return;
    }
    let rate = wrap_rad(psi - step.prior) / dt;
    st.yaw += (dt / YAW_TAU_S).min(1.0) * (rate - st.yaw);
}

fn advance_clocks(st: &mut StepState, step: &Step, dt: f32) {
    // A glitch changes nothing: a standing vehicle stays standing through one, a moving
    // one moving (at speed, the gate's `max_skips` rule applies, not a stand's).
    let moved = step.moving && !step.glitch;
    st.t_still = if (step.glitch && st.moving_now()) || moved {
        0.0
    } else {
        st.t_still + dt
    };
    if moved && !step.hold {
        st.t_mode += dt;
    }
    if !step.glitch {
        st.prev_speed = step.speed;
    }
    // Every used epoch is the gate's reference, a standing car's noise included: it
    // leaves rest from rest, not from the speed it stopped at.
    if !step.glitch || !st.prev_v[0].is_finite() {
        let (s, c) = step.course.sin_cos();
        st.prev_v = [step.speed * c, step.speed * s];
    }
}

/// Knots of a [`SigmaMap`].
pub const SIGMA_KNOTS: usize = 12;

/// A monotone map from the filter's raw σ to the reported σ, both in degrees, linear
/// in log σ between knots and constant beyond them: fitted on validation tracks so that
/// the reported σ covers the errors as a σ should (a share within 1σ near 68%, at
/// least 90% within 2σ), which one scale factor cannot do for heavy-tailed errors.
/// All-zero knots (the default) are the identity.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SigmaMap {
    /// Raw σ at the knots, degrees, increasing.
    pub raw_deg: [f32; SIGMA_KNOTS],
    /// Reported σ at the knots, degrees, non-decreasing.
    pub reported_deg: [f32; SIGMA_KNOTS],
}

impl SigmaMap {
    /// Whether this is the identity (no knots).
    pub fn is_identity(&self) -> bool {
        self.raw_deg.iter().all(|&v| v == 0.0)
    }

    /// The reported σ (degrees, at most the uniform σ) for a raw σ in degrees.
    pub fn apply(&self, raw_deg: f32) -> f32 {
        if self.is_identity() || !raw_deg.is_finite() {
            return raw_deg.min(MAX_STD_DEG);
        }
        let (x, y) = (&self.raw_deg, &self.reported_deg);
        let out = if raw_deg <= x[0] {
            y[0]
        } else if raw_deg >= x[SIGMA_KNOTS - 1] {
            y[SIGMA_KNOTS - 1]
        } else {
            let i = x
                .partition_point(|&v| v <= raw_deg)
                .clamp(1, SIGMA_KNOTS - 1);
            let (l0, l1) = (x[i - 1].ln(), x[i].ln());
            let t = if l1 > l0 {
                (raw_deg.ln() - l0) / (l1 - l0)
            } else {
                1.0
            };
            y[i - 1] + t * (y[i] - y[i - 1])
        };
        out.min(MAX_STD_DEG)
    }
}

/// The σ maps of the two vehicle classes, moving and standing: errors of a car
/// (reverses, holds its heading when stopped) and of a vehicle not yet known to be one
/// (perhaps turning in place) grow differently with the filter's σ, and a held heading
/// fails differently (drift, a misread direction) from a followed course (noise,
/// glitches).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SigmaMaps {
    /// Cars, moving epochs.
    pub car: SigmaMap,
    /// Other vehicles, moving epochs.
    pub platform: SigmaMap,
    /// Cars, standing epochs (of a receiver not known to be [`clean`]). Fitted per
    /// stop (each stop weighs one, however long), because a stop repeats one error and
    /// a filter fuses it once; the share per epoch is held to the bars as well.
    pub car_still: SigmaMap,
    /// Cars, standing epochs of a [`clean`] receiver, fitted as `car_still`; absent
    /// (identity) in older files, which then use `car_still`.
    pub car_still_clean: SigmaMap,
    /// Other vehicles, standing epochs.
    pub platform_still: SigmaMap,
    /// Seconds of yaw rate added in quadrature to the mapped σ of a car moving at
    /// [`TURN_SPEED`] or faster: `hypot(σ, yaw_s·|ω|)`, then through `car_turn`.
    /// Without it σ knows noise and speed but not turning, and averages straights with
    /// turns: on held-out simulated cars at 2 m/s and faster that left 75% of errors
    /// within 1σ under 0.5°/s and 40% at 10°/s and more (a lagging receiver's course
    /// trails the heading by ω·τ, τ unknown; a lever arm adds its own offset in a
    /// turn). 0 (older files) leaves σ as it was.
    pub yaw_s: f32,
    /// A car's moving epochs map the filter's σ alone, without the network's
    /// correction `y₂`.
    /// The filter's σ follows the receiver's noise (σ_v/ŝ): on a fresh simulated set
    /// at 2 m/s and faster its median grows 4.3× from the quietest quarter of drives to
    /// the noisiest, where the errors' 68th percentile grows 3×; with `y₂`, trained on
    /// all receivers pooled, it grew 1.7×, so σ was too wide for quiet receivers and
    /// too narrow for noisy ones. False (older files) keeps `y₂`.
    pub moving_without_y2: bool,
    /// Floor of a moving epoch's reported σ, as a multiple of the course scatter the
    /// source has shown at speed ([`Vehicle::scatter`]) over the speed: `scatter_k ·
    /// √scatter / speed`. The maps are fitted on receivers the recipes know; a receiver
    /// noisier than its accuracy says (or one without any) shows it here first. 0
    /// (older files) is no floor.
    pub scatter_k: f32,
    /// Cars, moving at speed: the σ with its turn term to the reported σ (a turn's
    /// errors have heavier tails than a Gaussian term covers, so the sum is mapped
    /// again). Cars only: the simulated platforms turn in place below [`TURN_SPEED`],
    /// so the only other vehicles at speed there are cars not yet known to be cars,
    /// no basis for a real platform's map.
    pub car_turn: SigmaMap,
}

/// A receiver is clean when the noise the filter measured at rest is under this share
/// of the speed accuracy it reports: its held headings lack the heavy tail of
/// receivers noisier than they say (validation standing cars: 68th percentile 1.9°
/// against 5.8°).
pub const CLEAN_NOISE_RATIO: f32 = 0.5;

/// Whether the receiver behind `noise` (measured, m/s) and `acc` (reported sAcc, m/s,
/// NaN when absent) is clean; never without an sAcc.
pub fn clean(noise: f32, acc: f32) -> bool {
    acc.is_finite() && noise < CLEAN_NOISE_RATIO * acc
}

impl SigmaMaps {
    /// The map of a class (`car`), state (`moving`) and receiver ([`clean`]).
    pub fn map(&self, car: bool, moving: bool, clean: bool) -> &SigmaMap {
        match (car, moving) {
            (true, true) => &self.car,
            (false, true) => &self.platform,
            (true, false) if clean && !self.car_still_clean.is_identity() => &self.car_still_clean,
            (true, false) => &self.car_still,
            (false, false) => &self.platform_still,
        }
    }

    /// The map of a class, state and receiver, to fit.
    pub fn map_mut(&mut self, car: bool, moving: bool, clean: bool) -> &mut SigmaMap {
        match (car, moving) {
            (true, true) => &mut self.car,
            (false, true) => &mut self.platform,
            (true, false) if clean => &mut self.car_still_clean,
            (true, false) => &mut self.car_still,
            (false, false) => &mut self.platform_still,
        }
    }

    /// The reported σ (degrees) for a raw σ in degrees.
    pub fn apply(&self, car: bool, moving: bool, clean: bool, raw_deg: f32) -> f32 {
        self.map(car, moving, clean).apply(raw_deg)
    }

    /// The reported σ (degrees) of an epoch of class `car` whose class map gave
    /// `mapped_deg`, at yaw rate `yaw` (rad/s): for a car moving at [`TURN_SPEED`] or
    /// faster, the turn term added in quadrature and mapped again. Slower epochs and
    /// standing ones take their class map's σ as it is: there the speed sets the error
    /// (and a held heading's turn is over); so do other vehicles (see `car_turn`).
    pub fn with_turn(&self, car: bool, moving: bool, speed: f32, mapped_deg: f32, yaw: f32) -> f32 {
        if !car || !moving || speed < TURN_SPEED || self.yaw_s <= 0.0 || !yaw.is_finite() {
            return mapped_deg;
        }
        let sum = mapped_deg.hypot(self.yaw_s * yaw.abs().to_degrees());
        self.car_turn.apply(sum)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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

    /// One 1 Hz epoch along `course_deg` at `speed` (sAcc 0.1 m/s), filter alone.
    fn along(st: &mut StepState, speed: f32, course_deg: f32) {
        let mp = ModeParams::default();
        let (s, c) = course_deg.to_radians().sin_cos();
        let step = prepare(&mp, 0.5, st, speed * c, speed * s, 0.1, 1.0);
        commit(st, &step, &[0.0, 0.0, 0.0], 1.0);
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

    /// The turn term grows the σ of a car moving at speed in quadrature (identity turn
    /// map: the sum as it is) and leaves slow and standing epochs, other vehicles and
    /// older files (no term) alone.
    #[test]
    fn turn_term_adds_in_quadrature_for_cars_at_speed_only() {
        let ten = 10f32.to_radians();
        let maps = SigmaMaps {
            yaw_s: 0.4,
            ..SigmaMaps::default()
        };
        assert!((maps.with_turn(true, true, 8.0, 3.0, ten) - 5.0).abs() < 1e-4);
        assert!((maps.with_turn(true, true, 8.0, 3.0, -ten) - 5.0).abs() < 1e-4);
        assert_eq!(maps.with_turn(false, true, 8.0, 3.0, ten), 3.0, "not a car");
        assert_eq!(maps.with_turn(true, true, 1.5, 3.0, ten), 3.0, "slow");
        assert_eq!(maps.with_turn(true, false, 8.0, 3.0, ten), 3.0, "standing");
        assert_eq!(
            SigmaMaps::default().with_turn(true, true, 8.0, 3.0, ten),
            3.0
        );
    }
}
