//! The rules of the bridge without I/O: a [`HeadingEstimate`] becomes an [`Imu`]
//! ([`SourceState::to_imu`]), and a source's last answer and counters become its
//! [`DiagnosticStatus`] ([`SourceState::diagnostic`]). The live loop, the tests and
//! the docs all go through these two functions.
//!
//! # Status in ROS terms
//!
//! | ghnet status | orientation | `orientation_covariance` |
//! |---|---|---|
//! | `Ok`, `LowSpeed` | yaw from the heading | `[0]`,`[4]` = [`UNKNOWN_VARIANCE`], `[8]` = σ² |
//! | `Held`, first of a stop | yaw from the heading | as `Ok` |
//! | `Held`, later in the same stop | yaw from the heading | as `Ok` but `[0]` = −1 |
//! | `Stationary`, `InvalidInput`, `Stale`, unknown | identity | `[0]` = −1, rest 0 |
//!
//! `[0] = -1` is `sensor_msgs/Imu`'s "no orientation estimate": a filter that fuses
//! every usable message fuses a stop once (every `Held` answer of a stop carries the
//! same error). A stop ends at the first answer that is neither `Held` nor `Stale`.

use std::time::Duration;

use ghnet_client::{HeadingEstimate, HeadingStatus};

use crate::msg::{DiagnosticStatus, Header, Imu, KeyValue, Level, Quaternion, Time, Vector3};

/// Variance (rad²) of roll and pitch, which GNSS velocity does not observe: large
/// enough that any filter ignores them.
pub const UNKNOWN_VARIANCE: f64 = 1.0e6;

/// Silence after which `/diagnostics` calls a source STALE even without ghnetd's
/// `Stale` message (ghnetd sends one after 2.5 s by default, unless it died).
pub const SILENT_AFTER: Duration = Duration::from_secs(5);

/// `covariance[0]` of a quantity the message does not carry.
pub const NO_ESTIMATE: f64 = -1.0;

/// The covariance of angular velocity and linear acceleration: not measured.
const NOT_MEASURED: [f64; 9] = [NO_ESTIMATE, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];

/// ENU yaw (rad, counter-clockwise from east) of a heading (deg, clockwise from
/// north): `90° − heading`, wrapped into `(−π, π]`.
pub fn yaw_of_heading(heading_deg: f32) -> f64 {
    let mut yaw = 90.0 - f64::from(heading_deg);
    yaw = yaw.rem_euclid(360.0);
    if yaw > 180.0 {
        yaw -= 360.0;
    }
    yaw.to_radians()
}

/// What the bridge knows about one source: the stop it is in, its last answer, its
/// counters.
#[derive(Debug, Clone, Default)]
pub struct SourceState {
    /// Whether the last answer (not counting `Stale`) was `Held`.
    in_stop: bool,
    /// The last message ghnetd sent for the source.
    pub last: Option<HeadingEstimate>,
    /// Counters shown in `/diagnostics`.
    pub counters: Counters,
}

/// Counts of one source, as `/diagnostics` shows them.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Counters {
    /// Messages from ghnetd relayed to ROS (every status).
    pub relayed: u64,
    /// Of those, sent with `orientation_covariance[0] = -1`.
    pub without_orientation: u64,
    /// Messages the ROS side did not take (DDS write refused, Zenoh put failed).
    pub send_failures: u64,
    /// Messages lost between ghnetd and the bridge (gaps in `seq` on iceoryx2).
    pub missed: u64,
}

impl SourceState {
    /// The Imu for `h`, advancing the stop state. `frame_id` goes into the header.
    pub fn to_imu(&mut self, h: &HeadingEstimate, frame_id: &str) -> Imu {
        let status = h.heading_status();
        let first_of_stop = status == Some(HeadingStatus::Held) && !self.in_stop;
        match status {
            Some(HeadingStatus::Held) => self.in_stop = true,
            Some(HeadingStatus::Stale) => {}
            _ => self.in_stop = false,
        }
        self.last = Some(*h);
        let usable =
            matches!(status, Some(HeadingStatus::Ok | HeadingStatus::LowSpeed)) || first_of_stop;
        let has_heading = matches!(
            status,
            Some(HeadingStatus::Ok | HeadingStatus::LowSpeed | HeadingStatus::Held)
        ) && h.heading_deg.is_finite()
            && h.heading_std_deg.is_finite();
        let (orientation, mut cov) = if has_heading {
            let sigma = f64::from(h.heading_std_deg).to_radians();
            let mut cov = [0.0; 9];
            (cov[0], cov[4], cov[8]) = (UNKNOWN_VARIANCE, UNKNOWN_VARIANCE, sigma * sigma);
            (Quaternion::from_yaw(yaw_of_heading(h.heading_deg)), cov)
        } else {
            (Quaternion::IDENTITY, [0.0; 9])
        };
        if !(usable && has_heading) {
            cov[0] = NO_ESTIMATE;
            self.counters.without_orientation += 1;
        }
        self.counters.relayed += 1;
        Imu {
            header: Header {
                stamp: Time::from_unix_ns(h.timestamp_ns),
                frame_id: frame_id.to_owned(),
            },
            orientation,
            orientation_covariance: cov,
            angular_velocity: Vector3::default(),
            angular_velocity_covariance: NOT_MEASURED,
            linear_acceleration: Vector3::default(),
            linear_acceleration_covariance: NOT_MEASURED,
        }
    }

    /// The source's `DiagnosticStatus`, named `ghnet: <source>`. `publishers` is the
    /// number of ghnetd publishers on its heading service (0: ghnetd is not serving
    /// it); `silent` the time since ghnetd's last message (`None`: never). Either
    /// makes the status STALE whatever the last answer was: a ghnetd that was killed
    /// sends no `Stale` message, and its dead publisher counts until iceoryx2 cleans
    /// it up.
    pub fn diagnostic(
        &self,
        source: &str,
        topic: &str,
        publishers: usize,
        silent: Option<Duration>,
    ) -> DiagnosticStatus {
        let status = self.last.map(|h| h.heading_status());
        let quiet = silent.filter(|s| *s > SILENT_AFTER);
        let (level, message) = match (publishers, status, quiet) {
            (0, _, _) => (Level::Stale, "ghnetd is not serving this source".to_owned()),
            (_, None, _) => (Level::Stale, "no answer from ghnetd yet".to_owned()),
            (_, Some(s), Some(q)) if s != Some(HeadingStatus::Stale) => (
                Level::Stale,
                format!("no message from ghnetd for {:.0} s", q.as_secs_f64()),
            ),
            (_, Some(s), _) => level_of(s),
        };
        let fmt_f32 = |v: Option<f32>| v.map_or("nan".to_owned(), |v| v.to_string());
        let c = &self.counters;
        let mut values = vec![
            kv("status", status_name(status)),
            kv("heading_deg", fmt_f32(self.last.map(|h| h.heading_deg))),
            kv(
                "heading_std_deg",
                fmt_f32(self.last.map(|h| h.heading_std_deg)),
            ),
            kv(
                "seq",
                self.last.map_or("none".into(), |h| h.seq.to_string()),
            ),
            kv("topic", topic.to_owned()),
            kv("ghnetd_publishers", publishers.to_string()),
            kv(
                "silent_s",
                silent.map_or("none".into(), |d| format!("{:.1}", d.as_secs_f64())),
            ),
        ];
        values.extend([
            kv("relayed", c.relayed.to_string()),
            kv("without_orientation", c.without_orientation.to_string()),
            kv("send_failures", c.send_failures.to_string()),
            kv("missed", c.missed.to_string()),
        ]);
        DiagnosticStatus {
            level: level as u8,
            name: format!("ghnet: {source}"),
            message,
            hardware_id: source.to_owned(),
            values,
        }
    }
}

fn kv(key: &str, value: impl Into<String>) -> KeyValue {
    KeyValue {
        key: key.to_owned(),
        value: value.into(),
    }
}

/// Level and message of a source whose last message had `status`.
fn level_of(status: Option<HeadingStatus>) -> (Level, String) {
    let (level, text) = match status {
        Some(HeadingStatus::Ok) => (Level::Ok, "heading ok"),
        Some(HeadingStatus::Stationary) => (Level::Ok, "stationary: heading not observable"),
        Some(HeadingStatus::LowSpeed) => (Level::Warn, "low speed: heading uncertain"),
        Some(HeadingStatus::Held) => (Level::Warn, "stopped: heading held"),
        Some(HeadingStatus::InvalidInput) => (Level::Error, "invalid input"),
        Some(HeadingStatus::Stale) => (Level::Stale, "source silent (stale)"),
        None => (Level::Error, "unknown status from a newer ghnetd"),
    };
    (level, text.to_owned())
}

/// The `status` value shown in `/diagnostics`: ghnet's status names in snake case.
pub fn status_name(status: Option<Option<HeadingStatus>>) -> String {
    match status {
        None => "none".to_owned(),
        Some(None) => "unknown".to_owned(),
        Some(Some(s)) => match s {
            HeadingStatus::Ok => "ok",
            HeadingStatus::LowSpeed => "low_speed",
            HeadingStatus::Stationary => "stationary",
            HeadingStatus::InvalidInput => "invalid_input",
            HeadingStatus::Stale => "stale",
            HeadingStatus::Held => "held",
        }
        .to_owned(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn answer(status: HeadingStatus, heading: f32, std: f32) -> HeadingEstimate {
        HeadingEstimate {
            timestamp_ns: 1_700_000_000_250_000_000,
            seq: 7,
            processing_ns: 1,
            heading_deg: heading,
            heading_std_deg: std,
            atan2_deg: heading,
            speed: 3.0,
            model_id: 1,
            status: status.as_u32(),
            model_name: [0; 16],
        }
    }

    #[test]
    fn heading_becomes_an_enu_yaw_quaternion() {
        let mut s = SourceState::default();
        // North (0°) is ENU yaw +90°, east (90°) is 0, south −90°, west 180°.
        for (heading, yaw) in [(0.0, 90.0), (90.0, 0.0), (180.0, -90.0), (270.0, 180.0)] {
            let imu = s.to_imu(&answer(HeadingStatus::Ok, heading, 2.0), "gnss");
            let q = imu.orientation;
            let want = Quaternion::from_yaw(f64::to_radians(yaw));
            assert!((q.z - want.z).abs() < 1e-12 && (q.w - want.w).abs() < 1e-12);
            assert_eq!((q.x, q.y), (0.0, 0.0));
            let cov = imu.orientation_covariance;
            assert_eq!((cov[0], cov[4]), (UNKNOWN_VARIANCE, UNKNOWN_VARIANCE));
            assert!((cov[8] - 2f64.to_radians().powi(2)).abs() < 1e-15);
            assert_eq!(imu.angular_velocity_covariance[0], -1.0);
            assert_eq!(imu.linear_acceleration_covariance[0], -1.0);
            assert_eq!(
                imu.header.stamp,
                Time::from_unix_ns(1_700_000_000_250_000_000)
            );
            assert_eq!(imu.header.frame_id, "gnss");
        }
    }

    #[test]
    fn a_stop_is_usable_once() {
        use HeadingStatus::*;
        let mut s = SourceState::default();
        let seq = [
            Ok,
            Held,
            Held,
            Stale,
            Held,
            LowSpeed,
            Held,
            Held,
            Stationary,
            InvalidInput,
        ];
        let usable: Vec<bool> = seq
            .iter()
            .map(|st| {
                s.to_imu(&answer(*st, 10.0, 3.0), "gnss")
                    .orientation_covariance[0]
                    > 0.0
            })
            .collect();
        let want = [
            true, true, false, false, false, true, true, false, false, false,
        ];
        assert_eq!(usable, want);
        assert_eq!(s.counters.relayed, 10);
        assert_eq!(s.counters.without_orientation, 6);
    }

    #[test]
    fn diagnostics_follow_the_last_status() {
        let mut s = SourceState::default();
        let d = s.diagnostic("gnss0", "/ghnet/gnss0/heading", 1, None);
        assert_eq!(
            (d.level, d.name.as_str()),
            (Level::Stale as u8, "ghnet: gnss0")
        );
        for (status, level) in [
            (HeadingStatus::Ok, Level::Ok),
            (HeadingStatus::LowSpeed, Level::Warn),
            (HeadingStatus::Held, Level::Warn),
            (HeadingStatus::InvalidInput, Level::Error),
            (HeadingStatus::Stale, Level::Stale),
        ] {
            s.to_imu(&answer(status, 10.0, 3.0), "gnss");
            assert_eq!(
                s.diagnostic("gnss0", "t", 1, Some(Duration::ZERO)).level,
                level as u8,
                "{status:?}"
            );
        }
        assert_eq!(
            s.diagnostic("gnss0", "t", 0, None).level,
            Level::Stale as u8
        );
        s.to_imu(&answer(HeadingStatus::Ok, 10.0, 3.0), "gnss");
        let long = Some(SILENT_AFTER + Duration::from_secs(1));
        assert_eq!(
            s.diagnostic("gnss0", "t", 1, long).level,
            Level::Stale as u8
        );
        let keys: Vec<String> = s
            .diagnostic("gnss0", "t", 1, None)
            .values
            .into_iter()
            .map(|kv| kv.key)
            .collect();
        for k in [
            "status",
            "heading_deg",
            "heading_std_deg",
            "relayed",
            "send_failures",
        ] {
            assert!(keys.iter().any(|x| x == k), "{k}");
        }
    }
}
