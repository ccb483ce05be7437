//! [`Stats`]: what a decoder did with every byte, and [`Skip`], why it skipped some.

use std::fmt;

use crate::Epoch;

/// Why a decoder skipped input. Nothing is dropped silently: every byte that is not
/// part of an accepted message, and every accepted message that gave no epoch, is
/// counted under one of these.
///
/// [`Skip::Garbage`] counts bytes; every other reason counts messages (UBX frames,
/// NMEA sentences, JSON lines, comment lines).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Skip {
    /// Bytes outside any message: line noise, another protocol on the same port
    /// (RTCM3, or NMEA inside a UBX stream), the sync bytes of rejected frames, the
    /// body of a frame whose checksum failed.
    Garbage,
    /// `#` comment lines (gpsd's captures start with them).
    Comment,
    /// A frame or sentence whose checksum did not match.
    BadChecksum,
    /// A UBX header with an impossible length, or a line longer than the protocol
    /// allows.
    BadLength,
    /// A frame or line cut off by the end of the stream or a reconnect.
    Truncated,
    /// A well-framed message whose content could not be read (a NAV-PVT of the wrong
    /// size, an RMC with too few fields, invalid JSON, a TPV with an unreadable time).
    Malformed,
    /// A well-formed message of another kind (UBX NAV-SAT, NMEA GSV, gpsd SKY, ...).
    Other,
    /// A sentence whose content another one of the same epoch already gave (VTG or
    /// GGA beside an RMC).
    Redundant,
    /// A gpsd TPV with the same time as the epoch before: gpsd reports a fix again as
    /// more sentences of the same cycle arrive.
    Duplicate,
    /// A gpsd TPV older than the epoch before (gpsd interleaves reports from several
    /// messages, e.g. u-blox HNR-PVT and NAV-PVT).
    OutOfOrder,
    /// A gpsd TPV with a fix but neither `velN`/`velE` nor `speed` (gpsd fills them
    /// in from a later sentence of the same cycle).
    NoVelocity,
}

impl Skip {
    /// Every reason, in the order [`Stats`] prints them.
    pub const ALL: [Skip; 11] = [
        Skip::Garbage,
        Skip::Comment,
        Skip::BadChecksum,
        Skip::BadLength,
        Skip::Truncated,
        Skip::Malformed,
        Skip::Other,
        Skip::Redundant,
        Skip::Duplicate,
        Skip::OutOfOrder,
        Skip::NoVelocity,
    ];

    /// The name in logs and summary lines (`garbage_bytes`, `bad_checksum`, ...).
    pub fn name(self) -> &'static str {
        match self {
            Skip::Garbage => "garbage_bytes",
            Skip::Comment => "comment",
            Skip::BadChecksum => "bad_checksum",
            Skip::BadLength => "bad_length",
            Skip::Truncated => "truncated",
            Skip::Malformed => "malformed",
            Skip::Other => "other",
            Skip::Redundant => "redundant",
            Skip::Duplicate => "duplicate",
            Skip::OutOfOrder => "out_of_order",
            Skip::NoVelocity => "no_velocity",
        }
    }

    fn index(self) -> usize {
        self as usize
    }
}

/// Counters of one decoder: bytes in, bytes skipped, epochs out and every skip by
/// reason. After [`finish`](crate::Decoder::finish),
/// `bytes_in == bytes_used + bytes_skipped` (tests check it on fuzzed input).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Stats {
    bytes_in: u64,
    bytes_skipped: u64,
    epochs: u64,
    invalid_epochs: u64,
    skipped: [u64; Skip::ALL.len()],
}

impl Stats {
    /// Bytes pushed into the decoder.
    pub fn bytes_in(&self) -> u64 {
        self.bytes_in
    }

    /// Bytes that were not part of an accepted message (garbage, comments, rejected
    /// and truncated frames or lines).
    pub fn bytes_skipped(&self) -> u64 {
        self.bytes_skipped
    }

    /// Bytes of accepted messages (epochs, other kinds, redundant ones).
    pub fn bytes_used(&self) -> u64 {
        self.bytes_in - self.bytes_skipped
    }

    /// Epochs produced, valid or not.
    pub fn epochs(&self) -> u64 {
        self.epochs
    }

    /// Epochs produced with `valid == false`.
    pub fn invalid_epochs(&self) -> u64 {
        self.invalid_epochs
    }

    /// How many times input was skipped for `reason` (bytes for
    /// [`Skip::Garbage`], messages otherwise).
    pub fn skipped(&self, reason: Skip) -> u64 {
        self.skipped[reason.index()]
    }

    /// Nonzero skip counters, in [`Skip::ALL`] order.
    pub fn skips(&self) -> impl Iterator<Item = (Skip, u64)> + '_ {
        Skip::ALL
            .into_iter()
            .map(|r| (r, self.skipped(r)))
            .filter(|&(_, n)| n > 0)
    }

    pub(crate) fn add_input(&mut self, n: usize) {
        self.bytes_in += n as u64;
    }

    /// Counts one skipped message of `bytes` bytes (or, for [`Skip::Garbage`],
    /// `bytes` skipped bytes).
    pub(crate) fn skip(&mut self, reason: Skip, bytes: usize) {
        self.bytes_skipped += bytes as u64;
        let n = if reason == Skip::Garbage {
            bytes as u64
        } else {
            1
        };
        self.skipped[reason.index()] += n;
    }

    /// Counts a message that was accepted but gave no epoch (its bytes stay used).
    pub(crate) fn note(&mut self, reason: Skip) {
        self.skipped[reason.index()] += 1;
    }

    pub(crate) fn record(&mut self, epoch: &Epoch) {
        self.epochs += 1;
        if !epoch.valid {
            self.invalid_epochs += 1;
        }
    }
}

impl fmt::Display for Stats {
    /// `epochs=24 invalid=0 bytes=5054 skipped: comment=8 other=28`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "epochs={} invalid={} bytes={}",
            self.epochs, self.invalid_epochs, self.bytes_in
        )?;
        let mut first = true;
        for (reason, n) in self.skips() {
            f.write_str(if first { " skipped:" } else { "" })?;
            write!(f, " {}={n}", reason.name())?;
            first = false;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_bytes_and_messages_apart() {
        let mut s = Stats::default();
        s.add_input(100);
        s.skip(Skip::Garbage, 7);
        s.skip(Skip::BadChecksum, 20);
        s.note(Skip::Other);
        s.record(&Epoch::invalid(None));
        assert_eq!(s.skipped(Skip::Garbage), 7);
        assert_eq!(s.skipped(Skip::BadChecksum), 1);
        assert_eq!((s.bytes_skipped(), s.bytes_used()), (27, 73));
        assert_eq!(
            s.to_string(),
            "epochs=1 invalid=1 bytes=100 skipped: garbage_bytes=7 bad_checksum=1 other=1"
        );
        assert!(Skip::ALL.iter().enumerate().all(|(i, r)| r.index() == i));
    }
}
