//! gpsd's JSON protocol: a streaming decoder that turns TPV reports into
//! [`Epoch`]s, and the `?WATCH` command that starts them.
//!
//! JSON is read with `serde_json` into a struct of the eight TPV fields ghnet uses.
//! The `gpsd_proto` crate (1.0.0, 2023) was not adopted: its TPV has no
//! `velN`/`velE`/`velD` (gpsd 3.19+), which the mapping prefers over speed and
//! track.
//!
//! # Epochs
//! - `velN`/`velE` (and `velD`, else `-climb`) when present, else `speed` and
//!   `track` (an absent track follows [`split_course`]); `mode` < 2 → invalid;
//!   `time` (ISO 8601, or seconds in gpsd < 3.10) → `time_ns`.
//! - gpsd reports a cycle again as more sentences arrive, and interleaves reports of
//!   different messages: a TPV whose time equals the last epoch's is
//!   [`Skip::Duplicate`], an older one [`Skip::OutOfOrder`], a fix without any
//!   velocity [`Skip::NoVelocity`] (a later TPV of the cycle usually has it).
//! - `eps` is gpsd's "estimated speed error, certainty unknown": not a 1σ, so the
//!   speed accuracy stays NaN unless configured
//!   ([`GpsdDecoder::with_speed_accuracy`]).

use std::borrow::Cow;

use serde::Deserialize;

use crate::epoch::{split_course, wrap_deg};
use crate::lines::{trim_eol, Lines};
use crate::stats::{Skip, Stats};
use crate::time::parse_iso8601;
use crate::Epoch;

/// Sent after connecting: asks gpsd to stream JSON reports (TPV, SKY, ...).
pub const WATCH_COMMAND: &[u8] = b"?WATCH={\"enable\":true,\"json\":true}\n";
/// Longest line accepted; gpsd's SKY reports with every signal of a multi-band
/// receiver reach a few kilobytes.
pub const MAX_LINE: usize = 65_536;

/// The fields of a gpsd report ghnet reads; every other field is ignored.
#[derive(Deserialize)]
struct Report<'a> {
    #[serde(borrow)]
    class: Cow<'a, str>,
    #[serde(default)]
    mode: i64,
    #[serde(borrow)]
    time: Option<TimeField<'a>>,
    #[serde(rename = "velN")]
    vel_n: Option<f64>,
    #[serde(rename = "velE")]
    vel_e: Option<f64>,
    #[serde(rename = "velD")]
    vel_d: Option<f64>,
    climb: Option<f64>,
    speed: Option<f64>,
    track: Option<f64>,
}

/// gpsd 3.10+ sends ISO 8601 text, older versions seconds since the Unix epoch.
#[derive(Deserialize)]
#[serde(untagged)]
enum TimeField<'a> {
    Text(#[serde(borrow)] Cow<'a, str>),
    Seconds(f64),
}

impl TimeField<'_> {
    fn to_ns(&self) -> Option<u64> {
        match self {
            TimeField::Text(s) => parse_iso8601(s),
            // Whole seconds and fraction apart: f64 cannot hold ns since 1970 exactly.
            TimeField::Seconds(s) if s.is_finite() && (0.0..1.8e10).contains(s) => {
                Some(s.trunc() as u64 * 1_000_000_000 + (s.fract() * 1e9).round() as u64)
            }
            TimeField::Seconds(_) => None,
        }
    }
}

/// Streaming decoder of gpsd's JSON lines; push bytes in any chunking.
#[derive(Debug)]
pub struct GpsdDecoder {
    lines: Lines,
    state: State,
    stats: Stats,
}

#[derive(Debug)]
struct State {
    last_time: Option<u64>,
    speed_accuracy: f32,
}

impl Default for GpsdDecoder {
    fn default() -> Self {
        Self::new()
    }
}

impl GpsdDecoder {
    /// A decoder whose epochs have an unknown (NaN) speed accuracy.
    pub fn new() -> Self {
        GpsdDecoder {
            lines: Lines::new(MAX_LINE),
            state: State {
                last_time: None,
                speed_accuracy: f32::NAN,
            },
            stats: Stats::default(),
        }
    }

    /// Uses `sigma` (m/s, 1σ) as the speed accuracy of every epoch.
    pub fn with_speed_accuracy(mut self, sigma: Option<f32>) -> Self {
        self.state.speed_accuracy = sigma.unwrap_or(f32::NAN);
        self
    }

    /// Decodes `bytes`, appending an epoch to `out` for every new TPV fix.
    pub fn push(&mut self, bytes: &[u8], out: &mut Vec<Epoch>) {
        self.stats.add_input(bytes.len());
        let state = &mut self.state;
        self.lines.push(bytes, &mut self.stats, |raw, stats| {
            state.line(raw, stats, out);
        });
    }

    /// Ends the stream (or a connection): an unterminated line is
    /// [`Skip::Truncated`]. The time of the last epoch is kept, so a gpsd that
    /// restarts does not repeat epochs already given.
    pub fn finish(&mut self) {
        self.lines.finish(&mut self.stats);
    }

    /// What the decoder has seen so far.
    pub fn stats(&self) -> &Stats {
        &self.stats
    }
}

impl State {
    fn line(&mut self, raw: &[u8], stats: &mut Stats, out: &mut Vec<Epoch>) {
        let line = trim_eol(raw);
        match line.first() {
            None => {}
            Some(b'#') => stats.skip(Skip::Comment, raw.len()),
            // NMEA passthrough (`"nmea":true`) is well-formed, just not ours.
            Some(b'$' | b'!') => stats.note(Skip::Other),
            Some(b'{') => match serde_json::from_slice::<Report<'_>>(line) {
                Err(_) => stats.note(Skip::Malformed),
                Ok(r) if r.class != "TPV" => stats.note(Skip::Other),
                Ok(r) => match self.tpv(&r) {
                    Ok(epoch) => {
                        stats.record(&epoch);
                        out.push(epoch);
                    }
                    Err(reason) => stats.note(reason),
                },
            },
            Some(_) => stats.skip(Skip::Garbage, raw.len()),
        }
    }

    fn tpv(&mut self, r: &Report<'_>) -> Result<Epoch, Skip> {
        let time_ns = match &r.time {
            None => None,
            Some(t) => Some(t.to_ns().ok_or(Skip::Malformed)?),
        };
        if let (Some(t), Some(last)) = (time_ns, self.last_time) {
            if t == last {
                return Err(Skip::Duplicate);
            }
            if t < last {
                return Err(Skip::OutOfOrder);
            }
        }
        let mut epoch = if r.mode < 2 {
            Epoch::invalid(time_ns)
        } else {
            velocity(r, time_ns).ok_or(Skip::NoVelocity)?
        };
        epoch.speed_accuracy = self.speed_accuracy;
        if time_ns.is_some() {
            self.last_time = time_ns;
        }
        Ok(epoch)
    }
}

/// The velocity of a TPV with a fix: `velN`/`velE` first, else speed and track.
fn velocity(r: &Report<'_>, time_ns: Option<u64>) -> Option<Epoch> {
    let finite = |v: Option<f64>| v.filter(|x| x.is_finite()).map(|x| x as f32);
    let course = finite(r.track).map(wrap_deg);
    let v_down = finite(r.vel_d).or(finite(r.climb).map(|c| -c));
    let (v_north, v_east, valid) = match (finite(r.vel_n), finite(r.vel_e), finite(r.speed)) {
        (Some(n), Some(e), _) => (n, e, true),
        (_, _, Some(s)) if s >= 0.0 => split_course(s, course),
        _ => return None,
    };
    Some(Epoch {
        time_ns,
        v_north,
        v_east,
        v_down,
        speed_accuracy: f32::NAN,
        valid,
        course_deg: course.unwrap_or(f32::NAN),
        course_accuracy_deg: f32::NAN,
    })
}

#[cfg(test)]
mod tests {
    use crate::testing::skips;
    use crate::Format::Gpsd;

    #[test]
    fn tpv_velocities_modes_and_duplicates() {
        let (e, s) = Gpsd.decode_text(concat!(
            "{\"class\":\"VERSION\",\"release\":\"3.25\",\"proto_major\":3,\"proto_minor\":15}\n",
            "{\"class\":\"TPV\",\"mode\":1}\n",
            "{\"class\":\"TPV\",\"mode\":3,\"time\":\"2022-10-18T10:00:01.000Z\",\"speed\":2.0,\"track\":90.0,\"climb\":0.5}\n",
            "{\"class\":\"TPV\",\"mode\":3,\"time\":\"2022-10-18T10:00:01.000Z\",\"speed\":2.0,\"track\":90.0}\n",
            "{\"class\":\"TPV\",\"mode\":3,\"time\":\"2022-10-18T10:00:00.500Z\",\"speed\":2.0,\"track\":90.0}\n",
            "{\"class\":\"TPV\",\"mode\":3,\"time\":\"2022-10-18T10:00:02.000Z\",\"velN\":1.0,\"velE\":-1.0,\"velD\":0.1,\"track\":315.0,\"speed\":1.41}\n",
            "{\"class\":\"TPV\",\"mode\":3,\"time\":\"2022-10-18T10:00:03.000Z\"}\n",
            "{\"class\":\"SKY\",\"satellites\":[]}\n",
            "{\"class\":\"TPV\",\"mode\":3,\"time\":\"2022-10-18T10:00:04Z\",\"speed\":0.2}\n",
            "{not json}\n",
        ));
        assert_eq!(e.len(), 4, "{s}");
        assert!(!e[0].valid && e[0].time_ns.is_none());
        assert!(e[1].valid && (e[1].v_east - 2.0).abs() < 1e-6 && e[1].v_down == Some(-0.5));
        assert_eq!(
            (e[2].v_north, e[2].v_east, e[2].v_down),
            (1.0, -1.0, Some(0.1))
        );
        assert!(e[3].valid && e[3].v_north == 0.0 && e[3].course_deg.is_nan());
        assert_eq!(
            skips(&s),
            "malformed=1 other=2 duplicate=1 out_of_order=1 no_velocity=1"
        );
    }

    #[test]
    fn old_numeric_time() {
        let (e, _) = Gpsd.decode_text(
            "{\"class\":\"TPV\",\"mode\":2,\"time\":1500000000.25,\"speed\":0,\"track\":0}\r\n",
        );
        assert_eq!(e[0].time_ns, Some(1_500_000_000_250_000_000));
    }
}
