//! NMEA 0183: a streaming sentence decoder that turns RMC (or, for receivers that
//! send none, VTG) into [`Epoch`]s.
//!
//! Why a hand parser and not the `nmea` crate (0.8.0, Apache-2.0, released
//! 2026-08-08 after 22 months without one): its VTG parser drops the km/h speed and
//! the mode indicator, and it rejects a whole sentence over a field ghnet does not
//! read. Over the 9,193 RMC/GGA/VTG sentences of the 118 gpsd test captures (gpsd
//! 46977faa) that have them, it rejected 67 that had not failed their checksum:
//! besides truncated lines, all 25 RMC of a Motorola T805 (magnetic variation
//! without E/W; moving epochs among them), GGA without a checksum (legal NMEA, HP
//! 58534A) and GGA with an empty fix quality. ghnet needs a few fields of six
//! sentence types; reading them is shorter than working around those rejections.
//!
//! # Epochs
//! - **RMC** gives one epoch: speed (knots) and course → `v_north`/`v_east`, date and
//!   time → `time_ns`, status `A`/`D` and mode indicator (`A D F R P`, NMEA 2.3+) →
//!   `valid`. A GGA of the same time before it with fix quality 0, 3, 6, 7 or 8 also
//!   makes it invalid (receivers older than NMEA 2.3 have no mode indicator).
//! - **VTG** gives the epoch for receivers configured without RMC (u-blox F9 with
//!   VTG + GGA, Hemisphere, ST Teseo): it takes the time of the next sentence that
//!   carries one (GGA, GLL, GNS, ZDA; u-blox sends VTG first in a cycle) and the date
//!   of the last RMC or ZDA. Beside an RMC it is counted as [`Skip::Redundant`].
//! - An empty course is unknown, never 0°: see [`split_course`].
//! - No vertical speed; speed accuracy NaN unless configured
//!   ([`NmeaDecoder::with_speed_accuracy`]): NMEA has none.

use crate::epoch::{split_course, wrap_deg};
use crate::lines::{trim_eol, Lines};
use crate::stats::{Skip, Stats};
use crate::time::{days_from_civil, digits, parse_ddmmyy, parse_hhmmss, unix_ns, DAY_NS};
use crate::Epoch;

/// Longest line accepted. The standard allows 82 characters; receivers exceed it
/// (u-blox GSV with many signals, proprietary sentences), so the bound is generous.
pub const MAX_LINE: usize = 1024;
/// Knots → m/s.
const KNOT: f64 = 1852.0 / 3600.0;
/// km/h → m/s.
const KMH: f64 = 1.0 / 3.6;
/// Most fields any sentence ghnet reads has (RMC of NMEA 4.1 has 13).
const MAX_FIELDS: usize = 24;

/// Streaming NMEA 0183 decoder; push bytes in any chunking.
#[derive(Debug)]
pub struct NmeaDecoder {
    lines: Lines,
    cycle: Cycle,
    speed_accuracy: f32,
    stats: Stats,
}

impl Default for NmeaDecoder {
    fn default() -> Self {
        Self::new()
    }
}

impl NmeaDecoder {
    /// A decoder whose epochs have an unknown (NaN) speed accuracy.
    pub fn new() -> Self {
        NmeaDecoder {
            lines: Lines::new(MAX_LINE),
            cycle: Cycle::default(),
            speed_accuracy: f32::NAN,
            stats: Stats::default(),
        }
    }

    /// Uses `sigma` (m/s, 1σ) as the speed accuracy of every epoch, for a receiver
    /// whose noise the user knows; NMEA itself has no such field.
    pub fn with_speed_accuracy(mut self, sigma: Option<f32>) -> Self {
        self.speed_accuracy = sigma.unwrap_or(f32::NAN);
        self
    }

    /// Decodes `bytes`, appending an epoch to `out` for every one completed.
    pub fn push(&mut self, bytes: &[u8], out: &mut Vec<Epoch>) {
        self.stats.add_input(bytes.len());
        let (cycle, sigma) = (&mut self.cycle, self.speed_accuracy);
        self.lines.push(bytes, &mut self.stats, |line, stats| {
            let start = out.len();
            cycle.line(line, stats, out);
            for e in &mut out[start..] {
                e.speed_accuracy = sigma;
                stats.record(e);
            }
        });
    }

    /// Ends the stream (or a connection): an unterminated line is
    /// [`Skip::Truncated`], and so is a VTG still waiting for its time.
    pub fn finish(&mut self) {
        self.lines.finish(&mut self.stats);
        if let Some(vtg) = self.cycle.pending_vtg.take() {
            let redundant = vtg.rmc_before || self.cycle.rmc_since_vtg;
            self.stats.note(if redundant {
                Skip::Redundant
            } else {
                Skip::Truncated
            });
        }
    }

    /// What the decoder has seen so far.
    pub fn stats(&self) -> &Stats {
        &self.stats
    }
}

/// What ties the sentences of one receiver cycle together.
#[derive(Debug, Default)]
struct Cycle {
    /// Days since 1970 of the last date seen (RMC, ZDA), rolled over at midnight.
    date: Option<i64>,
    /// Time of day (ns) of the last sentence that had one.
    last_tod: Option<u64>,
    /// The last GGA: its time of day and whether its fix quality allows a velocity.
    gga: Option<(Option<u64>, Option<bool>)>,
    /// A VTG waiting for the next time-bearing sentence.
    pending_vtg: Option<Vtg>,
    /// An RMC arrived since the last VTG: then VTG only repeats it.
    rmc_since_vtg: bool,
}

#[derive(Debug)]
struct Vtg {
    speed: Option<f32>,
    course: Option<f32>,
    mode_ok: Option<bool>,
    rmc_before: bool,
}

/// A sentence's time: time of day, date if it has one, and its own fix verdict.
struct Stamp {
    tod: Option<u64>,
    date: Option<i64>,
    ok: Option<bool>,
    is_rmc: bool,
}

impl Stamp {
    fn new(tod: Option<u64>, date: Option<i64>, ok: Option<bool>) -> Self {
        Stamp {
            tod,
            date,
            ok,
            is_rmc: false,
        }
    }
}

impl Cycle {
    fn line(&mut self, raw: &[u8], stats: &mut Stats, out: &mut Vec<Epoch>) {
        let line = trim_eol(raw);
        if line.is_empty() {
            return;
        }
        if line[0] == b'#' {
            return stats.skip(Skip::Comment, raw.len());
        }
        // Anything before the last `$` is noise or a sentence cut short (`$` cannot
        // appear inside a sentence).
        let Some(start) = line.iter().rposition(|&b| b == b'$' || b == b'!') else {
            return stats.skip(Skip::Garbage, raw.len());
        };
        if start > 0 {
            stats.skip(Skip::Garbage, start);
        }
        let used = raw.len() - start;
        match checked_body(&line[start..]) {
            Err(reason) => stats.skip(reason, used),
            Ok(_) if line[start] == b'!' => stats.note(Skip::Other), // AIS
            Ok(body) => {
                if let Err(reason) = self.sentence(&Fields::split(body), stats, out) {
                    stats.note(reason);
                }
            }
        }
    }

    /// Dispatches one checked sentence; `Err` says why it gave nothing.
    fn sentence(
        &mut self,
        f: &Fields<'_>,
        stats: &mut Stats,
        out: &mut Vec<Epoch>,
    ) -> Result<(), Skip> {
        let address = f.get(0);
        if address.len() != 5 || address[0] == b'P' {
            return Err(Skip::Other); // proprietary ($PUBX, $PGRME, ...) or odd
        }
        let stamp = match &address[2..] {
            b"RMC" => return self.rmc(f, stats, out),
            b"VTG" => return self.vtg(f, stats),
            b"GGA" => {
                let stamp = Stamp::new(time_field(f.get(1))?, None, gga_quality_ok(f.get(6)));
                self.gga = Some((stamp.tod, stamp.ok));
                stamp
            }
            b"GLL" => {
                let ok = status_ok(f.get(6)).map(|s| s && mode_ok(f.get(7)).unwrap_or(true));
                Stamp::new(time_field(f.get(5))?, None, ok)
            }
            b"GNS" => Stamp::new(time_field(f.get(1))?, None, gns_mode_ok(f.get(6))),
            b"ZDA" => {
                let date = match (digits(f.get(2)), digits(f.get(3)), digits(f.get(4))) {
                    (Some(d), Some(m), Some(y)) => days_from_civil(y.into(), m, d),
                    _ => None,
                };
                Stamp::new(time_field(f.get(1))?, date, None)
            }
            _ => return Err(Skip::Other),
        };
        self.stamp(&stamp, stats, out);
        Ok(())
    }

    fn rmc(&mut self, f: &Fields<'_>, stats: &mut Stats, out: &mut Vec<Epoch>) -> Result<(), Skip> {
        if f.len() < 10 {
            return Err(Skip::Malformed);
        }
        let tod = time_field(f.get(1))?;
        let date = match f.get(9) {
            [] => None,
            d => Some(parse_ddmmyy(d).ok_or(Skip::Malformed)?),
        };
        let speed = number(f.get(7))?.map(|kn| (kn * KNOT) as f32);
        let course = number(f.get(8))?.map(|c| c as f32);
        let gga_ok = match self.gga {
            Some((t, Some(false))) => t != tod || tod.is_none(),
            _ => true,
        };
        let ok = status_ok(f.get(2)) == Some(true) && mode_ok(f.get(12)).unwrap_or(true) && gga_ok;
        self.rmc_since_vtg = true;
        let stamp = Stamp {
            is_rmc: true,
            ..Stamp::new(tod, date, Some(ok))
        };
        self.stamp(&stamp, stats, out);
        let time_ns = self.time_ns(tod);
        out.push(velocity_epoch(time_ns, speed, course, ok));
        Ok(())
    }

    fn vtg(&mut self, f: &Fields<'_>, stats: &mut Stats) -> Result<(), Skip> {
        // NMEA 2.0+: course,T,course,M,knots,N,km/h,K[,mode]; NMEA 1.x: four numbers.
        let (course, knots, kmh, mode) = match f.len() {
            n if n >= 9 => (f.get(1), f.get(5), f.get(7), f.get(9)),
            5 => (f.get(1), f.get(3), f.get(4), &[][..]),
            _ => return Err(Skip::Malformed),
        };
        let speed = match number(knots)? {
            Some(kn) => Some(kn * KNOT),
            None => number(kmh)?.map(|v| v * KMH),
        };
        let vtg = Vtg {
            speed: speed.map(|s| s as f32),
            course: number(course)?.map(|c| c as f32),
            mode_ok: mode_ok(mode),
            rmc_before: std::mem::take(&mut self.rmc_since_vtg),
        };
        // Two VTG without a time between them: the first never gets one.
        if self.pending_vtg.replace(vtg).is_some() {
            stats.note(Skip::Truncated);
        }
        Ok(())
    }

    /// A sentence with a time arrived: roll the date, then give a waiting VTG its
    /// time (or drop it as redundant beside an RMC).
    fn stamp(&mut self, s: &Stamp, stats: &mut Stats, out: &mut Vec<Epoch>) {
        if let Some(t) = s.tod {
            match (s.date, self.date, self.last_tod) {
                (Some(d), _, _) => self.date = Some(d),
                // Midnight passed with no new date yet (time of day went far back).
                (None, Some(d), Some(last)) if last > t + DAY_NS / 2 => self.date = Some(d + 1),
                _ => {}
            }
            self.last_tod = Some(t);
        }
        // Only a time (or an RMC, which makes VTG redundant) settles a waiting VTG:
        // receivers without a fix send GGA with an empty time before their RMC.
        if s.tod.is_none() && !s.is_rmc {
            return;
        }
        let Some(vtg) = self.pending_vtg.take() else {
            return;
        };
        if vtg.rmc_before || self.rmc_since_vtg || s.is_rmc {
            return stats.note(Skip::Redundant);
        }
        let ok = vtg.mode_ok.or(s.ok).unwrap_or(true);
        out.push(velocity_epoch(
            self.time_ns(s.tod),
            vtg.speed,
            vtg.course,
            ok,
        ));
    }

    fn time_ns(&self, tod: Option<u64>) -> Option<u64> {
        unix_ns(self.date?, i64::try_from(tod?).ok()?)
    }
}

/// The epoch of a speed and course report (RMC or VTG).
fn velocity_epoch(
    time_ns: Option<u64>,
    speed: Option<f32>,
    course: Option<f32>,
    ok: bool,
) -> Epoch {
    let Some(speed) = speed.filter(|s| s.is_finite() && *s >= 0.0) else {
        return Epoch::invalid(time_ns);
    };
    let course = course.map(wrap_deg);
    let (v_north, v_east, direction_known) = split_course(speed, course);
    Epoch {
        time_ns,
        v_north,
        v_east,
        v_down: None,
        speed_accuracy: f32::NAN,
        valid: ok && direction_known,
        course_deg: course.unwrap_or(f32::NAN),
        course_accuracy_deg: f32::NAN,
    }
}

/// Checks framing and checksum of `$...*hh`; returns the body between `$` and `*`.
/// A sentence without `*hh` (legal for old talkers) must be printable ASCII.
fn checked_body(s: &[u8]) -> Result<&[u8], Skip> {
    let Some(star) = s.iter().rposition(|&b| b == b'*') else {
        let printable = s.iter().all(|&b| (0x20..0x7f).contains(&b));
        return if printable {
            Ok(&s[1..])
        } else {
            Err(Skip::Malformed)
        };
    };
    let body = &s[1..star];
    let want = match &s[star + 1..] {
        [h, l] => hex(*h).zip(hex(*l)).map(|(h, l)| h << 4 | l),
        _ => None,
    };
    let Some(want) = want else {
        return Err(Skip::Malformed);
    };
    if body.iter().fold(0u8, |x, &b| x ^ b) != want {
        return Err(Skip::BadChecksum);
    }
    Ok(body)
}

fn hex(b: u8) -> Option<u8> {
    (b as char).to_digit(16).map(|d| d as u8)
}

/// Comma-separated fields of a sentence body, field 0 the address (`GPRMC`), kept
/// on the stack.
struct Fields<'a> {
    items: [&'a [u8]; MAX_FIELDS],
    len: usize,
}

impl<'a> Fields<'a> {
    fn split(body: &'a [u8]) -> Self {
        let mut f = Fields {
            items: [&[]; MAX_FIELDS],
            len: 0,
        };
        for item in body.split(|&b| b == b',').take(MAX_FIELDS) {
            f.items[f.len] = item;
            f.len += 1;
        }
        f
    }

    fn len(&self) -> usize {
        self.len
    }

    /// Field `i`, empty when absent.
    fn get(&self, i: usize) -> &'a [u8] {
        if i < self.len {
            self.items[i]
        } else {
            &[]
        }
    }
}

/// An empty field is `None`; anything but a plain decimal number is malformed (Rust's
/// float parser would also take `inf`, `NaN` and exponents).
fn number(field: &[u8]) -> Result<Option<f64>, Skip> {
    if field.is_empty() {
        return Ok(None);
    }
    let plain = field
        .iter()
        .enumerate()
        .all(|(i, &b)| b.is_ascii_digit() || b == b'.' || (i == 0 && (b == b'-' || b == b'+')));
    let text = std::str::from_utf8(field).map_err(|_| Skip::Malformed)?;
    match text.parse::<f64>() {
        Ok(v) if plain => Ok(Some(v)),
        _ => Err(Skip::Malformed),
    }
}

fn time_field(field: &[u8]) -> Result<Option<u64>, Skip> {
    match field {
        [] => Ok(None),
        t => parse_hhmmss(t).map(Some).ok_or(Skip::Malformed),
    }
}

/// RMC/GLL status: `A` (valid) or `D` (differential) → true, `V` (void) → false.
fn status_ok(field: &[u8]) -> Option<bool> {
    match field {
        [] => None,
        [b'A'] | [b'D'] => Some(true),
        _ => Some(false),
    }
}

/// NMEA 2.3+ mode indicator: autonomous, differential, float or fixed RTK, precise →
/// true; not valid, estimated (dead reckoning), manual, simulator → false.
fn mode_ok(field: &[u8]) -> Option<bool> {
    field.first().map(|m| b"ADFRP".contains(m))
}

/// GNS carries one mode character per constellation: valid if any is a fix.
fn gns_mode_ok(field: &[u8]) -> Option<bool> {
    (!field.is_empty()).then(|| field.iter().any(|m| b"ADFRP".contains(m)))
}

/// GGA fix quality: GPS, DGPS, RTK fixed and float carry a velocity; invalid (0),
/// PPS (3), estimated (6), manual (7) and simulation (8) do not.
fn gga_quality_ok(field: &[u8]) -> Option<bool> {
    match field {
        [q] if q.is_ascii_digit() => Some(matches!(q, b'1' | b'2' | b'4' | b'5')),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::skips;
    use crate::Format::Nmea;

    #[test]
    fn rmc_moving_standstill_and_void() {
        let (e, s) = Nmea.decode_text(concat!(
            "$GPRMC,143307.00,A,5546.82649,N,02334.71625,E,30.860,221.48,091209,,,A*5D\r\n",
            "$GPRMC,152505.00,A,5547.82113,N,02334.14130,E,0.253,,091209,,,A*7A\r\n",
            "$GPRMC,,V,,,,,,,,,,N*53\r\n",
        ));
        assert_eq!(e.len(), 3, "{s}");
        let moving = e[0];
        assert!(moving.valid && moving.v_down.is_none() && moving.speed_accuracy.is_nan());
        assert!((moving.speed() - 30.86 * 0.514_444).abs() < 1e-3);
        assert!((moving.course_deg - 221.48).abs() < 1e-4 && moving.v_north < 0.0);
        // 2009-12-09 14:33:07 UTC
        assert_eq!(moving.time_ns, Some(1_260_369_187_000_000_000));
        // Empty course at 0.13 m/s: a standstill, not 0°.
        assert!(e[1].valid && e[1].v_north == 0.0 && e[1].v_east == 0.0);
        assert!(e[1].course_deg.is_nan());
        assert!(!e[2].valid && e[2].time_ns.is_none());
    }

    #[test]
    fn mode_indicator_and_gga_quality_invalidate() {
        let (e, _) = Nmea.decode_text(concat!(
            "$GPRMC,000346.03,A,4808.1,N,01131.0,E,5.0,90.0,010120,,,E*61\r\n",
            "$GPGGA,000347,4808.1,N,01131.0,E,0,00,,,M,,M,,*5A\r\n",
            "$GPRMC,000347,A,4808.1,N,01131.0,E,5.0,90.0,010120,,*24\r\n",
            "$GPRMC,000348,A,4808.1,N,01131.0,E,5.0,90.0,010120,,*2B\r\n",
        ));
        let valid: Vec<bool> = e.iter().map(|e| e.valid).collect();
        assert_eq!(valid, [false, false, true]);
    }

    #[test]
    fn vtg_without_rmc_takes_the_next_time_and_zda_date() {
        let (e, s) = Nmea.decode_text(concat!(
            "$GNZDA,231409.00,11,04,2025,00,00*74\r\n",
            "$GNVTG,90.0,T,,M,1.944,N,3.600,K,A*27\r\n",
            "$GNGGA,231410.00,4503.94,N,07500.00,W,1,12,0.9,100.0,M,0.0,M,,*53\r\n",
        ));
        assert_eq!(e.len(), 1, "{s}");
        assert!(e[0].valid && (e[0].v_east - 1.0).abs() < 1e-3);
        // 2025-04-11 23:14:10 UTC
        assert_eq!(e[0].time_ns, Some(1_744_413_250_000_000_000));
    }

    #[test]
    fn vtg_beside_rmc_is_redundant_in_either_order() {
        let (e, _) = Nmea.decode_text(concat!(
            "$GPVTG,300.5,T,296.9,M,1.3,N,2.3,K,A*22\r\n",
            "$GPRMC,191503.01,A,3645.876324,N,03124.670280,E,1.3,300.5,110922,3.6,E,A,V*4E\r\n",
            "$GPVTG,300.5,T,296.9,M,1.0,N,1.9,K,A*28\r\n",
            "$GPGGA,191504.01,3645.8,N,03124.6,E,1,08,1.0,10.0,M,0.0,M,,*63\r\n",
            "$GPRMC,191504.01,A,3645.876678,N,03124.668626,E,1.0,300.5,110922,3.6,E,A,V*47\r\n",
        ));
        assert_eq!(e.len(), 2);
    }

    #[test]
    fn rejects_bad_checksums_and_counts_other_sentences() {
        let (e, s) = Nmea.decode_text(concat!(
            "# a comment\r\n",
            "$GPRMC,143307.00,A,5546.82649,N,02334.71625,E,30.860,221.48,091209,,,A*5E\r\n",
            "$GPGSV,1,1,00*79\r\n",
            "$PGRME,15.0,M,22.5,M,27.0,M*1A\r\n",
            "xx$GPGSV,1,1,00*79\r\n",
            "$GPRMC,1433",
        ));
        assert!(e.is_empty());
        assert_eq!(
            skips(&s),
            "garbage_bytes=2 comment=1 bad_checksum=1 truncated=1 other=3"
        );
    }

    #[test]
    fn unchecked_sentences_are_accepted() {
        let (e, _) =
            Nmea.decode_text("$GPRMC,222449,A,3349.0337,S,01843.9282,E,0.0,0.0,010120,,\r\n");
        assert_eq!(e.len(), 1);
        assert!(e[0].valid);
    }

    #[test]
    fn numbers_are_plain_decimals() {
        assert_eq!(number(b""), Ok(None));
        assert_eq!(number(b"-1.5"), Ok(Some(-1.5)));
        assert_eq!(number(b"inf"), Err(Skip::Malformed));
        assert_eq!(number(b"1e5"), Err(Skip::Malformed));
        assert_eq!(number(b"1.2.3"), Err(Skip::Malformed));
    }
}
