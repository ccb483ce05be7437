//! The ROS 2 messages the bridge publishes, as plain structs whose serde order is the
//! field order of their `.msg` definitions: serialised with CDR (by ros2-client on
//! DDS, by `cdr-encoding` on Zenoh) they are byte for byte what a ROS 2 node expects.
//!
//! Only what the bridge sends is defined: `sensor_msgs/msg/Imu` with its
//! `std_msgs/Header`, `geometry_msgs` parts and `builtin_interfaces/Time`, and
//! `diagnostic_msgs/msg/DiagnosticArray`. ROS `byte` is `u8`, `float64` is `f64`, a
//! fixed array `float64[9]` is `[f64; 9]` (no length on the wire), an unbounded
//! sequence is a `Vec` (a `u32` length first).

use serde::{Deserialize, Serialize};

/// `builtin_interfaces/msg/Time`: seconds and nanoseconds since the Unix epoch.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Time {
    /// Whole seconds (`int32`).
    pub sec: i32,
    /// Nanoseconds within the second, `0..1e9` (`uint32`).
    pub nanosec: u32,
}

impl Time {
    /// The time of `ns` nanoseconds since the Unix epoch. `int32` seconds reach 2038;
    /// later times saturate rather than wrap (ROS 2 has the same limit).
    pub fn from_unix_ns(ns: u64) -> Self {
        let sec = (ns / 1_000_000_000).min(i32::MAX as u64) as i32;
        Time {
            sec,
            nanosec: (ns % 1_000_000_000) as u32,
        }
    }
}

/// `std_msgs/msg/Header`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Header {
    /// When the data was valid.
    pub stamp: Time,
    /// The tf2 frame the data is expressed in.
    pub frame_id: String,
}

/// `geometry_msgs/msg/Quaternion` (x, y, z, w).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Quaternion {
    /// x
    pub x: f64,
    /// y
    pub y: f64,
    /// z
    pub z: f64,
    /// w
    pub w: f64,
}

impl Quaternion {
    /// No rotation.
    pub const IDENTITY: Quaternion = Quaternion {
        x: 0.0,
        y: 0.0,
        z: 0.0,
        w: 1.0,
    };

    /// A rotation by `yaw` radians about z (counter-clockwise seen from above,
    /// REP-103): `(0, 0, sin(yaw/2), cos(yaw/2))`.
    pub fn from_yaw(yaw: f64) -> Self {
        let (s, c) = (yaw / 2.0).sin_cos();
        Quaternion {
            x: 0.0,
            y: 0.0,
            z: s,
            w: c,
        }
    }
}

/// `geometry_msgs/msg/Vector3`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Vector3 {
    /// x
    pub x: f64,
    /// y
    pub y: f64,
    /// z
    pub z: f64,
}

/// `sensor_msgs/msg/Imu`. Covariances are row-major 3×3 (x, y, z axes); element 0
/// set to −1 means "no estimate of this quantity" (the message's own convention).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Imu {
    /// Time of the GNSS sample and the frame of the antenna.
    pub header: Header,
    /// Attitude in the ENU world frame.
    pub orientation: Quaternion,
    /// Covariance of roll, pitch, yaw in rad².
    pub orientation_covariance: [f64; 9],
    /// Not measured (zero, covariance −1).
    pub angular_velocity: Vector3,
    /// `[0] = -1`: no angular velocity.
    pub angular_velocity_covariance: [f64; 9],
    /// Not measured (zero, covariance −1).
    pub linear_acceleration: Vector3,
    /// `[0] = -1`: no linear acceleration.
    pub linear_acceleration_covariance: [f64; 9],
}

/// `diagnostic_msgs/msg/KeyValue`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct KeyValue {
    /// The value's name.
    pub key: String,
    /// The value, as text.
    pub value: String,
}

/// `diagnostic_msgs/msg/DiagnosticStatus`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct DiagnosticStatus {
    /// [`Level`] as its `byte` value.
    pub level: u8,
    /// `ghnet: <source>`.
    pub name: String,
    /// One line for people.
    pub message: String,
    /// The source name: what the status is about.
    pub hardware_id: String,
    /// Named values for tools (`rqt_runtime_monitor`, aggregators).
    pub values: Vec<KeyValue>,
}

/// `diagnostic_msgs/msg/DiagnosticArray`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DiagnosticArray {
    /// When the array was made; no frame.
    pub header: Header,
    /// One per source.
    pub status: Vec<DiagnosticStatus>,
}

/// `DiagnosticStatus.level` values (the `byte` constants of the message).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum Level {
    /// `OK = 0`.
    Ok = 0,
    /// `WARN = 1`.
    Warn = 1,
    /// `ERROR = 2`.
    Error = 2,
    /// `STALE = 3`.
    Stale = 3,
}

/// A ROS message type: its package and name, for DDS type names and rmw_zenoh keys.
pub trait RosMessage: Serialize {
    /// e.g. `sensor_msgs`.
    const PACKAGE: &'static str;
    /// e.g. `Imu`.
    const NAME: &'static str;
}

impl RosMessage for Imu {
    const PACKAGE: &'static str = "sensor_msgs";
    const NAME: &'static str = "Imu";
}

impl RosMessage for DiagnosticArray {
    const PACKAGE: &'static str = "diagnostic_msgs";
    const NAME: &'static str = "DiagnosticArray";
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn time_splits_nanoseconds() {
        let t = Time::from_unix_ns(1_700_000_000_123_456_789);
        assert_eq!((t.sec, t.nanosec), (1_700_000_000, 123_456_789));
        assert_eq!(Time::from_unix_ns(u64::MAX).sec, i32::MAX);
    }

    #[test]
    fn yaw_quaternion_is_a_unit_rotation_about_z() {
        for yaw in [-3.0, -1.0, 0.0, 0.5, 3.1] {
            let q = Quaternion::from_yaw(yaw);
            let back = (2.0 * q.w * q.z).atan2(1.0 - 2.0 * q.z * q.z);
            assert!((back - yaw).abs() < 1e-12, "{yaw}");
            assert!((q.z * q.z + q.w * q.w - 1.0).abs() < 1e-12);
        }
    }
}
