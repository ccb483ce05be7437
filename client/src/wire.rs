//! The two message types that cross process boundaries, and their byte codec.
//!
//! Both structs are `#[repr(C)]` with every byte accounted for by a named field
//! (explicit `_pad`/`_reserved` fields instead of compiler-inserted padding), so a C
//! struct, a Python `ctypes.Structure` or a NumPy dtype with the same fields in the
//! same order has exactly the same layout. `client/README.md` has a table per struct;
//! the `layout` unit tests pin size, alignment and every offset so the table cannot
//! drift silently.
//!
//! The `#[type_name(..)]` strings are part of the wire contract: iceoryx2 refuses to
//! connect two processes whose payload type names, sizes or alignments differ
//! (`IncompatibleTypes`). Changing a struct therefore means a new type name.

use iceoryx2::prelude::*;
use serde::{Deserialize, Serialize};

/// iceoryx2 type name of [`VelocitySample`]; other languages must use this exact string.
pub const VELOCITY_SAMPLE_TYPE_NAME: &str = "ghnet::VelocitySample";
/// iceoryx2 type name of [`HeadingEstimate`]; other languages must use this exact string.
pub const HEADING_ESTIMATE_TYPE_NAME: &str = "ghnet::HeadingEstimate";

/// Length of [`HeadingEstimate::model_name`] in bytes.
pub const MODEL_NAME_LEN: usize = 16;

/// Bits of [`VelocitySample::flags`].
///
/// Bits are "negative" on purpose: a publisher that knows nothing about flags sends
/// `0` and gets the normal treatment. Bits 3..=31 are reserved, must be sent as zero
/// and are ignored by the daemon (so new bits can be added without breaking readers).
pub mod flags {
    /// The receiver itself marked this velocity as invalid (no fix, failed RAIM, ...).
    /// The daemon answers with [`HeadingStatus::InvalidInput`](super::HeadingStatus).
    pub const INVALID: u32 = 1 << 0;
    /// `v_down` is not provided; the daemon ignores its value (it may be NaN).
    pub const V_DOWN_UNKNOWN: u32 = 1 << 1;
    /// The sample was produced by a simulator or a log replay, not a live receiver.
    /// Informational only: the daemon treats it like any other sample.
    pub const SIMULATED: u32 = 1 << 2;
    /// All bits defined so far.
    pub const KNOWN: u32 = INVALID | V_DOWN_UNKNOWN | SIMULATED;
}

/// One GNSS velocity measurement, published by a source on `<prefix>/<source>/velocity`.
///
/// Velocities are `f32` because that is what the model consumes and because GNSS
/// Doppler velocities are good to about a centimetre per second, far above `f32`
/// resolution (about 8 µm/s at 100 m/s). Integers that must not lose precision
/// (time, sequence) are `u64`.
///
/// 40 bytes, alignment 8, no implicit padding. See `client/README.md` for the table.
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend, Serialize, Deserialize)]
#[repr(C)]
#[type_name("ghnet::VelocitySample")]
pub struct VelocitySample {
    /// Time of validity of the velocity in nanoseconds since the Unix epoch (UTC,
    /// ideally GNSS-derived, else the host's `CLOCK_REALTIME`). The daemon only checks
    /// that it does not go backwards per source, and echoes it.
    pub timestamp_ns: u64,
    /// Per-source sequence number, +1 for every sample. Lets the daemon count gaps
    /// (lost samples) and duplicates; it is echoed in the answer so a client can match
    /// answers to samples.
    pub seq: u64,
    /// Velocity towards true north in m/s.
    pub v_north: f32,
    /// Velocity towards east in m/s.
    pub v_east: f32,
    /// Velocity downwards in m/s (NED convention). Ignored if
    /// [`flags::V_DOWN_UNKNOWN`] is set.
    pub v_down: f32,
    /// 1σ speed accuracy reported by the receiver in m/s; NaN when unknown.
    /// Negative or infinite values are invalid input.
    pub speed_accuracy: f32,
    /// Bitfield, see [`flags`].
    pub flags: u32,
    /// Explicit padding to the 8-byte alignment; send zero.
    pub _reserved: u32,
}

impl VelocitySample {
    /// Size on the wire in bytes.
    pub const SIZE: usize = 40;

    /// A sample with the given time, sequence and NED velocity, unknown accuracy and no
    /// flags: the common case for a publisher.
    pub fn new(timestamp_ns: u64, seq: u64, v_north: f32, v_east: f32, v_down: f32) -> Self {
        Self {
            timestamp_ns,
            seq,
            v_north,
            v_east,
            v_down,
            speed_accuracy: f32::NAN,
            flags: 0,
            _reserved: 0,
        }
    }
}

/// Quality of a [`HeadingEstimate`], carried as `u32` in [`HeadingEstimate::status`].
///
/// The wire field is a plain `u32` rather than this enum because the struct lives in
/// shared memory written by other processes (possibly other languages): an
/// out-of-range value in a Rust enum would be undefined behaviour, an unknown `u32`
/// is merely [`None`] from [`HeadingStatus::from_u32`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[repr(u32)]
pub enum HeadingStatus {
    /// Heading is valid and its standard deviation is within the model's policy.
    Ok = 0,
    /// Moving, but too slowly for a trustworthy heading (std above the policy limit);
    /// the heading and std are still filled in.
    LowSpeed = 1,
    /// Stopped with no heading known (speed below the stationary threshold, or a
    /// temporal model's stand before its history has a heading): heading is not
    /// observable. The fields carry whatever the model computed; do not use them.
    Stationary = 2,
    /// The input was rejected (non-finite value, speed above the limit, negative
    /// accuracy, receiver-flagged invalid, timestamp going backwards). Heading fields
    /// are NaN.
    InvalidInput = 3,
    /// The source has sent nothing for longer than ghnetd's `sources.stale_after_ms`
    /// (default 2.5 s): a publisher that crashed, hung or lost its receiver. Sent ONCE
    /// per silence, *not* an answer to a sample: `seq` and `timestamp_ns` repeat the
    /// last sample's, heading, std, atan2 and speed are NaN, `processing_ns` is 0.
    /// Consumers that match answers to samples skip it; a filter stops trusting the
    /// last heading. When samples come again they are answered normally.
    Stale = 4,
    /// The vehicle is stopped and the heading is the one it had when it stopped, kept
    /// from this source's history (temporal models only): a car does not turn while
    /// standing, so the heading it came to the stop with stays the best estimate (a
    /// car's is the mean of its answers over the last seconds of driving, unless it
    /// turned into the stop: the last, slowest courses are the noisiest). Stopped is the
    /// model's call (the epoch's course was not used), so a noisy receiver at rest is
    /// `Held` even where its speed looks like motion, but never past the motion: 0.8 s
    /// (and at least two epochs) of plain motion on a steady course end a stop, and a
    /// source configured as a robot (it turns in place) is `Held` only over the first
    /// epoch or two of a stop, with a σ near the uniform one. `heading_std_deg` grows
    /// with the time stopped; use it with that σ, once per stop: every `Held` answer of
    /// a stop carries the same error, so a filter that fused each as new would grow
    /// sure of it. Clients built before this status existed see an unknown value and
    /// treat it as not `Ok`.
    Held = 5,
}

impl HeadingStatus {
    /// Decodes the wire value; `None` for values this version does not know (a newer
    /// daemon may add statuses).
    pub fn from_u32(v: u32) -> Option<Self> {
        Some(match v {
            0 => Self::Ok,
            1 => Self::LowSpeed,
            2 => Self::Stationary,
            3 => Self::InvalidInput,
            4 => Self::Stale,
            5 => Self::Held,
            _ => return None,
        })
    }

    /// The wire value.
    pub fn as_u32(self) -> u32 {
        self as u32
    }
}

/// The daemon's answer to exactly one [`VelocitySample`], published on
/// `<prefix>/<source>/heading`.
///
/// Headings are degrees clockwise from true north in `[0, 360)`. 64 bytes (one cache
/// line), alignment 8, no implicit padding. See `client/README.md` for the table.
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend, Serialize, Deserialize)]
#[repr(C)]
#[type_name("ghnet::HeadingEstimate")]
pub struct HeadingEstimate {
    /// [`VelocitySample::timestamp_ns`] of the input, echoed.
    pub timestamp_ns: u64,
    /// [`VelocitySample::seq`] of the input, echoed, to match answers to samples.
    pub seq: u64,
    /// Time the daemon spent on this sample, from taking it out of the subscriber to
    /// handing the answer to the publisher, in nanoseconds.
    pub processing_ns: u64,
    /// Model heading in degrees clockwise from north, `[0, 360)`; NaN when
    /// [`status`](Self::status) is `InvalidInput`, meaningless when `Stationary`.
    pub heading_deg: f32,
    /// 1σ uncertainty of `heading_deg` in degrees as predicted by the model; NaN when
    /// the heading is NaN.
    pub heading_std_deg: f32,
    /// Plain `atan2(v_east, v_north)` heading in degrees, `[0, 360)`, as a model-free
    /// reference; NaN for invalid input.
    pub atan2_deg: f32,
    /// Horizontal speed `sqrt(v_north² + v_east²)` in m/s; NaN when `v_north` or
    /// `v_east` is not finite. `InvalidInput` answers carry it too (e.g. a speed above
    /// ghnetd's `model.max_speed`).
    pub speed: f32,
    /// Stable 32-bit id of the model weights (a hash), so consumers can tell models
    /// apart even when names collide.
    pub model_id: u32,
    /// A [`HeadingStatus`] as `u32`; decode with [`HeadingEstimate::heading_status`].
    pub status: u32,
    /// Model name, ASCII, NUL-padded; truncated to 16 bytes (then not NUL-terminated).
    pub model_name: [u8; MODEL_NAME_LEN],
}

impl HeadingEstimate {
    /// Size on the wire in bytes.
    pub const SIZE: usize = 64;

    /// The decoded [`status`](Self::status), `None` if unknown to this version.
    pub fn heading_status(&self) -> Option<HeadingStatus> {
        HeadingStatus::from_u32(self.status)
    }

    /// [`model_name`](Self::model_name) without the NUL padding. Bytes that are not
    /// UTF-8 (only a foreign writer could produce them) end the name.
    pub fn model_name_str(&self) -> &str {
        let end = self
            .model_name
            .iter()
            .position(|&c| c == 0)
            .unwrap_or(MODEL_NAME_LEN);
        match std::str::from_utf8(&self.model_name[..end]) {
            Ok(s) => s,
            Err(e) => std::str::from_utf8(&self.model_name[..e.valid_up_to()]).unwrap_or(""),
        }
    }

    /// Encodes a model name for [`model_name`](Self::model_name): NUL-padded,
    /// truncated to [`MODEL_NAME_LEN`] bytes at a character boundary.
    pub fn encode_model_name(name: &str) -> [u8; MODEL_NAME_LEN] {
        let mut out = [0u8; MODEL_NAME_LEN];
        let mut end = name.len().min(MODEL_NAME_LEN);
        while !name.is_char_boundary(end) {
            end -= 1;
        }
        out[..end].copy_from_slice(&name.as_bytes()[..end]);
        out
    }
}

/// A byte buffer had the wrong length for the message type being decoded.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("wrong message length: expected {expected} bytes, got {actual}")]
pub struct CodecError {
    /// Size of the message type.
    pub expected: usize,
    /// Length of the buffer that was given.
    pub actual: usize,
}

/// `b` as an array of exactly `N` bytes.
fn exactly<const N: usize>(b: &[u8]) -> Result<&[u8; N], CodecError> {
    b.try_into().map_err(|_| CodecError {
        expected: N,
        actual: b.len(),
    })
}

/// A field of the wire layout: its little-endian bytes, written and read in place.
trait LeField: Sized {
    /// Bytes on the wire.
    const N: usize;
    fn put(&self, b: &mut [u8]);
    fn get(b: &[u8]) -> Self;
}

macro_rules! le_number {
    ($($t:ty),*) => {$(
        impl LeField for $t {
            const N: usize = std::mem::size_of::<$t>();
            fn put(&self, b: &mut [u8]) {
                b[..Self::N].copy_from_slice(&self.to_le_bytes());
            }
            fn get(b: &[u8]) -> Self {
                <$t>::from_le_bytes(b[..Self::N].try_into().expect("N bytes"))
            }
        }
    )*};
}
le_number!(u32, u64, f32);

impl<const K: usize> LeField for [u8; K] {
    const N: usize = K;
    fn put(&self, b: &mut [u8]) {
        b[..K].copy_from_slice(self);
    }
    fn get(b: &[u8]) -> Self {
        b[..K].try_into().expect("K bytes")
    }
}

/// The little-endian codec of a wire struct from its fields in layout order (the
/// order of the `#[repr(C)]` declaration, no implicit padding), written once for
/// both directions.
macro_rules! le_codec {
    ($t:ty: $($f:ident),* $(,)?) => {
        impl $t {
            /// Encodes into the wire layout, little-endian, for transports without
            /// shared memory (files, Zenoh). Identical to the in-memory bytes on
            /// little-endian hosts.
            pub fn to_le_bytes(&self) -> [u8; Self::SIZE] {
                let mut b = [0u8; Self::SIZE];
                let mut at = 0;
                $(
                    LeField::put(&self.$f, &mut b[at..]);
                    at += field_len(&self.$f);
                )*
                debug_assert_eq!(at, Self::SIZE);
                b
            }

            /// Decodes the layout written by [`to_le_bytes`](Self::to_le_bytes).
            pub fn from_le_bytes(b: &[u8; Self::SIZE]) -> Self {
                let mut at = 0;
                let v = Self {
                    $($f: {
                        let v = LeField::get(&b[at..]);
                        at += field_len(&v);
                        v
                    },)*
                };
                debug_assert_eq!(at, Self::SIZE);
                v
            }

            /// Decodes from a slice that must be exactly [`Self::SIZE`] bytes long.
            pub fn from_le_slice(b: &[u8]) -> Result<Self, CodecError> {
                Ok(Self::from_le_bytes(exactly(b)?))
            }
        }
    };
}

/// Bytes of a field on the wire (type inference picks the field's [`LeField`]).
fn field_len<T: LeField>(_: &T) -> usize {
    T::N
}

le_codec! {
    VelocitySample: timestamp_ns, seq, v_north, v_east, v_down, speed_accuracy, flags, _reserved
}
le_codec! {
    HeadingEstimate: timestamp_ns, seq, processing_ns, heading_deg, heading_std_deg, atan2_deg,
    speed, model_id, status, model_name
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::mem::{align_of, offset_of, size_of};

    /// Size, alignment and every field's offset of `$t`.
    macro_rules! assert_layout {
        ($t:ty, size $size:expr, align $align:expr, { $($field:ident: $offset:expr),* $(,)? }) => {
            assert_eq!(size_of::<$t>(), $size);
            assert_eq!(size_of::<$t>(), <$t>::SIZE);
            assert_eq!(align_of::<$t>(), $align);
            $(assert_eq!(offset_of!($t, $field), $offset, stringify!($field));)*
        };
    }

    /// These numbers are the tables in client/README.md. If this test fails, the wire
    /// changed: update the README, the type name, and every foreign mirror.
    #[test]
    fn layouts_are_the_documented_tables() {
        assert_layout!(VelocitySample, size 40, align 8, {
            timestamp_ns: 0, seq: 8, v_north: 16, v_east: 20, v_down: 24,
            speed_accuracy: 28, flags: 32, _reserved: 36,
        });
        assert_layout!(HeadingEstimate, size 64, align 8, {
            timestamp_ns: 0, seq: 8, processing_ns: 16, heading_deg: 24,
            heading_std_deg: 28, atan2_deg: 32, speed: 36, model_id: 40, status: 44,
            model_name: 48,
        });
        assert_eq!(size_of::<[u8; MODEL_NAME_LEN]>(), 16);
    }

    #[test]
    fn type_names_are_the_documented_ones() {
        // Foreign clients hard-code these strings; a silent change breaks them.
        assert_eq!(
            unsafe { <VelocitySample as ZeroCopySend>::type_name() },
            VELOCITY_SAMPLE_TYPE_NAME
        );
        assert_eq!(
            unsafe { <HeadingEstimate as ZeroCopySend>::type_name() },
            HEADING_ESTIMATE_TYPE_NAME
        );
    }

    #[test]
    fn codec_matches_in_memory_layout() {
        let v = VelocitySample {
            timestamp_ns: 0x0102_0304_0506_0708,
            seq: 42,
            v_north: 1.5,
            v_east: -2.25,
            v_down: 0.125,
            speed_accuracy: f32::NAN,
            flags: flags::SIMULATED,
            _reserved: 0,
        };
        let bytes = v.to_le_bytes();
        // SAFETY: VelocitySample is repr(C) without implicit padding, so all 40 bytes
        // are initialised and may be viewed as u8.
        let mem: [u8; 40] = unsafe { std::mem::transmute(v) };
        if cfg!(target_endian = "little") {
            assert_eq!(bytes, mem);
        }
        let back = VelocitySample::from_le_bytes(&bytes);
        assert_eq!(back.to_le_bytes(), bytes, "NaN-safe round trip by bytes");
        assert_eq!(back.seq, 42);

        let h = HeadingEstimate {
            timestamp_ns: 7,
            seq: 8,
            processing_ns: 9,
            heading_deg: 359.5,
            heading_std_deg: 1.0,
            atan2_deg: 0.5,
            speed: 3.0,
            model_id: 0xdead_beef,
            status: HeadingStatus::LowSpeed.as_u32(),
            model_name: HeadingEstimate::encode_model_name("ghnet-full"),
        };
        let bytes = h.to_le_bytes();
        let mem: [u8; 64] = unsafe { std::mem::transmute(h) };
        if cfg!(target_endian = "little") {
            assert_eq!(bytes, mem);
        }
        assert_eq!(HeadingEstimate::from_le_bytes(&bytes), h);
        assert_eq!(HeadingEstimate::from_le_slice(&bytes[..]), Ok(h));
        assert_eq!(
            HeadingEstimate::from_le_slice(&bytes[..63]),
            Err(CodecError {
                expected: 64,
                actual: 63
            })
        );
        assert!(VelocitySample::from_le_slice(&[0u8; 41]).is_err());
    }

    #[test]
    fn status_round_trip_and_unknown_values() {
        for s in [
            HeadingStatus::Ok,
            HeadingStatus::LowSpeed,
            HeadingStatus::Stationary,
            HeadingStatus::InvalidInput,
            HeadingStatus::Stale,
            HeadingStatus::Held,
        ] {
            assert_eq!(HeadingStatus::from_u32(s.as_u32()), Some(s));
        }
        assert_eq!(HeadingStatus::Held.as_u32(), 5);
        assert_eq!(HeadingStatus::from_u32(6), None);
        assert_eq!(HeadingStatus::from_u32(u32::MAX), None);
    }

    #[test]
    fn model_name_padding_and_truncation() {
        let n = HeadingEstimate::encode_model_name("paper-s1");
        assert_eq!(&n[..8], b"paper-s1");
        assert!(n[8..].iter().all(|&c| c == 0));
        let mut h = HeadingEstimate::from_le_bytes(&[0; 64]);
        h.model_name = n;
        assert_eq!(h.model_name_str(), "paper-s1");
        h.model_name = HeadingEstimate::encode_model_name("a-very-long-model-name");
        assert_eq!(h.model_name_str(), "a-very-long-mode");
        // Multi-byte characters are never split.
        h.model_name = HeadingEstimate::encode_model_name("ééééééééé");
        assert_eq!(h.model_name_str(), "éééééééé");
    }

    #[test]
    fn flag_bits_are_distinct() {
        assert_eq!(flags::INVALID & flags::V_DOWN_UNKNOWN, 0);
        assert_eq!(flags::KNOWN.count_ones(), 3);
    }
}
