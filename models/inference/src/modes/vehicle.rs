//! What carries the receiver: the platform a source's user names, what one history
//! has learned about the vehicle and its receiver, and when driving makes it a car.

use serde::{Deserialize, Serialize};

/// A receiver that holds static seldom reports a speed above zero and below this
/// (m/s): its first moving epoch after a stand jumps past it.
pub const HOLD_CREEP_SPEED: f32 = 0.25;

/// A receiver holds static when its exact zeros outnumber its creeping speeds (under
/// [`HOLD_CREEP_SPEED`]) this many times: a stand of a few seconds is all zeros, a
/// slow stop may creep for an epoch or two on its way down, while a receiver that
/// shows its noise at rest creeps at least as often as its quantized speed reads 0.
pub const HOLD_ZEROS_PER_CREEP: u32 = 4;

/// Fewest exact zeros that show a static hold: a second of standing at 5 Hz. One bad
/// fix printed as 0.0 m/s while driving is no hold, and a receiver taken to hold
/// static is led and keeps its noise guess ([`Vehicle::holds_static`]).
pub const HOLD_MIN_ZEROS: u32 = 5;

/// Fewest epochs above `fast_speed` that make a vehicle a car.
pub const FAST_EPOCHS: u16 = 5;

/// Speed (m/s) that a vehicle driving above it for `fast_secs` (in a run that makes it
/// a car) shows is no robot: ground robots drive at walking pace, the simulated ones
/// at 0.3–2 m/s. Such a car is never demoted by a departure off its stand's axis (the
/// release rule's sign of a turn in place): on a noisy receiver a car that turned in
/// a slow manoeuvre the stand did not follow leaves that way too, and demoted, its
/// stands until it drove fast again held nothing (the uniform σ, the noise's course).
/// Demotion so cost up to 5% on the car sections of models/reports/unmet.md (1 Hz
/// RTKLIB) and 10% on the shared drive's noisy copies (noisy-real.md); a few sections
/// lose up to 1.2%, where a sure car holds a stand whose sense it misread (σ 90°).
pub const SURE_CAR_SPEED: f32 = 6.0;

/// Degrees off the axis of the heading an `auto` vehicle not known to be a car stood
/// with (neither along it nor against it) by which its departure must leave to show
/// that it turned in place ([`Vehicle::turns`]). A car that backs out, or drives off
/// into a turn, has turned by much less a second after it set off; a robot's spin at
/// a stop is any angle.
pub const TURN_IN_PLACE_DEG: f32 = 45.0;

/// Seconds of standing after which a departure is compared with the heading stood with.
pub const TURN_STAND_S: f32 = 1.0;

/// Seconds of steady motion (the release rule's run) that confirm a departure off the
/// axis, and that a run must last for its heading to be the one a later departure is
/// compared with. A glitch burst at a stand, which the release rule may take for a
/// departure, lasts a few epochs: compared after the release rule's second, such
/// bursts took simulated 1 Hz cars for robots.
pub const TURN_RUN_S: f32 = 3.0;

/// Largest σ (degrees, the filter's) of a heading a departure is compared with.
pub const TURN_SURE_DEG: f32 = 20.0;

/// Quantile of slow speeds over their sAcc that [`Vehicle::acc_ratio`] tracks. Low, so
/// that it reads the receiver at rest through a robot's creeps: under `noise_speed` a
/// robot creeping at 0.3–0.5 m/s fills many of the slow epochs, and the running 20%
/// quantile of slow speeds ([`Vehicle::noise`]) rose with every creep, to twice the
/// noise a stopped u-blox showed (the robots of `models/reports/unmet.md`). A 5%
/// quantile reads the stands' own speeds while they are over a twentieth of the slow
/// epochs (the 20% one needs a fifth) and rises a fifth as fast through a creep.
pub const ACC_RATIO_QUANTILE: f32 = 0.05;

/// Slow epochs with an sAcc that must have fed [`Vehicle::acc_ratio`] before it counts
/// ([`Vehicle::acc_scale`]): one and a half below its quantile, on average. From
/// ten, one low speed at a robot's first stand (its first steps are large) took an
/// honest receiver's sAcc for twice its noise for the whole drive after it.
pub const ACC_RATIO_MIN_EPOCHS: u32 = 30;

/// The `tau` quantile of a stopped receiver's speed over its per-axis σ (Rayleigh): what
/// a running low quantile of slow speeds is divided by to read that σ.
#[inline]
pub(super) fn rayleigh_quantile(tau: f32) -> f32 {
    (-2.0 * (1.0 - tau).ln()).sqrt()
}

/// The `acc_ratio` of a receiver whose sAcc is its noise: the [`ACC_RATIO_QUANTILE`]
/// Rayleigh quantile.
#[inline]
pub(super) fn acc_ratio_factor() -> f32 {
    rayleigh_quantile(ACC_RATIO_QUANTILE)
}

/// What carries the receiver: whether the mode filter may take it for a car, and
/// whether it may turn in place. Set per source; `Auto` decides online.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Platform {
    /// Decide online: a vehicle that drives fast for a while is a car until it leaves a
    /// stand sideways (it turned in place); one that is no car and leaves a stand off
    /// its axis is answered at its stands as a robot ([`Vehicle::turns`]).
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
    ///
    /// [`SCATTER_TAU_S`]: crate::modes::SCATTER_TAU_S
    /// [`SigmaMaps::scatter_k`]: crate::modes::SigmaMaps::scatter_k
    pub scatter: f32,
    /// What the source's user says carries the receiver; kept through every reset.
    pub platform: Platform,
    /// Epochs the receiver reported a velocity of exactly zero.
    pub zeros: u32,
    /// Epochs the receiver reported a speed above zero and below [`HOLD_CREEP_SPEED`].
    pub creeps: u32,
    /// Whether a [`Platform::Auto`] vehicle, while not known to be a car, has left a
    /// stand off the axis of the heading it stood with ([`TURN_IN_PLACE_DEG`]) and
    /// kept going ([`TURN_RUN_S`]): it turns in place, so what it holds at a stop may
    /// be stale, as a declared robot's is, and its `Stationary` answers follow a steady
    /// creep as a robot's do ([`stationary_course`]).
    ///
    /// [`stationary_course`]: crate::modes::stationary_course
    pub turns: bool,
    /// Seconds of the current run of fast epochs (those that count towards `car`) above
    /// [`SURE_CAR_SPEED`].
    pub t_sure: f32,
    /// Whether the vehicle has driven above [`SURE_CAR_SPEED`] for `fast_secs`: faster
    /// than any robot, so a car whatever its stands show (kept across fix gaps, as the
    /// rest of the vehicle is).
    pub sure_car: bool,
    /// Running low quantile ([`ACC_RATIO_QUANTILE`]) of slow speeds over the sAcc
    /// reported with them (NaN until the first slow epoch with an sAcc): how far under
    /// its sAcc the receiver's noise at rest lies ([`Vehicle::acc_scale`]).
    pub acc_ratio: f32,
    /// Slow epochs with an sAcc that have fed `acc_ratio` (its first steps are larger).
    pub acc_ratio_n: u32,
    /// Running mean agreement of successive velocity changes while moving (NaN until
    /// the first pair): negative for white noise, near zero or positive for a
    /// navigation filter's smoothed output ([`SMOOTH_WHITE_BAR`],
    /// [`Vehicle::raw_velocity`]).
    ///
    /// [`SMOOTH_WHITE_BAR`]: crate::modes::SMOOTH_WHITE_BAR
    pub smooth: f32,
    /// Pairs of changes that have fed `smooth`.
    pub smooth_n: u32,
    /// The last epoch of the chain `smooth` is fed from; `None` when it is broken.
    pub smooth_last: Option<SmoothLink>,
}

/// One epoch of the chain [`Vehicle::smooth`] is fed from: its velocity (north, east;
/// m/s) and, once the chain has two epochs, that velocity's change since the epoch
/// before and the interval (s) it spans.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SmoothLink {
    /// The epoch's velocity, north and east (m/s).
    pub v: [f32; 2],
    /// Its change since the chain's previous epoch (m/s) and that interval (s).
    pub change: Option<([f32; 2], f32)>,
}

impl Vehicle {
    /// Nothing known yet.
    pub const UNKNOWN: Vehicle = Vehicle {
        car: false,
        noise: f32::NAN,
        scatter: f32::NAN,
        platform: Platform::Auto,
        zeros: 0,
        creeps: 0,
        turns: false,
        t_sure: 0.0,
        sure_car: false,
        acc_ratio: f32::NAN,
        acc_ratio_n: 0,
        smooth: f32::NAN,
        smooth_n: 0,
        smooth_last: None,
    };

    /// Whether the receiver holds static but passes raw velocity through
    /// ([`Vehicle::holds_static`], [`Vehicle::raw_velocity`]): its zeros are a hold's,
    /// its course does not trail a turn, so it is neither led nor given a lag's σ.
    #[inline]
    pub fn raw_hold(&self) -> bool {
        self.holds_static() && self.raw_velocity()
    }

    /// How far under its sAcc the receiver's noise at rest lies: its running low
    /// quantile of slow speeds over their sAcc (`acc_ratio`) over the one a receiver
    /// whose sAcc is its noise shows. 1 until [`ACC_RATIO_MIN_EPOCHS`] slow epochs have
    /// fed it.
    #[inline]
    pub fn acc_scale(&self) -> f32 {
        let scale = self.acc_ratio / acc_ratio_factor();
        if scale.is_finite() && self.acc_ratio_n >= ACC_RATIO_MIN_EPOCHS {
            scale
        } else {
            1.0
        }
    }

    /// Whether the vehicle turns in place: a declared [`Platform::Robot`], or an `auto`
    /// one not known to be a car that has shown it does ([`Vehicle::turns`]).
    #[inline]
    pub fn turns_in_place(&self) -> bool {
        match self.platform {
            Platform::Robot => true,
            Platform::Auto => !self.car && self.turns,
            Platform::Car => false,
        }
    }

    /// Record what one epoch's speed says about a static hold (a speed of exactly zero
    /// is a velocity of exactly zero).
    #[inline]
    pub fn observe_hold(&mut self, speed: f32) {
        if speed == 0.0 {
            self.zeros = self.zeros.saturating_add(1);
        } else if speed < HOLD_CREEP_SPEED {
            self.creeps = self.creeps.saturating_add(1);
        }
    }

    /// Whether the receiver holds static: it has reported exactly zero at rest
    /// ([`HOLD_MIN_ZEROS`] times or more) and hardly ever a creeping speed
    /// ([`HOLD_ZEROS_PER_CREEP`]), so motion starts with a jump. Raw Doppler velocities
    /// (RTKLIB, most u-blox settings) and quantized NMEA speeds show their noise at rest.
    #[inline]
    pub fn holds_static(&self) -> bool {
        self.zeros >= HOLD_MIN_ZEROS
            && self.zeros >= HOLD_ZEROS_PER_CREEP.saturating_mul(self.creeps)
    }
}
