//! u-blox UBX: a streaming frame decoder that turns NAV-PVT into [`Epoch`]s, and a
//! NAV-PVT encoder for simulators.
//!
//! Why a hand parser and not the `ublox` crate (0.10.0, MIT, five releases between
//! August 2025 and March 2026): it parses well, but (1) it skips garbage silently and
//! does not expose the length of the frames it returns, so skipped bytes cannot be
//! counted by reason; (2) NAV-PVT is a receive-only packet there (no builder), so
//! the encoder the lab needs would be hand-written anyway; (3) what we need is the
//! UBX framing (sync, length, 8-bit Fletcher checksum) and twelve fields at fixed
//! offsets. `ublox` stays as a dev-dependency: a test checks that both decode the
//! same fields from the real captures.
//!
//! Frame: `B5 62 class id len(u16 LE) payload[len] ck_a ck_b`, checksum over
//! `class..payload`.
//!
//! A simulator writes a UBX log from its epochs with [`NavPvt::from_epoch`] and
//! [`NavPvt::write_frame`]; reading it back gives the same epochs up to the
//! receiver's quantization (1 mm/s, 1e-5°):
//!
//! ```
//! use ghnet_receivers::{decode, ubx::NavPvt, Epoch, Format};
//! let epoch = Epoch {
//!     time_ns: Some(1_764_151_200_000_000_000), // 2025-11-26 10:00:00 UTC
//!     v_north: 3.0,
//!     v_east: 4.0,
//!     v_down: Some(-0.1),
//!     speed_accuracy: 0.2,
//!     valid: true,
//!     course_deg: f32::NAN, // NaN: the direction of the velocity, as a u-blox reports
//!     course_accuracy_deg: f32::NAN,
//! };
//! let mut log = Vec::new();
//! for i in 0..10 {
//!     let t = epoch.time_ns.map(|t| t + i * 100_000_000); // 10 Hz
//!     NavPvt::from_epoch(&Epoch { time_ns: t, ..epoch }).write_frame(&mut log);
//! }
//! assert_eq!(log.len(), 10 * 100);
//! let back = decode(&log, None);
//! assert_eq!((back.format, back.epochs.len()), (Some(Format::Ubx), 10));
//! assert!((back.epochs[0].course_deg - 53.130_102).abs() < 1e-4);
//! assert_eq!(back.epochs[9].time_ns, Some(1_764_151_200_900_000_000));
//! ```

use crate::epoch::wrap_deg;
use crate::stats::{Skip, Stats};
use crate::time::{civil_from_days, days_from_civil, ns_of_day, unix_ns, DAY_NS};
use crate::Epoch;

/// The two sync bytes that start every UBX frame.
pub const SYNC: [u8; 2] = [0xB5, 0x62];
/// Class of navigation results.
pub const CLASS_NAV: u8 = 0x01;
/// Message id of NAV-PVT within [`CLASS_NAV`].
pub const ID_NAV_PVT: u8 = 0x07;
/// NAV-PVT payload length from protocol 15 on (u-blox M8, M9, M10, F9).
pub const NAV_PVT_LEN: usize = 92;
/// NAV-PVT payload length of protocol 14 (u-blox 7): the same fields up to `pDOP`.
pub const NAV_PVT_LEN_PROTO14: usize = 84;
/// Sync, class, id and length.
const HEADER_LEN: usize = 6;
/// Header plus the two checksum bytes.
const OVERHEAD: usize = HEADER_LEN + 2;
/// Longest payload accepted. The largest frames real receivers send (RXM-RAWX,
/// MON-SPAN, NAV-SAT with every signal) stay well below; a corrupt length is
/// rejected at once instead of stalling the stream while waiting for its bytes.
pub const MAX_PAYLOAD: usize = 8192;

/// Message classes defined by u-blox (NAV, RXM, INF, ACK, CFG, UPD, MON, AID, TIM,
/// ESF, MGA, LOG, SEC, HNR, NAV2). A sync pair followed by another class is noise;
/// checking it keeps a false sync in garbage from holding up the real frames behind
/// it.
const KNOWN_CLASSES: [u8; 15] = [
    0x01, 0x02, 0x04, 0x05, 0x06, 0x09, 0x0A, 0x0B, 0x0D, 0x10, 0x13, 0x21, 0x27, 0x28, 0x29,
];

/// The 8-bit Fletcher checksum UBX puts after each frame, over class, id, length and
/// payload.
pub fn checksum(bytes: &[u8]) -> [u8; 2] {
    let (mut a, mut b) = (0u8, 0u8);
    for &x in bytes {
        a = a.wrapping_add(x);
        b = b.wrapping_add(a);
    }
    [a, b]
}

/// Appends a complete frame (sync, header, payload, checksum) to `out`.
///
/// # Panics
/// If `payload` is longer than [`MAX_PAYLOAD`] (a programming error, not input).
pub fn write_frame(class: u8, id: u8, payload: &[u8], out: &mut Vec<u8>) {
    assert!(payload.len() <= MAX_PAYLOAD, "UBX payload too long");
    let start = out.len();
    out.extend_from_slice(&SYNC);
    out.extend_from_slice(&[class, id]);
    out.extend_from_slice(&(payload.len() as u16).to_le_bytes());
    out.extend_from_slice(payload);
    let ck = checksum(&out[start + 2..]);
    out.extend_from_slice(&ck);
}

/// The NAV-PVT fields ghnet reads or a simulator should fill, in the receiver's own
/// units (mm/s, 1e-5 degrees, ...). Position fields are kept so an encoded frame is a
/// complete, plausible message.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct NavPvt {
    /// GPS time of week, ms.
    pub itow_ms: u32,
    /// UTC year.
    pub year: u16,
    /// UTC month, 1..=12.
    pub month: u8,
    /// UTC day of month, 1..=31.
    pub day: u8,
    /// UTC hour.
    pub hour: u8,
    /// UTC minute.
    pub min: u8,
    /// UTC second (60 during a leap second).
    pub sec: u8,
    /// Validity bits: 0 `validDate`, 1 `validTime`, 2 `fullyResolved`.
    pub valid: u8,
    /// Time accuracy, ns.
    pub time_accuracy_ns: u32,
    /// Fraction of the second, ns, signed (−1e9..1e9): the epoch is `sec + nano`.
    pub nano: i32,
    /// 0 no fix, 1 dead reckoning only, 2 2D, 3 3D, 4 GNSS + dead reckoning, 5 time
    /// only.
    pub fix_type: u8,
    /// Bit 0 `gnssFixOK` (the fix is within the configured masks).
    pub flags: u8,
    /// Bits 5..7: confirmed date and time.
    pub flags2: u8,
    /// Satellites used.
    pub num_sv: u8,
    /// Longitude, 1e-7 degrees.
    pub lon: i32,
    /// Latitude, 1e-7 degrees.
    pub lat: i32,
    /// Height above the ellipsoid, mm.
    pub height_mm: i32,
    /// Height above mean sea level, mm.
    pub height_msl_mm: i32,
    /// Horizontal accuracy, mm.
    pub h_acc_mm: u32,
    /// Vertical accuracy, mm.
    pub v_acc_mm: u32,
    /// Velocity north, mm/s.
    pub vel_n: i32,
    /// Velocity east, mm/s.
    pub vel_e: i32,
    /// Velocity down, mm/s.
    pub vel_d: i32,
    /// Ground speed (2-D), mm/s.
    pub g_speed: i32,
    /// Heading of motion (2-D), 1e-5 degrees; frozen while the receiver is slow.
    pub head_mot: i32,
    /// Speed accuracy estimate, mm/s.
    pub s_acc: u32,
    /// Heading accuracy estimate, 1e-5 degrees.
    pub head_acc: u32,
    /// Position DOP, 0.01.
    pub p_dop: u16,
}

fn u16_at(p: &[u8], i: usize) -> u16 {
    u16::from_le_bytes([p[i], p[i + 1]])
}

fn u32_at(p: &[u8], i: usize) -> u32 {
    u32::from_le_bytes([p[i], p[i + 1], p[i + 2], p[i + 3]])
}

fn i32_at(p: &[u8], i: usize) -> i32 {
    u32_at(p, i) as i32
}

/// The speed accuracy an encoder writes for "unknown" (u-blox never sends it;
/// [`NavPvt::to_epoch`] reads it back as NaN so simulated epochs round-trip).
pub const S_ACC_UNKNOWN: u32 = u32::MAX;

impl NavPvt {
    /// Reads a NAV-PVT payload of [`NAV_PVT_LEN`] or [`NAV_PVT_LEN_PROTO14`] bytes;
    /// `None` for any other length.
    pub fn parse(p: &[u8]) -> Option<NavPvt> {
        if p.len() != NAV_PVT_LEN && p.len() != NAV_PVT_LEN_PROTO14 {
            return None;
        }
        Some(NavPvt {
            itow_ms: u32_at(p, 0),
            year: u16_at(p, 4),
            month: p[6],
            day: p[7],
            hour: p[8],
            min: p[9],
            sec: p[10],
            valid: p[11],
            time_accuracy_ns: u32_at(p, 12),
            nano: i32_at(p, 16),
            fix_type: p[20],
            flags: p[21],
            flags2: p[22],
            num_sv: p[23],
            lon: i32_at(p, 24),
            lat: i32_at(p, 28),
            height_mm: i32_at(p, 32),
            height_msl_mm: i32_at(p, 36),
            h_acc_mm: u32_at(p, 40),
            v_acc_mm: u32_at(p, 44),
            vel_n: i32_at(p, 48),
            vel_e: i32_at(p, 52),
            vel_d: i32_at(p, 56),
            g_speed: i32_at(p, 60),
            head_mot: i32_at(p, 64),
            s_acc: u32_at(p, 68),
            head_acc: u32_at(p, 72),
            p_dop: u16_at(p, 76),
        })
    }

    /// The 92-byte payload (protocol 15+ layout; `flags3`, `headVeh` and the
    /// magnetic fields zero).
    pub fn to_payload(&self) -> [u8; NAV_PVT_LEN] {
        let mut p = [0u8; NAV_PVT_LEN];
        let mut put = |at: usize, bytes: &[u8]| p[at..at + bytes.len()].copy_from_slice(bytes);
        put(0, &self.itow_ms.to_le_bytes());
        put(4, &self.year.to_le_bytes());
        put(
            6,
            &[
                self.month, self.day, self.hour, self.min, self.sec, self.valid,
            ],
        );
        put(12, &self.time_accuracy_ns.to_le_bytes());
        put(16, &self.nano.to_le_bytes());
        put(20, &[self.fix_type, self.flags, self.flags2, self.num_sv]);
        put(24, &self.lon.to_le_bytes());
        put(28, &self.lat.to_le_bytes());
        put(32, &self.height_mm.to_le_bytes());
        put(36, &self.height_msl_mm.to_le_bytes());
        put(40, &self.h_acc_mm.to_le_bytes());
        put(44, &self.v_acc_mm.to_le_bytes());
        put(48, &self.vel_n.to_le_bytes());
        put(52, &self.vel_e.to_le_bytes());
        put(56, &self.vel_d.to_le_bytes());
        put(60, &self.g_speed.to_le_bytes());
        put(64, &self.head_mot.to_le_bytes());
        put(68, &self.s_acc.to_le_bytes());
        put(72, &self.head_acc.to_le_bytes());
        put(76, &self.p_dop.to_le_bytes());
        p
    }

    /// Appends this NAV-PVT as a complete, checksummed UBX frame (100 bytes).
    pub fn write_frame(&self, out: &mut Vec<u8>) {
        write_frame(CLASS_NAV, ID_NAV_PVT, &self.to_payload(), out);
    }

    /// UTC time of the epoch, ns since the Unix epoch, if the receiver marked both
    /// date and time valid and they are in range.
    pub fn time_ns(&self) -> Option<u64> {
        if self.valid & 0b11 != 0b11 {
            return None;
        }
        let days = days_from_civil(i64::from(self.year), self.month.into(), self.day.into())?;
        let ns = ns_of_day(
            self.hour.into(),
            self.min.into(),
            self.sec.into(),
            self.nano.into(),
        )?;
        unix_ns(days, ns)
    }

    /// Whether the velocity is a GNSS solution: `gnssFixOK` and a 2D, 3D or
    /// GNSS + dead-reckoning fix. Dead reckoning alone and time-only fixes are not.
    pub fn is_valid(&self) -> bool {
        self.flags & 1 == 1 && matches!(self.fix_type, 2..=4)
    }

    /// The epoch ghnet publishes: mm/s → m/s, `sAcc` → speed accuracy, `headMot` and
    /// `headAcc` → the receiver's course and its accuracy.
    pub fn to_epoch(&self) -> Epoch {
        let mm = |v: i32| (f64::from(v) / 1000.0) as f32;
        let deg = |v: f64| (v / 1e5) as f32;
        let s_acc = if self.s_acc == S_ACC_UNKNOWN {
            f32::NAN
        } else {
            (f64::from(self.s_acc) / 1000.0) as f32
        };
        Epoch {
            time_ns: self.time_ns(),
            v_north: mm(self.vel_n),
            v_east: mm(self.vel_e),
            v_down: Some(mm(self.vel_d)),
            speed_accuracy: s_acc,
            valid: self.is_valid(),
            course_deg: wrap_deg(deg(self.head_mot.into())),
            course_accuracy_deg: deg(self.head_acc.into()),
        }
    }

    /// A NAV-PVT that decodes back to `epoch` (up to the receiver's quantization:
    /// 1 mm/s, 1e-5°, 1 ns), for simulators writing receiver logs.
    ///
    /// A valid epoch becomes a 3D fix with `gnssFixOK`, an invalid one "no fix". No
    /// time gives invalid date and time bits. A NaN course becomes the direction of
    /// the velocity (what a moving u-blox reports) with a 180° accuracy (what it
    /// reports when it has no idea); a NaN speed accuracy becomes [`S_ACC_UNKNOWN`];
    /// no `v_down` becomes 0.
    pub fn from_epoch(epoch: &Epoch) -> NavPvt {
        let mm = |v: f32| (f64::from(v) * 1000.0).round() as i32;
        let e5 = |deg: f64| (deg * 1e5).round() as i32;
        let (vn, ve) = (mm(epoch.v_north), mm(epoch.v_east));
        let course = if epoch.course_deg.is_nan() {
            f64::from(ve)
                .atan2(f64::from(vn))
                .to_degrees()
                .rem_euclid(360.0)
        } else {
            f64::from(epoch.course_deg)
        };
        let head_acc = match epoch.course_accuracy_deg {
            a if a.is_nan() => 180.0,
            a => f64::from(a),
        };
        let mut pvt = NavPvt {
            fix_type: if epoch.valid { 3 } else { 0 },
            flags: u8::from(epoch.valid),
            num_sv: if epoch.valid { 12 } else { 0 },
            vel_n: vn,
            vel_e: ve,
            vel_d: mm(epoch.v_down.unwrap_or(0.0)),
            g_speed: f64::from(vn).hypot(f64::from(ve)).round() as i32,
            head_mot: e5(course),
            s_acc: match epoch.speed_accuracy {
                a if a.is_nan() => S_ACC_UNKNOWN,
                a => mm(a).max(0) as u32,
            },
            head_acc: e5(head_acc).max(0) as u32,
            p_dop: 150,
            ..NavPvt::default()
        };
        if let Some(t) = epoch.time_ns {
            pvt.set_time(t);
        }
        pvt
    }

    /// Sets date, time, `nano`, GPS time of week and the validity bits from a UTC
    /// time. The time of week ignores leap seconds (simulators do not need them).
    fn set_time(&mut self, t: u64) {
        let days = (t / DAY_NS) as i64;
        let ns_of_day = t % DAY_NS;
        let (year, month, day) = civil_from_days(days);
        let secs = ns_of_day / 1_000_000_000;
        (self.year, self.month, self.day) = (year as u16, month as u8, day as u8);
        self.hour = (secs / 3600) as u8;
        self.min = (secs / 60 % 60) as u8;
        self.sec = (secs % 60) as u8;
        self.nano = (ns_of_day % 1_000_000_000) as i32;
        self.valid = 0b111;
        self.time_accuracy_ns = 30;
        // GPS week starts Sunday 1980-01-06 = day 3657 since 1970 (a Sunday).
        let week_day = (days - 3657).rem_euclid(7) as u64;
        let ms = (week_day * DAY_NS + ns_of_day + 500_000) / 1_000_000;
        self.itow_ms = (ms % (7 * 86_400_000)) as u32;
    }
}

/// Streaming UBX decoder: push bytes in any chunking, get one [`Epoch`] per NAV-PVT.
///
/// Resynchronises after garbage, bad checksums and truncated frames by searching
/// for the next sync pair right after the rejected frame's sync bytes; counts
/// everything in [`Stats`]. Never panics on any input (fuzzed).
#[derive(Debug)]
pub struct UbxDecoder {
    /// Bytes of an unfinished frame carried over to the next push.
    pending: Vec<u8>,
    comments: Comments,
    stats: Stats,
}

/// `#` comment lines before the first frame (gpsd's captures start with a header
/// of them) are counted as [`Skip::Comment`] rather than garbage.
#[derive(Debug, Clone, Copy)]
struct Comments {
    /// No frame accepted yet: comment lines are still expected.
    allowed: bool,
    /// The previous byte ended a line (or the stream just started).
    line_start: bool,
}

/// A comment line longer than this is garbage (binary noise that began with `#`).
const MAX_COMMENT: usize = 4096;

impl Default for UbxDecoder {
    fn default() -> Self {
        Self::new()
    }
}

impl UbxDecoder {
    /// A decoder at the start of a stream.
    pub fn new() -> Self {
        UbxDecoder {
            pending: Vec::new(),
            comments: Comments {
                allowed: true,
                line_start: true,
            },
            stats: Stats::default(),
        }
    }

    /// Decodes `bytes`, appending an epoch to `out` for every NAV-PVT completed.
    pub fn push(&mut self, bytes: &[u8], out: &mut Vec<Epoch>) {
        self.stats.add_input(bytes.len());
        if self.pending.is_empty() {
            // Common case: whole frames in the chunk, nothing copied.
            let used = scan(bytes, &mut self.comments, &mut self.stats, out);
            self.pending.extend_from_slice(&bytes[used..]);
        } else {
            self.pending.extend_from_slice(bytes);
            let used = scan(&self.pending, &mut self.comments, &mut self.stats, out);
            self.pending.drain(..used);
        }
    }

    /// Ends the stream (or a connection): an unfinished frame is counted as
    /// [`Skip::Truncated`] and forgotten, so the next bytes start afresh.
    pub fn finish(&mut self) {
        finish_pending(&mut self.pending, &mut self.stats);
    }

    /// What the decoder has seen so far.
    pub fn stats(&self) -> &Stats {
        &self.stats
    }
}

/// Counts leftover bytes at the end of a stream: an unfinished frame (it starts with
/// the sync pair, or is only its first byte) is truncated, anything else garbage.
fn finish_pending(pending: &mut Vec<u8>, stats: &mut Stats) {
    if pending.is_empty() {
        return;
    }
    let reason = if pending[0] == SYNC[0] {
        Skip::Truncated
    } else {
        Skip::Garbage
    };
    stats.skip(reason, pending.len());
    pending.clear();
}

/// Decodes every complete frame in `data`; returns how many leading bytes are done
/// with (the rest is an unfinished frame to keep).
fn scan(data: &[u8], comments: &mut Comments, stats: &mut Stats, out: &mut Vec<Epoch>) -> usize {
    let mut i = 0;
    while i < data.len() {
        let rest = &data[i..];
        if rest[0] != SYNC[0] {
            match skip_noise(rest, comments, stats) {
                Some(n) => i += n,
                None => return i, // a comment line not yet complete
            }
            continue;
        }
        match frame_at(rest) {
            Frame::NeedMore => return i,
            Frame::Noise => {
                stats.skip(Skip::Garbage, 1);
                i += 1;
            }
            Frame::Reject(reason) => {
                // Only the sync pair is consumed: a real frame may start inside.
                stats.skip(reason, SYNC.len());
                i += SYNC.len();
            }
            Frame::Complete { class, id, len } => {
                comments.allowed = false;
                handle(class, id, &rest[HEADER_LEN..HEADER_LEN + len], stats, out);
                i += len + OVERHEAD;
            }
        }
    }
    i
}

/// Skips what precedes the next sync byte: a whole comment line, or a run of
/// garbage (up to a line end while comments are still expected). Returns the bytes
/// skipped, `None` when a comment line has not ended yet.
fn skip_noise(rest: &[u8], comments: &mut Comments, stats: &mut Stats) -> Option<usize> {
    if comments.allowed && comments.line_start && rest[0] == b'#' {
        match rest.iter().position(|&b| b == b'\n') {
            Some(nl) => {
                stats.skip(Skip::Comment, nl + 1);
                return Some(nl + 1);
            }
            None if rest.len() < MAX_COMMENT => return None,
            None => {}
        }
    }
    let ends_run = |b: &u8| *b == SYNC[0] || (comments.allowed && *b == b'\n');
    let run = match rest.iter().position(ends_run) {
        Some(p) if rest[p] == b'\n' => p + 1,
        Some(p) => p,
        None => rest.len(),
    };
    comments.line_start = rest[run - 1] == b'\n';
    stats.skip(Skip::Garbage, run);
    Some(run)
}

/// What starts at a sync byte.
enum Frame {
    /// Too few bytes yet to decide.
    NeedMore,
    /// Not a frame start after all (second sync byte or class wrong).
    Noise,
    /// A frame header whose length or checksum is wrong.
    Reject(Skip),
    /// A whole frame with a good checksum.
    Complete { class: u8, id: u8, len: usize },
}

fn frame_at(rest: &[u8]) -> Frame {
    if rest.len() < 2 {
        return Frame::NeedMore;
    }
    if rest[1] != SYNC[1] {
        return Frame::Noise;
    }
    if rest.len() < 3 {
        return Frame::NeedMore;
    }
    if !KNOWN_CLASSES.contains(&rest[2]) {
        return Frame::Noise;
    }
    if rest.len() < HEADER_LEN {
        return Frame::NeedMore;
    }
    let (class, id) = (rest[2], rest[3]);
    let len = usize::from(u16_at(rest, 4));
    let nav_pvt = (class, id) == (CLASS_NAV, ID_NAV_PVT);
    if len > MAX_PAYLOAD || (nav_pvt && len != NAV_PVT_LEN && len != NAV_PVT_LEN_PROTO14) {
        return Frame::Reject(Skip::BadLength);
    }
    if rest.len() < len + OVERHEAD {
        return Frame::NeedMore;
    }
    let body = &rest[2..HEADER_LEN + len];
    if checksum(body) != rest[HEADER_LEN + len..len + OVERHEAD] {
        return Frame::Reject(Skip::BadChecksum);
    }
    Frame::Complete { class, id, len }
}

fn handle(class: u8, id: u8, payload: &[u8], stats: &mut Stats, out: &mut Vec<Epoch>) {
    if (class, id) != (CLASS_NAV, ID_NAV_PVT) {
        stats.note(Skip::Other);
        return;
    }
    // `frame_at` admits only the two NAV-PVT lengths, so this always parses.
    if let Some(pvt) = NavPvt::parse(payload) {
        let epoch = pvt.to_epoch();
        stats.record(&epoch);
        out.push(epoch);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample_epoch() -> Epoch {
        Epoch {
            time_ns: Some(1_706_628_712_100_000_000),
            v_north: -1.336,
            v_east: 0.004,
            v_down: Some(-0.076),
            speed_accuracy: 0.144,
            valid: true,
            course_deg: 338.32,
            course_accuracy_deg: 4.05,
        }
    }

    #[test]
    fn checksum_matches_a_real_frame() {
        // UBX-ACK-ACK for CFG-PRT from the u-blox M8 protocol description.
        let frame = [0xB5, 0x62, 0x05, 0x01, 0x02, 0x00, 0x06, 0x00, 0x0E, 0x37];
        assert_eq!(checksum(&frame[2..8]), [0x0E, 0x37]);
        let mut out = Vec::new();
        write_frame(0x05, 0x01, &[0x06, 0x00], &mut out);
        assert_eq!(out, frame);
    }

    #[test]
    fn epoch_round_trips_through_a_frame() {
        let e = sample_epoch();
        let mut bytes = Vec::new();
        NavPvt::from_epoch(&e).write_frame(&mut bytes);
        assert_eq!(bytes.len(), NAV_PVT_LEN + OVERHEAD);
        let mut dec = UbxDecoder::new();
        let mut out = Vec::new();
        dec.push(&bytes, &mut out);
        assert_eq!(out, vec![e]);
        assert_eq!(dec.stats().epochs(), 1);
    }

    #[test]
    fn unknowns_encode_to_receiver_conventions() {
        let e = Epoch {
            time_ns: None,
            course_deg: f32::NAN,
            course_accuracy_deg: f32::NAN,
            speed_accuracy: f32::NAN,
            v_down: None,
            valid: false,
            v_north: 0.0,
            v_east: 2.0,
        };
        let pvt = NavPvt::from_epoch(&e);
        assert_eq!((pvt.valid, pvt.fix_type, pvt.flags), (0, 0, 0));
        assert_eq!((pvt.head_mot, pvt.head_acc), (9_000_000, 18_000_000));
        let back = pvt.to_epoch();
        assert!(back.time_ns.is_none() && !back.valid && back.speed_accuracy.is_nan());
        assert_eq!((back.course_deg, back.v_down), (90.0, Some(0.0)));
    }

    #[test]
    fn time_of_week_and_negative_nano() {
        let mut pvt = NavPvt::default();
        // 2017-07-19 08:50:00.799899687 UTC: gpsd's ublox-neo-m8n.log, iTOW 291018800
        // (GPS is 18 s ahead of UTC then; set_time ignores leap seconds).
        pvt.set_time(1_500_454_200_799_899_687);
        assert_eq!(
            (pvt.year, pvt.month, pvt.day, pvt.hour, pvt.min, pvt.sec),
            (2017, 7, 19, 8, 50, 0)
        );
        assert_eq!(pvt.itow_ms, 291_018_800 - 18_000);
        pvt.sec = 1;
        pvt.nano = -100_231;
        assert_eq!(pvt.time_ns(), Some(1_500_454_200_999_899_769));
        pvt.valid = 0b01; // date valid, time not
        assert_eq!(pvt.time_ns(), None);
    }

    #[test]
    fn validity_follows_fix_ok_and_fix_type() {
        let mut pvt = NavPvt {
            flags: 1,
            ..NavPvt::default()
        };
        let valid: Vec<bool> = (0..=6)
            .map(|t| {
                pvt.fix_type = t;
                pvt.is_valid()
            })
            .collect();
        assert_eq!(valid, [false, false, true, true, true, false, false]);
        pvt.flags = 0;
        pvt.fix_type = 3;
        assert!(!pvt.is_valid());
    }

    #[test]
    fn resyncs_after_garbage_bad_checksum_and_truncation() {
        let mut frame = Vec::new();
        NavPvt::from_epoch(&sample_epoch()).write_frame(&mut frame);
        let mut bad = frame.clone();
        bad[50] ^= 0xFF;
        let mut stream = b"\xB5\x00noise".to_vec();
        stream.extend_from_slice(&bad);
        stream.extend_from_slice(&frame[..40]); // cut off ...
        stream.extend_from_slice(&frame); // ... then a good one
        stream.extend_from_slice(&frame[..10]); // truncated by the end of the stream
        let mut dec = UbxDecoder::new();
        let mut out = Vec::new();
        for chunk in stream.chunks(7) {
            dec.push(chunk, &mut out);
        }
        dec.finish();
        let s = dec.stats();
        assert_eq!(out.len(), 1);
        assert_eq!(s.skipped(Skip::BadChecksum), 2, "{s}"); // the flipped and the cut one
        assert_eq!(s.skipped(Skip::Truncated), 1, "{s}");
        assert_eq!(s.bytes_used(), frame.len() as u64, "{s}");
    }

    #[test]
    fn other_classes_are_counted_and_bad_lengths_rejected() {
        let mut stream = Vec::new();
        write_frame(0x01, 0x35, &[0; 8], &mut stream); // NAV-SAT
        write_frame(CLASS_NAV, ID_NAV_PVT, &[0; 40], &mut stream); // wrong NAV-PVT size
        let mut dec = UbxDecoder::new();
        let mut out = Vec::new();
        dec.push(&stream, &mut out);
        dec.finish();
        assert!(out.is_empty());
        assert_eq!(dec.stats().skipped(Skip::Other), 1);
        assert_eq!(dec.stats().skipped(Skip::BadLength), 1);
        assert_eq!(dec.stats().bytes_used(), 16);
    }
}
