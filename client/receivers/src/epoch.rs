//! [`Epoch`], the one plain result every parser produces, and [`Format`].

use std::fmt;
use std::str::FromStr;

/// The receiver protocol a byte stream speaks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Format {
    /// u-blox UBX binary; epochs come from NAV-PVT (class 0x01, id 0x07).
    Ubx,
    /// NMEA 0183 text; epochs come from RMC (or VTG where a receiver sends no RMC).
    Nmea,
    /// gpsd's JSON reports; epochs come from TPV.
    Gpsd,
}

impl Format {
    /// Every format, in the order auto-detection prefers them when several match
    /// (UBX carries a speed accuracy, gpsd's TPV a vertical speed, NMEA neither).
    pub const ALL: [Format; 3] = [Format::Ubx, Format::Gpsd, Format::Nmea];

    /// The name used on the command line (`--format ubx|nmea|gpsd`).
    pub fn name(self) -> &'static str {
        match self {
            Format::Ubx => "ubx",
            Format::Nmea => "nmea",
            Format::Gpsd => "gpsd",
        }
    }
}

impl fmt::Display for Format {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// `--format` got a name that is not `ubx`, `nmea` or `gpsd`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct UnknownFormat(pub String);

impl fmt::Display for UnknownFormat {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "unknown format `{}` (expected ubx, nmea or gpsd)",
            self.0
        )
    }
}

impl std::error::Error for UnknownFormat {}

impl FromStr for Format {
    type Err = UnknownFormat;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Format::ALL
            .into_iter()
            .find(|f| f.name().eq_ignore_ascii_case(s))
            .ok_or_else(|| UnknownFormat(s.to_owned()))
    }
}

/// One navigation epoch of a receiver, in the units of ghnet's `VelocitySample`.
///
/// Plain data, no IPC: the bridge (`ghnet-gnss`) adds a sequence number and a
/// monotonic timestamp and publishes it; the lab's `ghnet infer` compares ghnet's
/// heading with the receiver's own `course_deg` on the same epochs.
///
/// "Unknown" is explicit everywhere: `None` for time and vertical speed, NaN for the
/// accuracies and the receiver's course. A receiver that blanks its course at a
/// standstill gives `course_deg = NaN` and `v_north = v_east = 0`, never a made-up
/// 0° course.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Epoch {
    /// Time of validity, ns since the Unix epoch (UTC), when the receiver gave a valid
    /// date and time; `None` otherwise (no fix yet, or a time-of-day without a date).
    pub time_ns: Option<u64>,
    /// Velocity towards true north, m/s. NaN when the receiver gave no usable
    /// velocity (then `valid` is false).
    pub v_north: f32,
    /// Velocity towards east, m/s (NaN as `v_north`).
    pub v_east: f32,
    /// Velocity downwards (NED), m/s; `None` when the protocol has none (NMEA).
    pub v_down: Option<f32>,
    /// 1σ speed accuracy, m/s; NaN when unknown (NMEA unless configured).
    pub speed_accuracy: f32,
    /// `false` when the receiver itself marks the velocity unusable: no fix, fix
    /// type or mode indicator not a GNSS fix, status "void", or no velocity at all.
    /// Published with the `INVALID` flag.
    pub valid: bool,
    /// The receiver's own course over ground, degrees clockwise from true north in
    /// `[0, 360)`: u-blox `headMot` (frozen at a standstill), NMEA/gpsd course.
    /// NaN when the receiver gave none.
    pub course_deg: f32,
    /// The receiver's accuracy of `course_deg`, degrees (u-blox `headAcc`); NaN when
    /// unknown.
    pub course_accuracy_deg: f32,
}

impl Epoch {
    /// An epoch the receiver marked unusable: no velocity, nothing known but `time_ns`.
    pub fn invalid(time_ns: Option<u64>) -> Self {
        Epoch {
            time_ns,
            v_north: f32::NAN,
            v_east: f32::NAN,
            v_down: None,
            speed_accuracy: f32::NAN,
            valid: false,
            course_deg: f32::NAN,
            course_accuracy_deg: f32::NAN,
        }
    }

    /// Horizontal speed `hypot(v_north, v_east)`, m/s.
    pub fn speed(&self) -> f32 {
        self.v_north.hypot(self.v_east)
    }
}

/// Ground speed above which a receiver that gives a speed but no course is taken to
/// be moving in an unknown direction (epoch invalid) rather than standing still.
///
/// Receivers blank the course field when they consider themselves stationary (an
/// ANTARIS in gpsd's `bt451.log` does it at 0.13–0.19 m/s); such an epoch is
/// answered as a standstill (`v = 0`, course NaN). Above a brisk walk every consumer
/// receiver reports a course, so a missing one means a broken sentence.
pub const COURSE_MISSING_MAX_SPEED: f32 = 1.0;

/// Splits a ground speed and a course (degrees from true north, `None` when the
/// receiver left it empty) into `(v_north, v_east, valid)`.
///
/// With no course: a standstill (`0, 0, true`) up to
/// [`COURSE_MISSING_MAX_SPEED`], an unknown direction (`NaN, NaN, false`) above it.
pub fn split_course(speed: f32, course_deg: Option<f32>) -> (f32, f32, bool) {
    match course_deg {
        Some(c) if c.is_finite() => {
            let (s, c) = (f64::from(speed), f64::from(c).to_radians());
            ((s * c.cos()) as f32, (s * c.sin()) as f32, true)
        }
        _ if speed <= COURSE_MISSING_MAX_SPEED => (0.0, 0.0, true),
        _ => (f32::NAN, f32::NAN, false),
    }
}

/// Wraps a course in degrees into `[0, 360)`; NaN stays NaN.
pub fn wrap_deg(deg: f32) -> f32 {
    let w = deg.rem_euclid(360.0);
    // rem_euclid of a tiny negative number rounds up to exactly 360.0 in f32.
    if w >= 360.0 {
        0.0
    } else {
        w
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn formats_parse_and_print() {
        for f in Format::ALL {
            assert_eq!(f.name().parse::<Format>(), Ok(f));
            assert_eq!(f.to_string().to_uppercase().parse::<Format>(), Ok(f));
        }
        assert!("sirf".parse::<Format>().is_err());
    }

    #[test]
    fn course_split_and_standstill() {
        let (n, e, ok) = split_course(2.0, Some(90.0));
        assert!(ok && n.abs() < 1e-6 && (e - 2.0).abs() < 1e-6);
        assert_eq!(split_course(0.3, None), (0.0, 0.0, true));
        let (n, _, ok) = split_course(5.0, None);
        assert!(!ok && n.is_nan());
        assert_eq!(wrap_deg(360.0), 0.0);
        assert_eq!(wrap_deg(-90.0), 270.0);
        assert_eq!(wrap_deg(-1e-9), 0.0);
    }
}
