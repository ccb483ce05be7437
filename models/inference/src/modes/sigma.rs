//! From the filter's σ to the reported σ: monotone maps per vehicle class and state,
//! the turn term and the clean-receiver rule.

use serde::{Deserialize, Serialize};

use super::vehicle::Vehicle;
use crate::head::MAX_STD_DEG;

/// Speed (m/s) from which a moving epoch's σ gets the turn term
/// ([`SigmaMaps::yaw_s`]). Below it the speed sets the error and the first map's σ is
/// nearly flat in the raw σ, so a second map over both would mix slow epochs with
/// turns at speed (on simulated cars at 0.5–2 m/s that cost 4–8 points within 1σ).
pub const TURN_SPEED: f32 = 2.0;

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
        self.apply_beyond(raw_deg, f32::INFINITY)
    }

    /// [`apply`](Self::apply), but from `from` times the last knot's raw σ on, the
    /// reported σ grows in proportion to the raw σ instead of staying at the last
    /// knot's: the fit's data end at its last knot, and a receiver the fit has not met
    /// may go far beyond it ([`CAR_BEYOND_K`]).
    pub fn apply_beyond(&self, raw_deg: f32, from: f32) -> f32 {
        if self.is_identity() || !raw_deg.is_finite() {
            return raw_deg.min(MAX_STD_DEG);
        }
        let (x, y) = (&self.raw_deg, &self.reported_deg);
        let last = SIGMA_KNOTS - 1;
        let out = if raw_deg <= x[0] {
            y[0]
        } else if raw_deg >= x[last] {
            y[last] * (raw_deg / (from * x[last])).max(1.0)
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
    /// turns: on held-out simulated cars at 2 m/s and faster that left straights
    /// over-covered and fast turns far under (the turn-rate tables of
    /// models/reports/ghnet-temporal.md show the result; a lagging receiver's course
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
    ///
    /// [`Vehicle::scatter`]: crate::modes::Vehicle::scatter
    pub scatter_k: f32,
    /// Cars, moving at speed: the σ with its turn term to the reported σ (a turn's
    /// errors have heavier tails than a Gaussian term covers, so the sum is mapped
    /// again). Cars only: the simulated platforms turn in place below [`TURN_SPEED`],
    /// so the only other vehicles at speed there are cars not yet known to be cars,
    /// no basis for a real platform's map.
    pub car_turn: SigmaMap,
}

/// Times the last knot's raw σ from which a moving car's reported σ grows in
/// proportion to its raw σ ([`SigmaMap::apply_beyond`]) rather than staying at the
/// last knot's (about 5°). The car map is fitted on simulated receivers whose slow
/// answers beyond its last knot (about 5.6° raw) still erred little; a receiver
/// noisier than its sAcc says makes such answers at 1–2 m/s err by 20° and more. On
/// the shared real drive with 0.2 m/s of noise added and its sAcc kept
/// (`models/reports/noisy-real.md`) they were answered at σ 5°; as the map stood, the
/// braking before a stop was outside 2σ and the stop's heading, averaged from those
/// answers as if sure, too. From the last knot itself (1), the held-out cars and the
/// shared drive went over 76% within 1σ; from 1.5 times it, they stay within 76%.
pub const CAR_BEYOND_K: f32 = 1.5;

/// A receiver is clean when the noise the filter measured at rest is under this share
/// of the speed accuracy it reports: its held headings lack the heavy tail of
/// receivers noisier than they say (measured on the recipe's validation standing cars).
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

    /// The reported σ (degrees) for a raw σ in degrees: a moving car's grows beyond its
    /// map's range ([`CAR_BEYOND_K`]).
    pub fn apply(&self, car: bool, moving: bool, clean: bool, raw_deg: f32) -> f32 {
        let from = if car && moving {
            CAR_BEYOND_K
        } else {
            f32::INFINITY
        };
        self.map(car, moving, clean).apply_beyond(raw_deg, from)
    }

    /// The reported σ (degrees) of an epoch of class `car` whose class map gave
    /// `mapped_deg`, at yaw rate `yaw` (rad/s): for a car moving at [`TURN_SPEED`] or
    /// faster, the turn term added in quadrature and mapped again. Slower cars and
    /// standing epochs take their class map's σ as it is: there the speed sets the error
    /// (and a held heading's turn is over). Other vehicles moving get
    /// [`PLATFORM_TURN_SHARE`] of the term from [`PLATFORM_TURN_SPEED`], added in
    /// quadrature and not mapped again (see `car_turn`), also when their answer is led
    /// ([`crate::modes::Step::lead_s`]): the lead takes out the least lag a filtering
    /// receiver has, and the share covers the rest, which no course shows. A static
    /// hold whose noise shows raw velocity ([`Smoothing::Raw`]) has no lag to cover: no
    /// share.
    pub fn with_turn(
        &self,
        car: bool,
        moving: bool,
        speed: f32,
        mapped_deg: f32,
        yaw: f32,
        smoothing: Smoothing,
    ) -> f32 {
        if !moving || self.yaw_s <= 0.0 || !yaw.is_finite() {
            return mapped_deg;
        }
        let term = self.yaw_s * yaw.abs().to_degrees();
        if !car {
            if speed < PLATFORM_TURN_SPEED || smoothing == Smoothing::Raw {
                return mapped_deg;
            }
            return mapped_deg.hypot(PLATFORM_TURN_SHARE * term);
        }
        if speed < TURN_SPEED {
            return mapped_deg;
        }
        self.car_turn.apply(mapped_deg.hypot(term))
    }

    /// The σ (degrees) of a car moving at [`TURN_SPEED`] or faster whose receiver
    /// reports no speed accuracy, with its lag term:
    /// `hypot(σ, LAG_NONE_S·max(|ω| − deadband, 0))`, ω in °/s, the deadband
    /// [`LAG_YAW_DEADBAND_DEG`] unless the receiver holds static (then none: see
    /// [`Smoothing::HoldsStatic`]).
    /// Everything else, and older files without a turn term, keeps its σ: other
    /// vehicles' share of the turn term ([`PLATFORM_TURN_SHARE`]) is the lag's already.
    pub fn with_lag(
        &self,
        smoothing: Smoothing,
        car: bool,
        moving: bool,
        speed: f32,
        sigma_deg: f32,
        yaw: f32,
    ) -> f32 {
        let deadband = match smoothing {
            Smoothing::Accuracy | Smoothing::Raw => return sigma_deg,
            Smoothing::Unknown => LAG_YAW_DEADBAND_DEG,
            Smoothing::HoldsStatic => 0.0,
        };
        if !car || !moving || self.yaw_s <= 0.0 || !yaw.is_finite() || speed < TURN_SPEED {
            return sigma_deg;
        }
        let turning = (yaw.abs().to_degrees() - deadband).max(0.0);
        sigma_deg.hypot(LAG_NONE_S * turning).min(MAX_STD_DEG)
    }
}

/// What a source's velocities say about its receiver's smoothing, which decides the lag
/// term of [`SigmaMaps::with_lag`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Smoothing {
    /// The receiver reports a speed accuracy (raw Doppler, u-blox): the turn term
    /// (`yaw_s`), fitted on such receivers, covers its lag.
    Accuracy,
    /// No speed accuracy: an NMEA or consumer unit whose velocity may be its navigation
    /// filter's output, or a raw one; a course's noise reads as turning up to
    /// [`LAG_YAW_DEADBAND_DEG`].
    Unknown,
    /// No speed accuracy, and the velocity holds static
    /// ([`crate::modes::Vehicle::holds_static`]): a navigation filter's output, whose
    /// course trails every turn, the gentle ones too, and is smooth enough not to read
    /// its noise as turning. With the deadband, simulated consumer cars' gentle turns
    /// (1.5–4 °/s) fell short of 90% within 2σ at 1, 5 and 10 Hz, their answers trailing
    /// the heading there (models/reports/unmet.md).
    HoldsStatic,
    /// No speed accuracy, a static hold, but white noise
    /// ([`crate::modes::Vehicle::raw_hold`]): raw velocity behind the hold, which does
    /// not trail a turn. No lag term.
    Raw,
}

impl Smoothing {
    /// The smoothing of a receiver that reports an sAcc (`has_acc`) or not, and whose
    /// velocity holds static or not. An sAcc decides first, a static hold second: the
    /// turn term this chooses for was fitted on receivers with sAcc, half of the
    /// simulated u-blox ones lagging, so it covers a filtered receiver's lag already,
    /// and a lag term on top would count it twice. [`ModeParams::lead_s`] and
    /// [`ModeParams::lever`] take a static hold first instead: they move the answer by
    /// a lag, and a static hold is the surest sign of a navigation filter's. No simulated
    /// receiver both reports sAcc and holds static, so which order serves such a
    /// receiver (a u-blox with its static hold on) is untested. A static hold whose
    /// noise shows raw velocity ([`Vehicle::raw_hold`]) has no lag to cover.
    ///
    /// [`ModeParams::lead_s`]: crate::modes::ModeParams
    /// [`ModeParams::lever`]: crate::modes::ModeParams
    /// [`Vehicle::raw_hold`]: crate::modes::Vehicle::raw_hold
    pub fn of(has_acc: bool, vehicle: &Vehicle) -> Self {
        if has_acc {
            Smoothing::Accuracy
        } else if !vehicle.holds_static() {
            Smoothing::Unknown
        } else if vehicle.raw_hold() {
            Smoothing::Raw
        } else {
            Smoothing::HoldsStatic
        }
    }
}

/// Seconds of yaw rate added in quadrature to the σ of a moving car whose receiver
/// reports no speed accuracy ([`SigmaMaps::with_lag`]). A course trails a turning
/// heading by `ω·τ`, τ the receiver's velocity lag, which the courses themselves cannot
/// show (every course trails alike). The turn term (`yaw_s`) is fitted on the recipes'
/// receivers, a third of them raw Doppler velocity (RTKLIB) without any lag; a receiver
/// without sAcc is an NMEA or consumer unit whose velocity is its navigation filter's
/// output, smoothed with a lag of up to a second or more. Without this term such
/// receivers' σ was too narrow at speed and in turns (the consumer and NMEA car
/// sections of models/reports/unmet.md); tuned there at 1, 5 and 10 Hz, held to the
/// turn bands of models/reports/ghnet-temporal.md and checked on simulated drives of
/// other seeds.
pub const LAG_NONE_S: f32 = 0.5;

/// Yaw rate (°/s) below which [`SigmaMaps::with_lag`] adds nothing, and which it
/// subtracts above, for a receiver not known to hold static ([`Smoothing::Unknown`]):
/// about what a receiver without sAcc reads as turning on a straight
/// at speed (a course noise near 1° at 1 Hz differences to about 1.4°/s), which is not
/// a turn its lag could trail. Without it the term widened the gentle turns (1.5–4
/// °/s) of the held-out cars, already the best covered, past 80% within 1σ.
pub const LAG_YAW_DEADBAND_DEG: f32 = 1.5;

/// Share of the turn term ([`SigmaMaps::yaw_s`]) a vehicle not known to be a car gets
/// while it moves. A course trails a turning heading by the receiver's lag whatever
/// carries it, and the platform map, fitted on all turn rates pooled, leaves a
/// platform that turns as it drives under-covered in its turns and over-covered on
/// straights (the robots' speed rows of models/reports/unmet.md). `yaw_s` is
/// fitted on cars, whose course also leads the heading by the antenna's lever arm
/// in a curve (the antenna a metre or two ahead of the rear axle); a platform's
/// antenna sits near its turning centre, which leaves about the lag's share.
///
/// A receiver that does not lag (raw Doppler velocity, RTKLIB) is over-covered in
/// its turns by this share (the robots' RTKLIB rows of models/reports/unmet.md). Only
/// a static hold ([`crate::modes::Vehicle::holds_static`]) shows a navigation filter
/// online, and only there does the whiteness of the noise say that the filter passes
/// raw velocity ([`crate::modes::Vehicle::raw_hold`]: no share): the simulator's
/// other styles add their noise after their lag, so a lagging u-blox or NMEA
/// receiver's velocity is as white as a raw one's and the test cannot be tuned there.
pub const PLATFORM_TURN_SHARE: f32 = 0.5;

/// Speed (m/s) from which a moving platform's σ gets its share of the turn term:
/// slower, the course's noise over the speed reads as turning in the yaw rate, and the
/// map's σ, large there, already covers the turns.
pub const PLATFORM_TURN_SPEED: f32 = 1.0;

#[cfg(test)]
mod tests {
    use super::*;

    /// A yaw rate of 10 °/s (rad/s) and maps with turn term `yaw_s` (identity maps).
    fn turning(yaw_s: f32) -> (f32, SigmaMaps) {
        let maps = SigmaMaps {
            yaw_s,
            ..SigmaMaps::default()
        };
        (10f32.to_radians(), maps)
    }

    /// The turn term grows the σ of a car moving at speed in quadrature (identity turn
    /// map: the sum as it is) and leaves slow and standing cars and older files (no
    /// term) alone; a platform moving at [`PLATFORM_TURN_SPEED`] or faster gets its
    /// share of the term, unmapped.
    #[test]
    fn turn_term_adds_in_quadrature_for_moving_vehicles() {
        let (ten, maps) = turning(0.4);
        let filter = Smoothing::Unknown;
        for yaw in [ten, -ten] {
            assert!((maps.with_turn(true, true, 8.0, 3.0, yaw, filter) - 5.0).abs() < 1e-4);
        }
        assert_eq!(
            SigmaMaps::default().with_turn(true, true, 8.0, 3.0, ten, filter),
            3.0
        );
        let platform = 3f32.hypot(PLATFORM_TURN_SHARE * 4.0);
        let s = maps.with_turn(false, true, 1.5, 3.0, ten, filter);
        assert!((s - platform).abs() < 1e-4);
        let kept = [
            ((true, true, 1.5, filter), "slow"),
            ((true, false, 8.0, filter), "standing"),
            ((false, true, 0.5, filter), "creeping"),
            ((false, true, 1.5, Smoothing::Raw), "raw hold"),
            ((false, false, 1.5, filter), "standing platform"),
        ];
        for ((car, moving, speed, smoothing), what) in kept {
            let s = maps.with_turn(car, moving, speed, 3.0, ten, smoothing);
            assert_eq!(s, 3.0, "{what}");
        }
    }

    /// A car whose receiver has no sAcc gets the lag term in quadrature while moving
    /// at [`TURN_SPEED`] or faster and turning faster than the deadband (at any rate
    /// when its receiver holds static); one with sAcc,
    /// another vehicle (whose turn share is the lag's), a straight, a standing or slow
    /// epoch and an older file (no turn term) do not.
    #[test]
    fn lag_term_widens_only_receivers_without_accuracy() {
        let (ten, maps) = turning(1.0);
        let lagged = 3f32.hypot(LAG_NONE_S * (10.0 - LAG_YAW_DEADBAND_DEG));
        for yaw in [ten, -ten] {
            let s = maps.with_lag(Smoothing::Unknown, true, true, 8.0, 3.0, yaw);
            assert!((s - lagged).abs() < 1e-4);
        }
        // A receiver that holds static lags in gentle turns too: no deadband.
        let gentle = 1.0f32.to_radians();
        let s = maps.with_lag(Smoothing::HoldsStatic, true, true, 8.0, 3.0, gentle);
        assert!((s - 3f32.hypot(LAG_NONE_S)).abs() < 1e-4);
        let s = maps.with_lag(Smoothing::Unknown, true, true, 8.0, 3.0, gentle);
        assert_eq!(s, 3.0, "within the deadband");
        let straight = LAG_YAW_DEADBAND_DEG.to_radians();
        let (none, acc) = (Smoothing::Unknown, Smoothing::Accuracy);
        let kept = [
            ((none, false, true, 8.0, ten), "platform"),
            ((acc, true, true, 8.0, ten), "has sAcc"),
            (
                (Smoothing::Raw, true, true, 8.0, ten),
                "raw velocity behind a hold",
            ),
            ((none, true, false, 8.0, ten), "standing"),
            ((none, true, true, 1.5, ten), "slow car"),
            ((none, true, true, 8.0, straight), "straight"),
        ];
        for ((smoothing, car, moving, speed, yaw), what) in kept {
            let s = maps.with_lag(smoothing, car, moving, speed, 3.0, yaw);
            assert_eq!(s, 3.0, "{what}");
        }
        let old = SigmaMaps::default();
        assert_eq!(
            old.with_lag(Smoothing::HoldsStatic, true, true, 8.0, 3.0, ten),
            3.0,
            "older file"
        );
    }

    /// A moving car's σ stays at its map's last knot up to [`CAR_BEYOND_K`] times that
    /// knot's raw σ and grows in proportion beyond; a standing car's and a moving
    /// platform's stay at their last knots however large the raw σ.
    #[test]
    fn a_moving_cars_sigma_grows_beyond_its_maps_range() {
        let map = SigmaMap {
            raw_deg: std::array::from_fn(|i| 1.0 + i as f32),
            reported_deg: std::array::from_fn(|i| 0.5 * (1.0 + i as f32)),
        };
        let maps = SigmaMaps {
            car: map,
            car_still: map,
            platform: map,
            ..SigmaMaps::default()
        };
        let last = SIGMA_KNOTS as f32;
        let at = |car, moving, raw| maps.apply(car, moving, false, raw);
        assert_eq!(at(true, true, last), 0.5 * last);
        assert_eq!(at(true, true, CAR_BEYOND_K * last), 0.5 * last);
        let far = 3.0 * CAR_BEYOND_K * last;
        assert!((at(true, true, far) - 1.5 * last).abs() < 1e-4);
        assert_eq!(at(true, false, far), 0.5 * last);
        assert_eq!(at(false, true, far), 0.5 * last);
        assert_eq!(at(true, true, 1e6), MAX_STD_DEG);
    }
}
