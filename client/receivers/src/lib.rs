//! `ghnet_receivers`: what GNSS receivers send, as plain velocity epochs.
//!
//! Streaming parsers of u-blox UBX (NAV-PVT), NMEA 0183 (RMC, VTG, GGA, GLL, GNS,
//! ZDA) and gpsd's JSON (TPV), with format detection, into one [`Epoch`] type. No
//! IPC and no iceoryx2: the bridge `ghnet-gnss` publishes the epochs to ghnetd, the
//! lab's `ghnet infer` reads receiver logs through the same code.
//!
//! # Layout
//!
//! - [`epoch`] — [`Epoch`] (time, NED velocity, speed accuracy, validity, the
//!   receiver's own course) and [`Format`]; [`split_course`], the one rule for a
//!   speed without a course.
//! - [`decoder`] — [`Decoder`], the entry point: a given format or detection from
//!   the first epoch; [`decode`] for a whole recording.
//! - [`ubx`] — [`UbxDecoder`] and the NAV-PVT codec [`NavPvt`] (parse, encode a
//!   checksummed frame, to and from an [`Epoch`]): simulators write UBX logs with it.
//! - [`nmea`] — [`NmeaDecoder`]: sentences tied into cycles by their time of day.
//! - [`gpsd`] — [`GpsdDecoder`] and the `?WATCH` command.
//! - [`stats`] — [`Stats`] and [`Skip`]: every byte that gives no epoch is counted
//!   under a reason (garbage, bad checksum, truncated, other message, ...).
//! - [`time`] — UTC calendar arithmetic (civil date ↔ days, NMEA and ISO 8601 times)
//!   without a date library.
//! - `lines` (private) — bounded line reassembly for the two text protocols.
//!
//! # Guarantees
//!
//! Every decoder takes bytes in arbitrary chunks and gives the same epochs as for the
//! whole stream at once; it resynchronises after garbage, truncated frames and bad
//! checksums; it never panics and its memory is bounded, whatever the input (fuzzed
//! with proptest in `tests/fuzz.rs`). Real receiver captures with their expected
//! epoch counts are in `tests/data` (provenance and licence in its README).
//!
//! ```
//! use ghnet_receivers::{decode, Format};
//! let log = b"$GPRMC,143307.00,A,5546.82649,N,02334.71625,E,30.860,221.48,091209,,,A*5D\r\n";
//! let d = decode(log, None);
//! assert_eq!(d.format, Some(Format::Nmea));
//! let e = d.epochs[0];
//! assert!(e.valid && e.v_down.is_none() && e.speed_accuracy.is_nan());
//! assert!((e.speed() - 15.875).abs() < 1e-3); // 30.86 knots in m/s
//! ```

#![warn(missing_docs)]

pub mod decoder;
pub mod epoch;
pub mod gpsd;
mod lines;
pub mod nmea;
pub mod stats;
#[cfg(test)]
mod testing;
pub mod time;
pub mod ubx;

pub use decoder::{decode, Decoded, Decoder};
pub use epoch::{split_course, Epoch, Format, UnknownFormat, COURSE_MISSING_MAX_SPEED};
pub use gpsd::GpsdDecoder;
pub use nmea::NmeaDecoder;
pub use stats::{Skip, Stats};
pub use ubx::{NavPvt, UbxDecoder};
