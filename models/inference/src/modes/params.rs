//! The mode filter's constants, stored in each temporal model's metadata.

use serde::{Deserialize, Serialize};

use super::vehicle::{rayleigh_quantile, Platform, Vehicle};

/// A car's lever arm when nothing else is known, m ([`ModeParams::lever_m`]).
pub const LEVER_M: f32 = 1.0;

/// The mode filter's constants (stored in the model's metadata).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ModeParams {
    /// Heading random walk of a standing car, °/√s (small: cars do not turn in place).
    pub q_still_deg: f32,
    /// Heading random walk of a platform that turns in place, °/√s.
    pub q_tip_deg: f32,
    /// Heading random walk of a platform while it moves, °/√s, at epochs at most
    /// [`SCATTER_SMOOTH_DT`] apart: it spins only where it stands, and its turns while
    /// it drives are steering (`k_max`) and creeping, so the spin's walk (`q_tip_deg`)
    /// had the filter follow each course with its noise. On the robots of
    /// `reports/unmet.md` at 5 and 10 Hz a third of the spin's walk gained most on
    /// receivers whose sAcc understates their noise (RTKLIB), lost in no speed band,
    /// and narrowed σ where it covered more than a σ should; two thirds of that or less
    /// cost the lagging u-blox robots at 1–2 m/s. At longer intervals (1 Hz) a robot's
    /// turn between two courses outruns any such walk, and the filter follows each
    /// course as before. Files without the field load it; own-log training fits it.
    ///
    /// [`SCATTER_SMOOTH_DT`]: crate::modes::SCATTER_SMOOTH_DT
    pub q_move_deg: f32,
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
    /// Cars do not reverse above this speed (m/s): the reverse mode ends there, once the
    /// speed also clears the receiver's noise ([`crate::modes::ESCAPE_NOISE_K`]).
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
    /// be a car (or of any vehicle on a receiver that holds static) leads by (the
    /// filtered yaw rate times the lag, see [`crate::modes::commit`]); 0 for none.
    /// Own-log training fits it.
    pub lag_s: f32,
    /// The lag (s) assumed, when larger than `lag_s`, for a receiver that holds static
    /// ([`Vehicle::holds_static`]): a static hold is part of a receiver's navigation
    /// filter, and that filter lags the course. A third of the lag measured on a real
    /// robot day's consumer receiver, the least the simulator's consumer style has.
    ///
    /// [`Vehicle::holds_static`]: crate::modes::Vehicle::holds_static
    pub hold_lag_s: f32,
    /// The lag (s) assumed, when larger than `lag_s`, for a vehicle not known to be a
    /// car whose receiver reports no speed accuracy and shows its noise at rest (an
    /// NMEA unit's course and speed): such a course is often the receiver's navigation
    /// filter's output and trails a turn, though less surely than a static hold's, so
    /// the lead is half `hold_lag_s`. Robots turn while driving slowly, where that trail
    /// is most of the course's error (the NMEA robot rows of
    /// models/reports/unmet.md). Receivers with an sAcc are not led: raw Doppler
    /// velocity (RTKLIB) does not lag, and a lead there costs what it gains on the rest.
    /// Own-log training fits it with `lag_s`.
    pub no_acc_lag_s: f32,
    /// The lag (s) a car's lever correction allows a receiver that reports a speed
    /// accuracy and shows its noise at rest (raw Doppler velocity: u-blox, RTKLIB), in
    /// place of `hold_lag_s` (the fade of `ModeParams::lever`). Such velocity trails a
    /// turn by little, so the antenna's lead is taken out up to `L/2τ` (2 m/s) rather
    /// than 1 m/s, and in part up to `L/τ` (4 m/s): on the shared real drive (raw
    /// u-blox Doppler, its course a junction turn's 8–10° ahead of the heading) the
    /// 1–2 and 2–5 m/s bands and the fast turns gain most, and simulated RTKLIB cars
    /// gain in every turn band (models/reports/car-nagoya.md, unmet.md). Not 0, and
    /// the same quarter second as `no_acc_lag_s`: half the simulator's u-blox
    /// receivers lag by 0.2–1.5 s, and a correction at every speed cost their fast
    /// turns points within 2σ; at 0.2 s the real drive's errors were within 1σ more
    /// often than a σ should allow. Files without the field load it; own-log training
    /// fits it with `lag_s`.
    pub acc_lag_s: f32,
    /// How far (m) a car's antenna sits ahead of its rear axle, the point of the car
    /// with no sideways velocity: turning at yaw rate ω at speed `v`, the antenna's
    /// course leads the heading by `atan(ω·L/v)` (trails it reversing), and a car's
    /// answer takes that out (see [`crate::modes::commit`]). Unknown for a car in
    /// general: 1 m is where a passenger car's roof antenna sits (over the cabin, a
    /// little behind the middle of a 2.6–2.8 m wheelbase; the shared real drive's car
    /// reads about 1.1 m). The simulator's cars draw 0–2.5 m, trucks' cabs included,
    /// and on them 1 m and the range's middle differ by a hundredth of a degree
    /// (models/reports/unmet.md). Files without the field load it; own-log training fits
    /// it.
    pub lever_m: f32,
    /// Heading minus course (°) while the vehicle drives straight ahead, added to every
    /// answer: where the body points relative to the direction its antenna moves, as
    /// the user's truth sees it (an INS mounted a little askew, a crabbing chassis, a
    /// receiver's boresight). Nothing online can tell it from the course itself, so the
    /// shipped model has 0 (the simulator draws a few tenths of a degree per
    /// receiver); own-log training measures it on the log's truth. Files without the
    /// field load 0.
    pub boresight_deg: f32,
    /// The platform a source has unless its configuration says otherwise
    /// (`ghnet train --platform` records it; `auto` in older files).
    pub platform: Platform,
}

impl Default for ModeParams {
    fn default() -> Self {
        Self {
            q_still_deg: 1.0,
            q_tip_deg: 90.0,
            q_move_deg: 30.0,
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
            no_acc_lag_s: 0.25,
            acc_lag_s: 0.25,
            lever_m: LEVER_M,
            boresight_deg: 0.0,
            platform: Platform::Auto,
        }
    }
}

impl ModeParams {
    /// The lag (s) the answered heading leads a vehicle's course by, its receiver
    /// reporting a speed accuracy (`has_acc`) or not. A receiver that holds static is a
    /// navigation filter's output, which lags: `hold_lag_s`, or `lag_s` if larger,
    /// whatever carries it, unless its noise shows raw velocity behind the hold
    /// ([`Vehicle::raw_hold`]). Otherwise nothing for a car (its results are tuned on
    /// receivers that show no sign of their lag), and `lag_s` for another vehicle, or
    /// `no_acc_lag_s` if larger when its receiver gives no accuracy and may filter
    /// (not a raw hold).
    ///
    /// [`Vehicle::raw_hold`]: crate::modes::Vehicle::raw_hold
    #[inline]
    pub(super) fn lead_s(&self, v: &Vehicle, has_acc: bool) -> f32 {
        let raw_hold = v.raw_hold();
        if v.holds_static() && !raw_hold {
            self.lag_s.max(self.hold_lag_s)
        } else if v.car {
            0.0
        } else if has_acc || raw_hold {
            self.lag_s
        } else {
            self.lag_s.max(self.no_acc_lag_s)
        }
    }

    /// Whether a heading of variance `p` (rad²) is sure enough to act on
    /// ([`ModeParams::confident_deg`]): to flip a car's direction, or to hold a
    /// departure to the axis of its held heading.
    #[inline]
    pub(super) fn sure(&self, p: f32) -> bool {
        p < self.confident_deg.to_radians().powi(2)
    }

    /// A car's lever arm at `speed` (m/s), as [`Step::lever_s`] and [`Step::lever_max`];
    /// zeros for anything else (a platform turns about its antenna's neighbourhood).
    /// The antenna's lead `ω·L/v` fades with speed while a navigation filter's lag
    /// trail `ω·τ` does not: the correction takes a lagging receiver's error from
    /// `|lead − trail|` to `|trail|`, better only while the lead is twice the trail.
    /// With τ = `hold_lag_s` (the least lag of a receiver that filters) the correction
    /// is whole up to `L/2τ` (1 m/s) and gone from `L/τ` (2 m/s); above, the
    /// turn term of the σ ([`SigmaMaps::yaw_s`]) covers both as noise. A receiver
    /// that reports its accuracy (`has_acc`) and shows its noise at rest gives raw
    /// velocity, which lags little: τ = `acc_lag_s`, whole up to 2 m/s; so does one
    /// that holds static but whose noise shows raw velocity ([`Vehicle::raw_hold`]).
    ///
    /// [`Vehicle::raw_hold`]: crate::modes::Vehicle::raw_hold
    ///
    /// [`Step::lever_s`]: crate::modes::Step
    /// [`Step::lever_max`]: crate::modes::Step
    /// [`SigmaMaps::yaw_s`]: crate::modes::SigmaMaps
    #[inline]
    pub(super) fn lever(&self, v: &Vehicle, speed: f32, has_acc: bool) -> (f32, f32) {
        if !v.car || self.lever_m <= 0.0 || speed <= 0.0 {
            return (0.0, 0.0);
        }
        let lag = if (has_acc && !v.holds_static()) || v.raw_hold() {
            self.acc_lag_s
        } else {
            self.hold_lag_s
        };
        let fade = (2.0 - 2.0 * speed * lag / self.lever_m).clamp(0.0, 1.0);
        (
            fade * self.lever_m / speed,
            fade * self.k_max * self.lever_m,
        )
    }

    /// Rayleigh quantile factor: the `noise_quantile` quantile of a stopped receiver's
    /// speed is this times its per-axis σ.
    #[inline]
    pub(super) fn quantile_factor(&self) -> f32 {
        rayleigh_quantile(self.noise_quantile)
    }

    /// The per-axis velocity σ (m/s) a vehicle's receiver has shown at rest: its
    /// running low quantile of slow speeds ([`Vehicle::noise`]) over the
    /// [`quantile_factor`](Self::quantile_factor). What the release rule and a declared
    /// robot's `Stationary` course take for the receiver's noise.
    #[inline]
    pub(super) fn rest_noise(&self, v: &Vehicle) -> f32 {
        v.noise / self.quantile_factor()
    }

    /// The sAcc (m/s) the rules that decide whether a vehicle moves go by (the release
    /// rule's bars, the speed under which a stand's answer is `Held`): the reported
    /// `acc`, at most the noise the receiver has shown at rest (from its running low
    /// quantile of slow speeds, [`Vehicle::noise`]; not under `sigma_floor`). Many u-blox
    /// receivers report several times the noise they show; taken at its word, such an
    /// sAcc kept cars driving off at 1 m/s under the `3·sAcc` bars, `Held` for over ten
    /// seconds (the `--sacc-scale 3` sections of `models/reports/unmet.md`). The
    /// estimate starts at the sAcc and falls only as the receiver reports slow speeds,
    /// so an honest sAcc, or a receiver not yet seen at rest, is taken as reported. A
    /// receiver that holds static shows no noise at rest and keeps its sAcc (which the
    /// release rule sets aside). σ and the network keep the reported sAcc: the shared
    /// real drive's is above its noise at rest, and σ from that noise took its shares
    /// within 1σ and 2σ out of the bars (models/README.md, the release rule).
    #[inline]
    pub fn trusted_acc(&self, v: &Vehicle, acc: f32) -> f32 {
        if !acc.is_finite() || v.holds_static() {
            return acc;
        }
        acc.min(self.rest_noise(v).max(self.sigma_floor))
    }

    /// The sAcc (m/s) by which a vehicle not known to be a car weighs its course in the
    /// filter's gain: the reported `acc`, or `acc` times
    /// [`Vehicle::acc_scale`] (not under `sigma_floor`) when the receiver's sAcc
    /// is over [`PESSIMISTIC_SACC_RATIO`] times the noise it has shown at rest. Weighed
    /// by an sAcc three times the noise, a robot's courses were smoothed through its
    /// turns (at 1–2 m/s 25–54% worse than atan2) and its creeps carried no heading
    /// (the `--sacc-scale 3` sections of `models/reports/unmet.md`). The scale, not the
    /// noise at rest itself: sAcc follows the sky, so the scaled sAcc is this epoch's
    /// noise where the noise at rest is the last stand's. Everything else keeps the
    /// reported `acc`: whether the epoch moves, the glitch gate, the network's sAcc
    /// input. A receiver that holds static shows no noise at rest and keeps its sAcc.
    #[inline]
    pub fn gain_acc(&self, v: &Vehicle, acc: f32) -> f32 {
        if !acc.is_finite() || v.holds_static() {
            return acc;
        }
        let scale = v.acc_scale();
        if scale * PESSIMISTIC_SACC_RATIO < 1.0 {
            (acc * scale).max(self.sigma_floor)
        } else {
            acc
        }
    }
}

/// How many times the noise a receiver has shown at rest its sAcc must be for a
/// platform's filter gain to go by the scaled sAcc instead ([`ModeParams::gain_acc`]).
/// The simulated u-blox sAcc is 0.7–1.5 times the receiver's noise; the same receivers
/// reporting three times that are over the ratio, and so are the most pessimistic
/// honest ones, whose scaled sAcc is nearer their noise too. At 1, a noisier copy of
/// the shared real drive (its sAcc kept, near its noise) lost 11% at its start, while
/// still taken for a platform; at 2 the sAcc × 3 robots of `models/reports/unmet.md`
/// gained a fifth to a third less.
pub const PESSIMISTIC_SACC_RATIO: f32 = 1.3;

#[cfg(test)]
mod tests {
    use super::*;

    /// Files written before the lever arm (or its raw-Doppler lag) load the defaults;
    /// a car's lever is whole at a crawl, faded between `L/2τ` and `L/τ` (τ =
    /// `hold_lag_s` without sAcc), none for a vehicle not known to be a car.
    #[test]
    fn the_lever_arm_defaults_and_fades_with_speed() {
        let mp = ModeParams::default();
        let mut json = serde_json::to_value(mp).unwrap();
        json.as_object_mut().unwrap().remove("lever_m");
        json.as_object_mut().unwrap().remove("acc_lag_s");
        let old: ModeParams = serde_json::from_value(json).unwrap();
        assert_eq!(old.lever_m, LEVER_M);
        assert_eq!(old.acc_lag_s, mp.acc_lag_s);
        let mut car = Vehicle::UNKNOWN;
        car.car = true;
        let (l, k) = (mp.lever_m, mp.k_max);
        let whole = l / (2.0 * mp.hold_lag_s);
        let (s, m) = mp.lever(&car, 0.8 * whole, false);
        assert!((s - l / (0.8 * whole)).abs() < 1e-6 && (m - k * l).abs() < 1e-6);
        let (s, m) = mp.lever(&car, 1.5 * whole, false);
        assert!((s - 0.5 * l / (1.5 * whole)).abs() < 1e-6 && (m - 0.5 * k * l).abs() < 1e-6);
        assert_eq!(mp.lever(&car, 2.0 * whole, false), (0.0, 0.0));
        assert_eq!(mp.lever(&Vehicle::UNKNOWN, 1.0, true), (0.0, 0.0));
    }
}
