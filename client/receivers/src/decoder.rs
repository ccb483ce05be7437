//! [`Decoder`]: one entry point for every format, detecting it from the stream when
//! not told.

use crate::gpsd::GpsdDecoder;
use crate::nmea::NmeaDecoder;
use crate::stats::Stats;
use crate::ubx::UbxDecoder;
use crate::{Epoch, Format};

/// NMEA epochs to wait for before settling on NMEA when valid UBX frames are also in
/// the stream: a u-blox may send NMEA and UBX on one port, and its NAV-PVT (with a
/// speed accuracy) is the better source if it comes.
const NMEA_PATIENCE: u64 = 5;

/// A streaming decoder for one byte stream (a file, a serial port, a connection).
///
/// With a [`Format`] it is that format's decoder. Without one it runs all three on
/// the first bytes and settles on the first that produces an epoch (UBX before gpsd
/// before NMEA when several do in the same chunk); epochs found while detecting are
/// held and given out on the decision, so none is lost. Bytes are counted by the
/// decoder chosen.
///
/// ```
/// use ghnet_receivers::{Decoder, Format};
/// let mut decoder = Decoder::new(None);
/// let mut epochs = Vec::new();
/// decoder.push(b"$GPRMC,143307.00,A,5546.82649,N,02334.71625,E,30.860,221.48,091209,,,A*5D\r\n", &mut epochs);
/// decoder.finish(&mut epochs);
/// assert_eq!(decoder.format(), Some(Format::Nmea));
/// assert_eq!(epochs.len(), 1);
/// assert!((epochs[0].course_deg - 221.48).abs() < 1e-3);
/// ```
#[derive(Debug)]
pub struct Decoder {
    inner: Inner,
}

#[derive(Debug)]
enum Inner {
    Detecting(Box<Detect>),
    Ubx(UbxDecoder),
    Nmea(NmeaDecoder),
    Gpsd(GpsdDecoder),
}

#[derive(Debug)]
struct Detect {
    ubx: UbxDecoder,
    gpsd: GpsdDecoder,
    nmea: NmeaDecoder,
    /// Epochs each candidate produced so far, in [`Format::ALL`] order.
    held: [Vec<Epoch>; 3],
}

impl Decoder {
    /// A decoder for `format`, or one that detects the format when `None`.
    pub fn new(format: Option<Format>) -> Self {
        Self::with_speed_accuracy(format, None)
    }

    /// Like [`new`](Self::new), giving NMEA and gpsd epochs the speed accuracy
    /// `sigma` (m/s, 1σ) instead of NaN; UBX epochs keep the receiver's `sAcc`.
    pub fn with_speed_accuracy(format: Option<Format>, sigma: Option<f32>) -> Self {
        let inner = match format {
            Some(Format::Ubx) => Inner::Ubx(UbxDecoder::new()),
            Some(Format::Nmea) => Inner::Nmea(NmeaDecoder::new().with_speed_accuracy(sigma)),
            Some(Format::Gpsd) => Inner::Gpsd(GpsdDecoder::new().with_speed_accuracy(sigma)),
            None => Inner::Detecting(Box::new(Detect {
                ubx: UbxDecoder::new(),
                gpsd: GpsdDecoder::new().with_speed_accuracy(sigma),
                nmea: NmeaDecoder::new().with_speed_accuracy(sigma),
                held: Default::default(),
            })),
        };
        Decoder { inner }
    }

    /// The format decoded, once known.
    pub fn format(&self) -> Option<Format> {
        match &self.inner {
            Inner::Detecting(_) => None,
            Inner::Ubx(_) => Some(Format::Ubx),
            Inner::Nmea(_) => Some(Format::Nmea),
            Inner::Gpsd(_) => Some(Format::Gpsd),
        }
    }

    /// Decodes `bytes` (any chunk of the stream), appending completed epochs to
    /// `out`.
    pub fn push(&mut self, bytes: &[u8], out: &mut Vec<Epoch>) {
        match &mut self.inner {
            Inner::Ubx(d) => d.push(bytes, out),
            Inner::Nmea(d) => d.push(bytes, out),
            Inner::Gpsd(d) => d.push(bytes, out),
            Inner::Detecting(d) => {
                d.ubx.push(bytes, &mut d.held[0]);
                d.gpsd.push(bytes, &mut d.held[1]);
                d.nmea.push(bytes, &mut d.held[2]);
                if let Some(format) = d.decided() {
                    self.settle(format, out);
                }
            }
        }
    }

    /// Ends the stream or a connection: counts an unfinished frame or line and
    /// forgets it, so the next bytes (after a reconnect) start afresh. A decoder
    /// still detecting settles on the best candidate now and gives out its epochs.
    pub fn finish(&mut self, out: &mut Vec<Epoch>) {
        match &mut self.inner {
            Inner::Ubx(d) => d.finish(),
            Inner::Nmea(d) => d.finish(),
            Inner::Gpsd(d) => d.finish(),
            Inner::Detecting(d) => {
                d.ubx.finish();
                d.gpsd.finish();
                d.nmea.finish();
                let format = d.best_guess();
                if d.held.iter().any(|h| !h.is_empty()) {
                    self.settle(format, out);
                }
            }
        }
    }

    /// Counters of the decoder chosen; while detecting, of the best candidate.
    pub fn stats(&self) -> &Stats {
        match &self.inner {
            Inner::Ubx(d) => d.stats(),
            Inner::Nmea(d) => d.stats(),
            Inner::Gpsd(d) => d.stats(),
            Inner::Detecting(d) => d.stats_of(d.best_guess()),
        }
    }

    fn settle(&mut self, format: Format, out: &mut Vec<Epoch>) {
        let Inner::Detecting(d) = std::mem::replace(&mut self.inner, Inner::Ubx(UbxDecoder::new()))
        else {
            return;
        };
        let Detect {
            ubx,
            gpsd,
            nmea,
            mut held,
        } = *d;
        let index = Format::ALL.iter().position(|&f| f == format).unwrap_or(0);
        out.append(&mut held[index]);
        self.inner = match format {
            Format::Ubx => Inner::Ubx(ubx),
            Format::Gpsd => Inner::Gpsd(gpsd),
            Format::Nmea => Inner::Nmea(nmea),
        };
    }
}

impl Detect {
    fn decided(&self) -> Option<Format> {
        if !self.held[0].is_empty() {
            return Some(Format::Ubx);
        }
        if !self.held[1].is_empty() {
            return Some(Format::Gpsd);
        }
        let nmea = self.nmea.stats().epochs();
        let ubx_seen = self.ubx.stats().bytes_used() > 0;
        (nmea > 0 && (!ubx_seen || nmea >= NMEA_PATIENCE)).then_some(Format::Nmea)
    }

    /// The candidate with epochs (in preference order), else the one that recognised
    /// the most bytes: a UBX stream without NAV-PVT is still reported as UBX.
    fn best_guess(&self) -> Format {
        if let Some(i) = self.held.iter().position(|h| !h.is_empty()) {
            return Format::ALL[i];
        }
        Format::ALL
            .into_iter()
            .max_by_key(|&f| self.stats_of(f).bytes_used())
            .unwrap_or(Format::Ubx)
    }

    fn stats_of(&self, format: Format) -> &Stats {
        match format {
            Format::Ubx => self.ubx.stats(),
            Format::Gpsd => self.gpsd.stats(),
            Format::Nmea => self.nmea.stats(),
        }
    }
}

/// Everything a whole recording gives: the format (detected or given), its epochs
/// and the decoder's counters.
#[derive(Debug)]
pub struct Decoded {
    /// The format decoded; `None` only for input in which no format recognised
    /// anything (then `epochs` is empty).
    pub format: Option<Format>,
    /// One per epoch, in stream order.
    pub epochs: Vec<Epoch>,
    /// Bytes, epochs and skips by reason.
    pub stats: Stats,
}

/// Decodes a whole recording at once (what `ghnet infer` does with a receiver log).
pub fn decode(bytes: &[u8], format: Option<Format>) -> Decoded {
    let mut decoder = Decoder::new(format);
    let mut epochs = Vec::new();
    decoder.push(bytes, &mut epochs);
    decoder.finish(&mut epochs);
    let stats = decoder.stats().clone();
    let format = decoder
        .format()
        .or_else(|| (stats.bytes_used() > 0).then(|| detect_guess(&decoder)));
    Decoded {
        format,
        epochs,
        stats,
    }
}

fn detect_guess(decoder: &Decoder) -> Format {
    match &decoder.inner {
        Inner::Detecting(d) => d.best_guess(),
        _ => decoder.format().unwrap_or(Format::Ubx),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ubx::NavPvt;

    fn pvt_frame(v_east: f32) -> Vec<u8> {
        let epoch = Epoch {
            time_ns: Some(1_600_000_000_000_000_000),
            v_east,
            ..Epoch::invalid(None)
        };
        let mut frame = Vec::new();
        NavPvt::from_epoch(&epoch).write_frame(&mut frame);
        frame
    }

    #[test]
    fn ubx_wins_over_nmea_on_a_shared_port() {
        let rmc = b"$GPRMC,143307.00,A,5546.82649,N,02334.71625,E,30.860,221.48,091209,,,A*5D\r\n";
        let mut stream = Vec::new();
        crate::ubx::write_frame(0x01, 0x20, &[0; 16], &mut stream); // NAV-TIMEGPS
        stream.extend_from_slice(rmc);
        stream.extend_from_slice(&pvt_frame(1.0));
        stream.extend_from_slice(rmc);
        let mut d = Decoder::new(None);
        let mut out = Vec::new();
        d.push(&stream, &mut out);
        assert_eq!(d.format(), Some(Format::Ubx));
        assert_eq!(out.len(), 1);
        assert!(d.stats().skipped(crate::Skip::Garbage) > 0);
    }

    #[test]
    fn undecided_input_settles_at_the_end() {
        let d = decode(b"# only a comment\n", None);
        assert_eq!((d.format, d.epochs.len()), (None, 0));
        let mut frames = Vec::new();
        crate::ubx::write_frame(0x0A, 0x04, &[0; 40], &mut frames); // MON-VER
        let d = decode(&frames, None);
        assert_eq!(d.format, Some(Format::Ubx));
        assert_eq!(d.stats.skipped(crate::Skip::Other), 1);
    }
}
