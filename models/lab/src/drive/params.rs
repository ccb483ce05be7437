//! What the drive simulator is asked for: the vehicles and receiver styles it draws
//! from and the parameters of a data set.

use serde::{Deserialize, Serialize};

/// What moves.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum Platform {
    /// A car: bicycle-model steering, parks and reverses.
    Car,
    /// A differential-drive robot or Segway: turns in place.
    TurnInPlace,
}

/// How the receiver reports velocity.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum ReceiverKind {
    /// Raw velocity in mm/s and a rough sAcc (σ times 0.7–1.5).
    Ublox,
    /// Raw velocity and a nearly constant formal σ (RTKLIB's Doppler solution).
    Rtklib,
    /// Speed and course only: course frozen below 0.1 m/s, no accuracy.
    Nmea,
    /// A consumer receiver (phone, low-cost module): velocity smoothed with a lag of
    /// 0.5–1.5 s, its noise smoothed by the same lag, exactly 0.000 below a speed of 0.3–0.6 m/s (so the first moving
    /// epoch jumps from zero), no accuracy. Held out of the shipped recipes: it is how
    /// the tables show σ on a receiver the model has not met.
    Consumer,
    /// A u-blox with its static hold on (an automotive setting): smoothed, lagged and
    /// snapped to 0.000 at rest as the consumer style, but with the u-blox sAcc
    /// (σ times 0.7–1.5), which at rest describes no noise the receiver shows. Held out
    /// of the shipped recipes.
    UbloxHold,
    /// A receiver that snaps to 0.000 at rest as the consumer style does but passes its
    /// raw velocity through without a lag, and reports no accuracy: only its noise,
    /// white where the consumer style's is smoothed, tells it from the consumer style,
    /// whose lag the model leads (`Vehicle::raw_hold` in ghnet-inference). Held out of
    /// the shipped recipes.
    Snap,
}

/// Parameters of [`simulate`](super::simulate).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, clap::Args)]
#[serde(default)]
pub struct DriveParams {
    /// Number of tracks.
    #[arg(long, default_value_t = 200)]
    pub tracks: usize,
    /// Share of tracks that are turn-in-place platforms (the rest are cars).
    #[arg(long, default_value_t = 0.3)]
    pub platform_share: f64,
    /// Shortest track, s.
    #[arg(long, default_value_t = 300.0)]
    pub track_min_s: f64,
    /// Longest track, s.
    #[arg(long, default_value_t = 1200.0)]
    pub track_max_s: f64,
    /// Output rates to draw from, Hz (each track draws one).
    #[arg(long, value_delimiter = ',', default_value = "1,2,5,10")]
    pub rates_hz: Vec<u32>,
    /// Smallest per-axis velocity noise σ (m/s).
    #[arg(long, default_value_t = 0.02)]
    pub sigma_min: f64,
    /// Largest per-axis velocity noise σ (m/s).
    #[arg(long, default_value_t = 0.3)]
    pub sigma_max: f64,
    /// Largest receiver lag (first-order time constant, s); each track draws 0..this.
    #[arg(long, default_value_t = 1.5)]
    pub lag_max_s: f64,
    /// Fix gaps per minute (Poisson).
    #[arg(long, default_value_t = 0.3)]
    pub gaps_per_min: f64,
    /// Glitch probability per epoch.
    #[arg(long, default_value_t = 5e-4)]
    pub p_glitch: f64,
    /// Stretches of poor sky (urban canyons: multipath) per minute (Poisson), each
    /// 10 s to `bad_sky_max_s` long.
    #[arg(long, default_value_t = 0.1)]
    pub bad_sky_per_min: f64,
    /// Longest stretch of poor sky, s.
    #[arg(long, default_value_t = 90.0)]
    pub bad_sky_max_s: f64,
    /// Glitch probability per epoch under poor sky.
    #[arg(long, default_value_t = 0.1)]
    pub p_glitch_bad: f64,
    /// Share of tracks in validation.
    #[arg(long, default_value_t = 0.15)]
    pub val_fraction: f64,
    /// Share of tracks in test.
    #[arg(long, default_value_t = 0.15)]
    pub test_fraction: f64,
    /// Receiver styles to draw from (each track draws one).
    #[arg(
        long,
        value_enum,
        value_delimiter = ',',
        default_value = "ublox,rtklib,nmea"
    )]
    pub receivers: Vec<ReceiverKind>,
    /// Turn-in-place platforms: slowest and fastest cruising speed, m/s.
    #[arg(long, value_delimiter = ',', default_value = "0.5,1.8")]
    pub platform_speed: Vec<f64>,
    /// Turn-in-place platforms: slowest and fastest spin at a stop, °/s.
    #[arg(long, value_delimiter = ',', default_value = "10,90")]
    pub platform_spin: Vec<f64>,
    /// Turn-in-place platforms: share of stops with a spin.
    #[arg(long, default_value_t = 0.6)]
    pub platform_spin_share: f64,
    /// Times its usual sAcc (the noise σ times 0.7–1.5) a u-blox reports: many report
    /// several times the noise they show.
    #[arg(long, default_value_t = 1.0)]
    pub sacc_scale: f64,
}

impl Default for DriveParams {
    fn default() -> Self {
        Self {
            tracks: 200,
            platform_share: 0.3,
            track_min_s: 300.0,
            track_max_s: 1200.0,
            rates_hz: vec![1, 2, 5, 10],
            sigma_min: 0.02,
            sigma_max: 0.3,
            lag_max_s: 1.5,
            gaps_per_min: 0.3,
            p_glitch: 5e-4,
            bad_sky_per_min: 0.1,
            bad_sky_max_s: 90.0,
            p_glitch_bad: 0.1,
            val_fraction: 0.15,
            test_fraction: 0.15,
            receivers: vec![
                ReceiverKind::Ublox,
                ReceiverKind::Rtklib,
                ReceiverKind::Nmea,
            ],
            platform_speed: vec![0.5, 1.8],
            platform_spin: vec![10.0, 90.0],
            platform_spin_share: 0.6,
            sacc_scale: 1.0,
        }
    }
}

impl DriveParams {
    /// The robots the shipped recipes do not train on: differential-drive platforms
    /// that cruise at 0.3–2 m/s and spin in place at 20–60 °/s at most stops, as a
    /// held-out style for the tables.
    pub fn robots(mut self) -> Self {
        self.platform_share = 1.0;
        self.platform_speed = vec![0.3, 2.0];
        self.platform_spin = vec![20.0, 60.0];
        self.platform_spin_share = 0.9;
        self
    }

    /// `(lo, hi)` of a two-value range parameter, or `default` when it is malformed.
    pub(super) fn range(v: &[f64], default: (f64, f64)) -> (f64, f64) {
        match v {
            [lo, hi] if lo.is_finite() && hi.is_finite() && lo <= hi => (*lo, *hi),
            _ => default,
        }
    }
}
