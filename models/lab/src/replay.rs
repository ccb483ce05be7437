//! Offline inference over CSV logs, streaming in constant memory.
//!
//! Input: a CSV with a header that has `v_north` and `v_east` columns (m/s), and
//! optionally `speed_acc` (the receiver's 1σ speed accuracy, m/s, like u-blox sAcc; empty
//! when unknown), which full-circle models use for σ; every other column passes through
//! unchanged. Output: the same rows with `heading_deg` (clockwise from
//! north, [0, 360)), `heading_std_deg` and `status` appended. A row whose velocity is
//! empty, unparsable, NaN, infinite or absurd (over the policy's max speed) gets status
//! `invalid` and empty heading fields; it never stops the file. Rows are read, answered
//! and written in blocks, so memory does not grow with the file.
//!
//! `ghnet infer` answers each track through the sample rules ghnetd applies to a
//! source ([`Streams`]: `ghnet_inference::source`, one `SourceStream` per track), so a log
//! replayed here and the same samples published into ghnetd get the same answers: rows
//! in file order, one stream per value of a `track` column (all rows share one without
//! it), time from `t_s` (seconds) or `timestamp_ns`. A row whose time is earlier than
//! the previous row's of its track is `invalid` and clears the track's history (for a
//! stateful model); a time step longer than the model's gap limit clears it too.
//! Without a time column rows are taken as one second apart. A row whose time does not
//! parse is `invalid`. The per-epoch batch path ([`Answer`] for `Predictor`, no
//! per-source rules) is there for callers that want raw answers in bulk.
//!
//! # Malformed input
//!
//! What is an error (the whole file stops, with a one-line message) and what is a row
//! answered `invalid` (counted in [`InferSummary::invalid`], first one's row number in
//! [`InferSummary::first_invalid_row`]) is decided here once:
//!
//! | input | result |
//! |---|---|
//! | no header, or a header without `v_north` / `v_east` (also an empty file) | error [`InferError::MissingColumn`] naming the column |
//! | header already has `heading_deg`, `heading_std_deg` or `status` | error [`InferError::DuplicateColumn`] |
//! | header names with spaces around them, a UTF-8 byte-order mark, CRLF line ends | accepted (trimmed, stripped) |
//! | empty lines | skipped (not rows, not counted; CSV has no empty records) |
//! | a row with fewer or more fields than the header | `invalid`; padded with empty fields or cut to the header's width, so every output row lines up with the output header |
//! | non-numeric, empty, `NaN`, `inf`, non-UTF-8 velocity fields | `invalid` |
//! | a velocity over the policy's `max_speed` (100 m/s) | `invalid` |
//! | a time earlier than the previous row's of the track | `invalid`; the track's history (stateful models) is cleared |
//! | `speed_acc` non-numeric, empty, NaN, infinite or negative | unknown accuracy, answered with the network's σ (logs often write -1 for "not available"; the live wire has NaN for that and ghnetd rejects a negative one) |
//! | a huge line (megabytes in one field) | answered like any row (`invalid` if it is a velocity field); memory grows with the longest row only |
//! | an unterminated quote | the field runs to the end of the file: one more (likely `invalid`) row |
//! | a read or write failure | error [`InferError::Io`] / [`InferError::Csv`] |

use std::collections::HashMap;
use std::io::{Read, Write};
use std::sync::Arc;

use ghnet_inference::{Model, Runner, Sample, SourceStream, StatusPolicy};
use ghnet_inference::{Prediction, Predictor, Status};

/// Rows per block: large enough for the batch path, small enough to stay in cache.
const BLOCK: usize = 1024;

/// One block of parsed rows: what the model sees, separated from the CSV handling so
/// other readers (UBX, NMEA) can feed the same answerers.
#[derive(Debug, Default)]
pub struct Rows {
    /// North velocity, m/s (NaN when the field did not parse).
    pub v_north: Vec<f32>,
    /// East velocity, m/s.
    pub v_east: Vec<f32>,
    /// Speed accuracy, m/s (NaN unknown).
    pub speed_acc: Vec<f32>,
    /// Time, s (from `t_s` or `timestamp_ns`; the row number when the file has neither).
    pub t_s: Vec<f64>,
    /// Hash of the `track` field (0 without the column): rows of one value share a history.
    pub track: Vec<u64>,
}

/// Where the fields the model needs are in a record.
struct Columns {
    v_north: usize,
    v_east: usize,
    speed_acc: Option<usize>,
    t_s: Option<usize>,
    timestamp_ns: Option<usize>,
    track: Option<usize>,
}

impl Columns {
    /// The columns of `header`; an error when a required one is missing or an output
    /// column already exists.
    fn find(header: &csv::ByteRecord) -> Result<Self, InferError> {
        // Spaces around a name (`v_north, v_east`) are a common hand-edit; accept them.
        let find = |name: &'static str| {
            header
                .iter()
                .position(|h| h.trim_ascii() == name.as_bytes())
        };
        if let Some(c) = OUTPUT_COLUMNS.into_iter().find(|c| find(c).is_some()) {
            return Err(InferError::DuplicateColumn(c));
        }
        Ok(Columns {
            v_north: find("v_north").ok_or(InferError::MissingColumn("v_north"))?,
            v_east: find("v_east").ok_or(InferError::MissingColumn("v_east"))?,
            speed_acc: find("speed_acc"),
            t_s: find("t_s"),
            timestamp_ns: find("timestamp_ns"),
            track: find("track"),
        })
    }
}

impl Rows {
    fn clear(&mut self) {
        self.v_north.clear();
        self.v_east.clear();
        self.speed_acc.clear();
        self.t_s.clear();
        self.track.clear();
    }

    /// Parse one record (the `row`-th of the file, from 0).
    fn push(&mut self, r: &csv::ByteRecord, c: &Columns, row: u64) {
        self.v_north.push(parse_field(r.get(c.v_north)));
        self.v_east.push(parse_field(r.get(c.v_east)));
        // Logs often write -1 for "not available": unknown, as NaN is on the wire.
        let acc = c.speed_acc.map_or(f32::NAN, |i| parse_field(r.get(i)));
        let known = acc.is_finite() && acc >= 0.0;
        self.speed_acc.push(if known { acc } else { f32::NAN });
        self.t_s.push(match (c.t_s, c.timestamp_ns) {
            (Some(i), _) => parse_time(r.get(i), 1.0),
            (None, Some(i)) => parse_time(r.get(i), 1e-9),
            (None, None) => row as f64,
        });
        self.track.push(key(c.track.and_then(|i| r.get(i))));
    }
}

/// What answers a block of rows.
pub trait Answer {
    /// Answer `rows` into `out` (same length), in order.
    fn answer(&mut self, rows: &Rows, out: &mut [Prediction]);
}

/// Per-epoch models in bulk: the batch path, no per-source rules (no time checks).
impl Answer for Predictor {
    fn answer(&mut self, rows: &Rows, out: &mut [Prediction]) {
        self.predict_batch_with_accuracy(&rows.v_north, &rows.v_east, &rows.speed_acc, out);
    }
}

/// Stateful models (temporal, `kf`): one [`SourceStream`] per `track` value, the rules
/// ghnetd applies to a source (time backwards, gap over the model's limit).
#[derive(Debug)]
pub struct Streams {
    runner: Runner,
    tracks: HashMap<u64, SourceStream>,
}

impl Streams {
    /// Answer with `model`.
    pub fn new(model: Arc<Model>) -> Self {
        Self {
            runner: Runner::new(model, StatusPolicy::default(), None),
            tracks: HashMap::new(),
        }
    }
}

impl Answer for Streams {
    fn answer(&mut self, rows: &Rows, out: &mut [Prediction]) {
        for (i, o) in out.iter_mut().enumerate() {
            let runner = &self.runner;
            let track = self
                .tracks
                .entry(rows.track[i])
                .or_insert_with(|| runner.stream(None));
            let sample = Sample {
                // A log has no sequence numbers: rows of a track follow each other.
                seq: track.counts().received,
                t_s: rows.t_s[i],
                v_north: rows.v_north[i],
                v_east: rows.v_east[i],
                v_down: 0.0,
                speed_acc: rows.speed_acc[i],
                flagged: false,
            };
            *o = self.runner.answer(track, &sample);
        }
    }
}

/// FNV-1a of a field, the history key of a `track` value.
fn key(b: Option<&[u8]>) -> u64 {
    b.unwrap_or_default()
        .trim_ascii()
        .iter()
        .fold(0xcbf2_9ce4_8422_2325, |h, &c| {
            (h ^ c as u64).wrapping_mul(0x0100_0000_01b3)
        })
}

/// Columns appended to every row.
pub const OUTPUT_COLUMNS: [&str; 3] = ["heading_deg", "heading_std_deg", "status"];

/// Why a file could not be processed (as opposed to a row, which is answered `invalid`).
#[derive(Debug, thiserror::Error)]
pub enum InferError {
    /// The header (line 1) lacks a required column.
    #[error("input has no `{0}` column in its header (line 1; need a header with v_north and v_east, in m/s)")]
    MissingColumn(&'static str),
    /// The header already has a column this command would add.
    #[error("input already has a `{0}` column; rename it or drop it first")]
    DuplicateColumn(&'static str),
    /// Reading or writing failed.
    #[error("csv: {0}")]
    Csv(#[from] csv::Error),
    /// Writing failed.
    #[error("write: {0}")]
    Io(#[from] std::io::Error),
}

/// What a run did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct InferSummary {
    /// Data rows read (and written).
    pub rows: u64,
    /// Rows answered `invalid`.
    pub invalid: u64,
    /// Data row (1-based, the header not counted, empty lines not counted) of the
    /// first `invalid` row, so a user can find it; `None` when every row was answered.
    /// A row number rather than a line: quoted fields may span lines.
    pub first_invalid_row: Option<u64>,
}

/// Parse a velocity field: empty or unparsable gives NaN, which the predictor answers
/// `invalid`.
fn parse_field(field: Option<&[u8]>) -> f32 {
    field
        .and_then(|b| std::str::from_utf8(b).ok())
        .and_then(|s| s.trim().parse::<f32>().ok())
        .unwrap_or(f32::NAN)
}

/// Parse a time field in units of `scale` seconds; NaN (answered `invalid`) when absent.
fn parse_time(field: Option<&[u8]>, scale: f64) -> f64 {
    field
        .and_then(|b| std::str::from_utf8(b).ok())
        .and_then(|s| s.trim().parse::<f64>().ok())
        .map_or(f64::NAN, |v| v * scale)
}

/// Format a finite value with four decimals into `buf` (`{:.4}` through `fmt` costs a
/// tenth of a day-long replay; this is integer formatting with itoa).
fn fixed4(x: f32, buf: &mut Vec<u8>) -> &[u8] {
    buf.clear();
    let v = (x as f64 * 10_000.0).round() as i64;
    if v < 0 {
        buf.push(b'-');
    }
    let v = v.unsigned_abs();
    let mut ib = itoa::Buffer::new();
    buf.extend_from_slice(ib.format(v / 10_000).as_bytes());
    buf.push(b'.');
    let frac = ib.format(v % 10_000 + 10_000).as_bytes(); // "1xxxx": keeps leading zeros
    buf.extend_from_slice(&frac[1..]);
    buf
}

/// Pads `rec` with empty fields or cuts it to `width` fields, so that its output row
/// lines up with the header; `false` when it had another width (the row is then
/// `invalid`: which of its fields is which is a guess).
fn fit_to_width(rec: &mut csv::ByteRecord, width: usize) -> bool {
    let fits = rec.len() == width;
    rec.truncate(width);
    while rec.len() < width {
        rec.push_field(b"");
    }
    fits
}

/// Refuses to write `output` when it is the file `input` was opened from (same device
/// and inode, so hard and symbolic links count too): creating the output would
/// truncate the input before a row is read. Checked before anything is created.
pub fn refuse_same_file(input: &std::fs::File, output: &std::path::Path) -> anyhow::Result<()> {
    use std::os::unix::fs::MetadataExt;
    let inp = input.metadata()?;
    match std::fs::metadata(output) {
        Ok(out) if (out.dev(), out.ino()) == (inp.dev(), inp.ino()) => anyhow::bail!(
            "--output {} is the input file (same device and inode); refusing to overwrite it",
            output.display()
        ),
        _ => Ok(()),
    }
}

/// Stream `input` to `output`, answering every row.
pub fn run(
    predictor: &mut impl Answer,
    input: impl Read,
    output: impl Write,
) -> Result<InferSummary, InferError> {
    let mut rdr = csv::ReaderBuilder::new()
        .flexible(true)
        .has_headers(true)
        .from_reader(input);
    let mut wtr = csv::WriterBuilder::new().flexible(true).from_writer(output);
    let header = rdr.byte_headers()?.clone();
    let cols = Columns::find(&header)?;
    let mut out_header = header.clone();
    OUTPUT_COLUMNS
        .iter()
        .for_each(|c| out_header.push_field(c.as_bytes()));
    wtr.write_byte_record(&out_header)?;

    let mut records: Vec<csv::ByteRecord> = (0..BLOCK).map(|_| csv::ByteRecord::new()).collect();
    let mut rows = Rows::default();
    let mut preds = vec![Prediction::INVALID; BLOCK];
    let mut summary = InferSummary::default();
    let mut num = Vec::with_capacity(32);
    loop {
        rows.clear();
        let mut n = 0;
        while n < BLOCK && rdr.read_byte_record(&mut records[n])? {
            let fits = fit_to_width(&mut records[n], header.len());
            rows.push(&records[n], &cols, summary.rows + n as u64);
            if !fits {
                // NaN velocity: answered `invalid`, like any unusable row.
                *rows.v_north.last_mut().expect("just pushed") = f32::NAN;
            }
            n += 1;
        }
        if n == 0 {
            break;
        }
        predictor.answer(&rows, &mut preds[..n]);
        for (rec, p) in records[..n].iter_mut().zip(&preds[..n]) {
            summary.rows += 1;
            if p.status == Status::Invalid {
                summary.invalid += 1;
                if summary.first_invalid_row.is_none() {
                    summary.first_invalid_row = Some(summary.rows);
                }
                rec.push_field(b"");
                rec.push_field(b"");
            } else {
                // [0, 360) must survive rounding: 359.99996 prints as 0.0000, not 360.0000.
                let h = if p.heading_deg >= 359.999_95 {
                    0.0
                } else {
                    p.heading_deg
                };
                rec.push_field(fixed4(h, &mut num));
                rec.push_field(fixed4(p.std_deg, &mut num));
            }
            rec.push_field(p.status.as_str().as_bytes());
            wtr.write_byte_record(rec)?;
        }
        if n < BLOCK {
            break;
        }
    }
    wtr.flush()?;
    Ok(summary)
}

#[cfg(test)]
mod tests {
    use super::*;
    use ghnet_inference::Model;
    use std::sync::Arc;

    fn predictor() -> Predictor {
        Predictor::new(Arc::new(
            Model::builtin("ghnet-epoch").expect("embedded model"),
        ))
    }

    fn infer(input: &str) -> Result<(String, InferSummary), InferError> {
        let mut out = Vec::new();
        let s = run(&mut predictor(), input.as_bytes(), &mut out)?;
        Ok((String::from_utf8(out).unwrap(), s))
    }

    #[test]
    fn passes_columns_through_and_appends_three() {
        let (out, s) = infer("t,v_north,v_east,note\n1,1.0,1.0,a\n2,0.0,-2.0,\"b,c\"\n").unwrap();
        let lines: Vec<&str> = out.lines().collect();
        assert_eq!(
            lines[0],
            "t,v_north,v_east,note,heading_deg,heading_std_deg,status"
        );
        assert!(lines[1].starts_with("1,1.0,1.0,a,"), "{}", lines[1]);
        assert!(lines[2].starts_with("2,0.0,-2.0,\"b,c\","), "{}", lines[2]);
        let h: f32 = lines[2].split(',').nth(5).unwrap().parse().unwrap();
        assert!((h - 270.0).abs() < 5.0, "heading {h}");
        assert_eq!(
            s,
            InferSummary {
                rows: 2,
                invalid: 0,
                first_invalid_row: None,
            }
        );
    }

    #[test]
    fn bad_rows_are_invalid_and_never_stop_the_file() {
        let input = "v_north,v_east\n,1\nNaN,1\ninf,0\n1,-inf\n200,0\nabc,1\n1\n1,1\n";
        let (out, s) = infer(input).unwrap();
        let lines: Vec<&str> = out.lines().collect();
        assert_eq!(lines.len(), 9);
        for l in &lines[1..8] {
            assert!(l.ends_with(",,,invalid") || l.ends_with(",,invalid"), "{l}");
        }
        assert!(
            lines[8].ends_with(",ok") || lines[8].contains("low_speed"),
            "{}",
            lines[8]
        );
        assert_eq!(
            s,
            InferSummary {
                rows: 8,
                invalid: 7,
                first_invalid_row: Some(1),
            }
        );
    }

    #[test]
    fn speed_accuracy_column_sets_sigma_for_the_full_circle_model() {
        let (out, _) = infer("v_north,v_east,speed_acc\n2,0,0.02\n2,0,0.4\n2,0,\n").unwrap();
        let std: Vec<f32> = out
            .lines()
            .skip(1)
            .map(|l| l.split(',').nth(4).unwrap().parse().unwrap())
            .collect();
        assert!(
            std[0] < std[1],
            "a noisier receiver must give a larger σ: {std:?}"
        );
        assert!(std[2].is_finite() && std[2] > 0.0);
    }

    #[test]
    fn fixed_point_formatting() {
        let mut b = Vec::new();
        for (x, want) in [
            (0.0f32, "0.0000"),
            (1.5, "1.5000"),
            (359.99996, "360.0000"),
            (12.00049, "12.0005"),
            (0.0001, "0.0001"),
            (-3.25, "-3.2500"),
            (103.92305, "103.9230"),
        ] {
            assert_eq!(std::str::from_utf8(fixed4(x, &mut b)).unwrap(), want, "{x}");
        }
    }

    #[test]
    fn missing_columns_are_one_line_errors() {
        let e = infer("north,v_east\n1,2\n").unwrap_err().to_string();
        assert!(e.contains("`v_north`") && !e.contains('\n'), "{e}");
        let e = infer("v_north,v_east,status\n1,2,x\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("`status`"), "{e}");
        let (out, s) = infer("v_north,v_east\n").unwrap();
        assert_eq!(out.lines().count(), 1);
        assert_eq!(s.rows, 0);
    }

    /// Status column of each output row, `low_speed` shown as `ok` (answered with a
    /// heading either way; which one depends on the model's σ at that speed).
    fn statuses(out: &str) -> Vec<String> {
        out.lines()
            .skip(1)
            .map(|l| match l.rsplit(',').next().unwrap() {
                "low_speed" => "ok".to_owned(),
                other => other.to_owned(),
            })
            .collect()
    }

    #[test]
    fn wrong_header_is_an_error_naming_the_column_and_line_1() {
        for input in [
            "1.0,2.0\n3.0,4.0\n",
            "",
            "\n\n",
            "vn,ve\n1,2\n",
            "V_NORTH,V_EAST\n1,2\n",
        ] {
            let e = infer(input).unwrap_err().to_string();
            assert!(
                e.contains("`v_north`") && e.contains("line 1"),
                "{input:?}: {e}"
            );
            assert!(!e.contains('\n'), "one line: {e}");
        }
        let e = infer("v_north\n1\n").unwrap_err().to_string();
        assert!(e.contains("`v_east`"), "{e}");
    }

    #[test]
    fn header_spaces_bom_and_crlf_are_accepted() {
        let (out, s) = infer("\u{feff}t , v_north ,\tv_east\r\n1,3,4\r\n2,0,-2\r\n").unwrap();
        assert_eq!(statuses(&out), ["ok", "ok"], "{out}");
        assert_eq!((s.rows, s.invalid), (2, 0));
        // Header names pass through as written (only the match is trimmed).
        assert!(
            out.starts_with("t , v_north ,\tv_east,heading_deg"),
            "{out}"
        );
    }

    #[test]
    fn empty_lines_are_skipped_not_counted() {
        let (out, s) = infer("v_north,v_east\n\n1,1\n\n\r\n\n2,2\n\n").unwrap();
        assert_eq!(s.rows, 2, "{out}");
        assert_eq!(s.invalid, 0);
    }

    #[test]
    fn short_long_and_non_numeric_rows() {
        let input = "t,v_north,v_east\n\
                     1,1,1\n\
                     2,1\n\
                     3\n\
                     4,1,1,extra,fields\n\
                     5,north,1\n\
                     6,1,0x10\n\
                     7,\"1\",\"1\"\n\
                     8, 1 , 1 \n\
                     9,1e400,1\n\
                     10,1;5,1\n";
        let (out, s) = infer(input).unwrap();
        assert_eq!(
            statuses(&out),
            [
                "ok", "invalid", "invalid", "invalid", "invalid", "invalid", "ok", "ok", "invalid",
                "invalid"
            ],
            "{out}"
        );
        assert_eq!((s.rows, s.invalid, s.first_invalid_row), (10, 7, Some(2)));
        // Short rows are padded, long ones cut: every row lines up with the header.
        assert!(out.contains("\n3,,,,,invalid\n"), "{out}");
        assert!(out.contains("\n4,1,1,,,invalid\n"), "{out}");
        assert!(out.lines().all(|l| l.split(',').count() == 6), "{out}");
    }

    #[test]
    fn nan_and_infinity_strings_are_invalid() {
        let input =
            "v_north,v_east\nNaN,1\nnan,1\n-NaN,1\ninf,1\n-inf,1\ninfinity,1\n1,+Infinity\n1,1\n";
        let (out, s) = infer(input).unwrap();
        assert_eq!((s.rows, s.invalid), (8, 7), "{out}");
        assert_eq!(statuses(&out).last().unwrap(), "ok");
    }

    #[test]
    fn huge_line_is_one_invalid_row_and_the_next_row_is_fine() {
        let mut input = String::from("v_north,v_east,note\n");
        input.push_str(&"9".repeat(2_000_000));
        input.push_str(",1,");
        input.push_str(&"x".repeat(1_000_000));
        input.push_str("\n1,1,short\n");
        let (out, s) = infer(&input).unwrap();
        assert_eq!((s.rows, s.invalid), (2, 1));
        assert!(out.contains("\n1,1,short,"), "the next row passes through");
        assert_eq!(statuses(&out), ["invalid", "ok"]);
    }

    #[test]
    fn non_utf8_and_quotes_never_stop_the_file() {
        let mut input = b"v_north,v_east,note\n".to_vec();
        input.extend_from_slice(b"\xff\xfe,1,a\n");
        input.extend_from_slice(b"1,1,\xc3\x28\n"); // invalid UTF-8 passes through
        input.extend_from_slice(b"1,1,\"multi\nline\"\n");
        input.extend_from_slice(b"1,1,\"unterminated\n2,2,x\n");
        let mut out = Vec::new();
        let s = run(&mut predictor(), input.as_slice(), &mut out).unwrap();
        // The unterminated quote swallows the rest of the file into one field.
        assert_eq!((s.rows, s.invalid, s.first_invalid_row), (4, 1, Some(1)));
        assert!(
            out.windows(2).any(|w| w == b"\xc3\x28"),
            "bytes pass through"
        );
    }

    #[test]
    fn bad_speed_accuracy_means_unknown() {
        let (out, s) =
            infer("v_north,v_east,speed_acc\n2,0,\n2,0,-1\n2,0,abc\n2,0,inf\n2,0,NaN\n").unwrap();
        assert_eq!(s.invalid, 0, "{out}");
        let std: Vec<&str> = out
            .lines()
            .skip(1)
            .map(|l| l.split(',').nth(4).unwrap())
            .collect();
        assert!(
            std.iter().all(|x| *x == std[0]),
            "all the network's σ: {std:?}"
        );
    }

    #[test]
    fn batch_output_equals_single_sample_path() {
        let mut p = predictor();
        let mut input = String::from("v_north,v_east\n");
        let mut expect = Vec::new();
        for i in 0..3000 {
            let a = i as f32 * 0.37;
            let s = 0.01 * (i % 400) as f32;
            let (vn, ve) = (s * a.cos(), s * a.sin());
            input.push_str(&format!("{vn},{ve}\n"));
            expect.push(p.predict(vn, ve));
        }
        let (out, _) = infer(&input).unwrap();
        for (line, e) in out.lines().skip(1).zip(&expect) {
            let f: Vec<&str> = line.split(',').collect();
            let h: f32 = f[2].parse().unwrap();
            assert!(
                (h - e.heading_deg).abs() < 1e-3 || (h - e.heading_deg).abs() > 359.99,
                "{line} vs {e:?}"
            );
            assert_eq!(f[4], e.status.as_str());
        }
    }
}
