//! The mode filter's constants, stored in each temporal model's metadata.

use serde::{Deserialize, Serialize};

use super::vehicle::{Platform, Vehicle};

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
    /// A receiver's course lag (s) that the answered heading of a vehicle not known to
    /// be a car leads by (the filtered yaw rate times the lag, see
    /// [`crate::modes::commit`]); 0 for none. Own-log training fits it.
    pub lag_s: f32,
    /// The lag (s) assumed, when larger than `lag_s`, for a receiver that holds static
    /// ([`Vehicle::holds_static`]): a static hold is part of a receiver's navigation
    /// filter, and that filter lags the course. A third of the lag measured on a real
    /// robot day's consumer receiver, the least the simulator's consumer style has.
    ///
    /// [`Vehicle::holds_static`]: crate::modes::Vehicle::holds_static
    pub hold_lag_s: f32,
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
            lag_s: 0.0,
            hold_lag_s: 0.5,
            platform: Platform::Auto,
        }
    }
}

impl ModeParams {
    /// The lag (s) the answered heading leads a vehicle's course by: none for a car
    /// (its results are tuned without), `lag_s` or, for a receiver that holds static,
    /// `hold_lag_s` if larger.
    #[inline]
    pub(super) fn lead_s(&self, v: &Vehicle) -> f32 {
        if v.car {
            0.0
        } else if v.holds_static() {
            self.lag_s.max(self.hold_lag_s)
        } else {
            self.lag_s
        }
    }

    /// Rayleigh quantile factor: the `noise_quantile` quantile of a stopped receiver's
    /// speed is this times its per-axis σ.
    #[inline]
    pub(super) fn quantile_factor(&self) -> f32 {
        (-2.0 * (1.0 - self.noise_quantile).ln()).sqrt()
    }
}
