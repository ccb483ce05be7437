//! The Zenoh payload of a [`HeadingEstimate`]: bincode 2 with fixed-width
//! little-endian integers.
//!
//! The product asked for bincode; the configuration is chosen so that the bytes are
//! nothing more than the fields concatenated in declaration order, each in its natural
//! little-endian width, with no length prefixes and no varints:
//!
//! - `config::standard()` would write integers as varints; `with_fixed_int_encoding()`
//!   makes every `u64` 8 bytes and every `u32` 4 bytes, and `with_little_endian()`
//!   (already the default, stated for the reader) fixes the byte order;
//! - `f32` is always its 4 IEEE-754 bytes (NaN payloads survive the round trip);
//! - `[u8; 16]` goes through serde as a *tuple*, which bincode writes without a
//!   length prefix (only slices, `Vec` and strings get one).
//!
//! So the payload is 64 bytes and equal to [`HeadingEstimate::to_le_bytes`], i.e. the
//! same table as the iceoryx2 layout in `client/README.md` ("Zenoh payload" section).
//! A unit test pins both facts, so a bincode upgrade that changed either would fail
//! here, not in a Python consumer.

use crate::wire::HeadingEstimate;

/// Length of a Zenoh heading payload in bytes (the 64-byte layout of `client/README.md`).
pub const ZENOH_HEADING_LEN: usize = HeadingEstimate::SIZE;

/// The bincode configuration of the Zenoh wire. One function so encoder and decoder
/// cannot drift apart.
fn config() -> impl bincode::config::Config {
    bincode::config::standard()
        .with_fixed_int_encoding()
        .with_little_endian()
        // A heading is 64 bytes; refuse to look further into a hostile payload.
        .with_limit::<ZENOH_HEADING_LEN>()
}

/// A Zenoh payload that is not a heading. Returned, never panicked on: payloads come
/// from the network and anyone can publish on a key.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum DecodeError {
    /// The payload is not exactly [`ZENOH_HEADING_LEN`] bytes (a truncated message, or
    /// another type published on the key).
    #[error("wrong heading payload length: expected {ZENOH_HEADING_LEN} bytes, got {0}")]
    Length(usize),
    /// bincode rejected the bytes (cannot happen for 64 bytes with today's field
    /// types, kept so a future field type with invalid bit patterns is an error too).
    #[error("undecodable heading payload: {0}")]
    Bincode(String),
}

/// Encodes `h` as the Zenoh payload: 64 bytes, fields concatenated little-endian.
///
/// Writes into a fixed array (no allocation), so the daemon can call it per sample.
pub fn encode_zenoh(h: &HeadingEstimate) -> [u8; ZENOH_HEADING_LEN] {
    let mut out = [0u8; ZENOH_HEADING_LEN];
    // Cannot fail: every field has a fixed size and the sum is exactly 64 bytes.
    let n = bincode::serde::encode_into_slice(h, &mut out, config())
        .expect("a HeadingEstimate always encodes into 64 bytes");
    debug_assert_eq!(n, ZENOH_HEADING_LEN);
    out
}

/// Decodes a Zenoh heading payload; any other length or content is a [`DecodeError`].
///
/// ```
/// use ghnet_client::{decode_zenoh, encode_zenoh, HeadingEstimate};
/// let h = HeadingEstimate::from_le_bytes(&[0; 64]);
/// assert_eq!(decode_zenoh(&encode_zenoh(&h)), Ok(h));
/// assert!(decode_zenoh(b"not a heading").is_err());
/// ```
pub fn decode_zenoh(bytes: &[u8]) -> Result<HeadingEstimate, DecodeError> {
    if bytes.len() != ZENOH_HEADING_LEN {
        return Err(DecodeError::Length(bytes.len()));
    }
    let (h, used): (HeadingEstimate, usize) = bincode::serde::decode_from_slice(bytes, config())
        .map_err(|e| DecodeError::Bincode(e.to_string()))?;
    if used != ZENOH_HEADING_LEN {
        return Err(DecodeError::Length(used));
    }
    Ok(h)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::wire::HeadingStatus;
    use proptest::prelude::*;

    fn known() -> HeadingEstimate {
        HeadingEstimate {
            timestamp_ns: 0x0102_0304_0506_0708,
            seq: 0x1112_1314_1516_1718,
            processing_ns: 12_345,
            heading_deg: 359.5,
            heading_std_deg: 1.25,
            atan2_deg: f32::NAN,
            speed: 3.0,
            model_id: 0xdead_beef,
            status: HeadingStatus::LowSpeed.as_u32(),
            model_name: HeadingEstimate::encode_model_name("ghnet-full"),
        }
    }

    /// The "Zenoh payload" table in client/README.md, offset by offset. If this fails,
    /// the Zenoh wire changed: every foreign decoder (examples/python) breaks.
    #[test]
    fn layout_is_the_documented_table() {
        let h = known();
        let b = encode_zenoh(&h);
        assert_eq!(b.len(), 64);
        assert_eq!(b[0..8], 0x0102_0304_0506_0708u64.to_le_bytes());
        assert_eq!(b[8..16], 0x1112_1314_1516_1718u64.to_le_bytes());
        assert_eq!(b[16..24], 12_345u64.to_le_bytes());
        assert_eq!(b[24..28], 359.5f32.to_le_bytes());
        assert_eq!(b[28..32], 1.25f32.to_le_bytes());
        assert_eq!(b[32..36], f32::NAN.to_le_bytes());
        assert_eq!(b[36..40], 3.0f32.to_le_bytes());
        assert_eq!(b[40..44], [0xef, 0xbe, 0xad, 0xde]);
        assert_eq!(b[44..48], 1u32.to_le_bytes());
        assert_eq!(&b[48..58], b"ghnet-full");
        assert_eq!(b[58..64], [0u8; 6], "NUL padding, no length prefix");
        // Same bytes as the iceoryx2 layout's codec: one table for both transports.
        assert_eq!(b, h.to_le_bytes());
    }

    #[test]
    fn round_trip_keeps_every_bit() {
        let h = known();
        let back = decode_zenoh(&encode_zenoh(&h)).unwrap();
        assert_eq!(back.to_le_bytes(), h.to_le_bytes(), "NaN-safe comparison");
    }

    #[test]
    fn wrong_lengths_are_errors() {
        let b = encode_zenoh(&known());
        assert_eq!(decode_zenoh(&b[..63]), Err(DecodeError::Length(63)));
        assert_eq!(decode_zenoh(&[]), Err(DecodeError::Length(0)));
        let mut long = b.to_vec();
        long.push(0);
        assert_eq!(decode_zenoh(&long), Err(DecodeError::Length(65)));
    }

    #[test]
    fn huge_payload_is_a_length_error_without_decoding() {
        let big = vec![0x5au8; 4 << 20];
        assert_eq!(decode_zenoh(&big), Err(DecodeError::Length(4 << 20)));
        // Every byte value in every position of a 64-byte payload decodes (no field has
        // invalid bit patterns today), so the decoder's only error is the length.
        for v in [0x00u8, 0x7f, 0x80, 0xff] {
            assert!(decode_zenoh(&[v; 64]).is_ok(), "{v:#x}");
        }
    }

    proptest! {
        /// Arbitrary bytes never panic the decoder; 64 bytes always decode, to the
        /// same bytes.
        #[test]
        fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..200)) {
            match decode_zenoh(&bytes) {
                Ok(h) => {
                    prop_assert_eq!(bytes.len(), 64);
                    prop_assert_eq!(&encode_zenoh(&h)[..], &bytes[..]);
                }
                Err(_) => prop_assert_ne!(bytes.len(), 64),
            }
        }

        #[test]
        fn any_64_bytes_round_trip(bytes in proptest::array::uniform32(any::<u8>()), tail in proptest::array::uniform32(any::<u8>())) {
            let mut b = [0u8; 64];
            b[..32].copy_from_slice(&bytes);
            b[32..].copy_from_slice(&tail);
            let h = decode_zenoh(&b).unwrap();
            prop_assert_eq!(encode_zenoh(&h), b);
        }
    }
}
