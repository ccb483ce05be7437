//! Receiver logs in `ghnet infer`: a u-blox UBX, NMEA or gpsd JSON recording becomes
//! the CSV that [`crate::replay`] answers, one row per receiver epoch, with the
//! receiver's own course beside it so a user compares the two on their own log with
//! one command.
//!
//! Decoding is `ghnet_receivers`, the same code the `ghnet-gnss` bridge feeds ghnetd
//! with, so an epoch means the same thing offline and live. Columns: `timestamp_ns`
//! (empty when the receiver gave no date and time), `v_north`, `v_east`, `speed_acc`
//! (NaN unknown), `receiver_valid` (0 when the receiver marked the epoch unusable: its
//! velocity columns are then empty and the row is answered `invalid`),
//! `receiver_course_deg` (u-blox headMot, NMEA/gpsd course; empty when none) and
//! `receiver_course_acc_deg` (u-blox headAcc; empty when unknown).

use std::fmt::Write as _;

use ghnet_receivers::{decode, Epoch, Format};

use crate::logs::cell_or_empty;

/// What `ghnet infer --format` accepts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum InputFormat {
    /// CSV with a header holding `v_north` and `v_east`.
    Csv,
    /// u-blox UBX (NAV-PVT).
    Ubx,
    /// NMEA 0183 (RMC, VTG, GGA).
    Nmea,
    /// gpsd JSON (TPV).
    Gpsd,
}

/// A receiver log turned into CSV, with what the decoder saw.
#[derive(Debug)]
pub struct Converted {
    /// The CSV text (header and one row per epoch).
    pub csv: Vec<u8>,
    /// The format decoded.
    pub format: Format,
    /// The decoder's counters (`epochs=… invalid=… skipped: …`), for the summary line.
    pub stats: String,
}

/// `bytes` as CSV for [`crate::replay::run`]: `None` when `bytes` is CSV already
/// (`format` says so, or, undetermined, its first line names `v_north` or nothing in it
/// decodes as a receiver log); an error when a receiver `format` was given and nothing
/// decodes.
pub fn convert(bytes: &[u8], format: Option<InputFormat>) -> anyhow::Result<Option<Converted>> {
    let receiver = match format {
        Some(InputFormat::Csv) => return Ok(None),
        None if first_line_names_v_north(bytes) => return Ok(None),
        None => None,
        Some(InputFormat::Ubx) => Some(Format::Ubx),
        Some(InputFormat::Nmea) => Some(Format::Nmea),
        Some(InputFormat::Gpsd) => Some(Format::Gpsd),
    };
    let decoded = decode(bytes, receiver);
    let format = match decoded.format {
        Some(f) if !decoded.epochs.is_empty() => f,
        // Undetermined and no receiver epochs: let the CSV reader name what is missing.
        _ if receiver.is_none() => return Ok(None),
        _ => anyhow::bail!(
            "neither a CSV with a v_north column nor a receiver log with epochs \
             (UBX NAV-PVT, NMEA RMC/VTG, gpsd TPV); decoder: {}",
            decoded.stats
        ),
    };
    let mut csv = String::with_capacity(64 * (decoded.epochs.len() + 1));
    csv.push_str(HEADER);
    for e in &decoded.epochs {
        row(e, &mut csv);
    }
    Ok(Some(Converted {
        csv: csv.into_bytes(),
        format,
        stats: decoded.stats.to_string(),
    }))
}

const HEADER: &str = "timestamp_ns,v_north,v_east,speed_acc,receiver_valid,\
                      receiver_course_deg,receiver_course_acc_deg\n";

fn first_line_names_v_north(bytes: &[u8]) -> bool {
    let line = bytes.split(|&b| b == b'\n').next().unwrap_or_default();
    line.windows(7).any(|w| w == b"v_north")
}

/// One epoch as a CSV row (unknown values empty, speed accuracy NaN when unknown).
fn row(e: &Epoch, out: &mut String) {
    if let Some(t) = e.time_ns {
        let _ = write!(out, "{t}");
    }
    let (vn, ve) = if e.valid {
        (cell_or_empty(e.v_north), cell_or_empty(e.v_east))
    } else {
        (String::new(), String::new())
    };
    let _ = writeln!(
        out,
        ",{vn},{ve},{},{},{},{}",
        e.speed_accuracy,
        u8::from(e.valid),
        cell_or_empty(e.course_deg),
        cell_or_empty(e.course_accuracy_deg)
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn csv_is_passed_through_and_garbage_is_an_error() {
        let csv = b"t_s,v_north,v_east\n0,1,1\n";
        assert!(convert(csv, None).unwrap().is_none());
        assert!(convert(b"hello\nworld\n", None).unwrap().is_none());
        assert!(convert(b"hello\nworld\n", Some(InputFormat::Ubx)).is_err());
        assert!(convert(b"hello", Some(InputFormat::Csv)).unwrap().is_none());
    }

    #[test]
    fn an_nmea_standstill_has_an_empty_course_and_an_invalid_epoch_empty_velocity() {
        let log = concat!(
            "$GPRMC,143307.00,A,5546.82649,N,02334.71625,E,30.860,221.48,091209,,,A*5D\r\n",
            "$GPRMC,152505.00,A,5547.82113,N,02334.14130,E,0.253,,091209,,,A*7A\r\n",
            "$GPRMC,,V,,,,,,,,,,N*53\r\n",
        );
        let c = convert(log.as_bytes(), None)
            .unwrap()
            .expect("a receiver log");
        assert_eq!(c.format, Format::Nmea);
        let text = String::from_utf8(c.csv).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines.len(), 4, "{text}");
        let moving: Vec<&str> = lines[1].split(',').collect();
        assert_eq!(moving[0], "1260369187000000000");
        assert_eq!((moving[3], moving[4], moving[5]), ("NaN", "1", "221.48"));
        assert_eq!(
            lines[2].split(',').nth(5),
            Some(""),
            "no course at a standstill"
        );
        assert_eq!(lines[3], ",,,NaN,0,,", "void RMC");
    }
}
