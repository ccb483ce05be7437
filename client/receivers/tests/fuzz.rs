//! Property tests of the three decoders: arbitrary bytes, mutated real captures and
//! arbitrary chunking. Nothing may panic, every byte is accounted for, and how the
//! stream is cut into reads never changes what comes out.

use ghnet_receivers::ubx::NavPvt;
use ghnet_receivers::{decode, Decoder, Epoch, Format, Stats};
use proptest::prelude::*;

fn data(name: &str) -> Vec<u8> {
    let path = format!("{}/tests/data/{name}", env!("CARGO_MANIFEST_DIR"));
    std::fs::read(&path).unwrap_or_else(|e| panic!("{path}: {e}"))
}

/// One capture per format (small ones, so each case stays fast).
const CAPTURES: [(&str, Format); 3] = [
    ("ublox-neo-m8n.log", Format::Ubx),
    ("nl2008u.log", Format::Nmea),
    ("garmin15x.gpsd.jsonl", Format::Gpsd),
];

const FORMATS: [Option<Format>; 4] = [
    None,
    Some(Format::Ubx),
    Some(Format::Nmea),
    Some(Format::Gpsd),
];

/// Decodes `bytes` cut at `cuts` (positions, any order, any repeats).
fn decode_in_pieces(bytes: &[u8], cuts: &[usize], format: Option<Format>) -> (String, Stats) {
    let mut cuts: Vec<usize> = cuts.iter().map(|c| c % (bytes.len() + 1)).collect();
    cuts.sort_unstable();
    let mut d = Decoder::new(format);
    let mut out = Vec::new();
    let mut from = 0;
    for cut in cuts.into_iter().chain([bytes.len()]) {
        d.push(&bytes[from..cut], &mut out);
        from = cut;
    }
    d.finish(&mut out);
    (format!("{out:?}"), d.stats().clone())
}

fn accounted(s: &Stats) -> bool {
    s.bytes_in() == s.bytes_used() + s.bytes_skipped()
}

/// Bytes that look like receiver output often enough to reach deep code paths:
/// sync bytes, NMEA and JSON punctuation, digits, line ends, or anything.
fn noisy_bytes() -> impl Strategy<Value = Vec<u8>> {
    let byte = prop_oneof![
        any::<u8>(),
        Just(0xB5u8),
        Just(0x62u8),
        Just(0x01u8),
        Just(0x07u8),
        Just(b'$'),
        Just(b','),
        Just(b'*'),
        Just(b'\n'),
        Just(b'{'),
        Just(b'"'),
        Just(b'#'),
        (b'0'..=b'9'),
    ];
    prop::collection::vec(byte, 0..2000)
}

/// A random edit of a real capture: flip, delete, duplicate or insert bytes.
#[derive(Debug, Clone)]
enum Edit {
    Flip(usize, u8),
    Delete(usize, usize),
    Repeat(usize, usize),
    Insert(usize, Vec<u8>),
}

fn edit() -> impl Strategy<Value = Edit> {
    prop_oneof![
        (any::<usize>(), 1..=255u8).prop_map(|(at, x)| Edit::Flip(at, x)),
        (any::<usize>(), 1..200usize).prop_map(|(at, n)| Edit::Delete(at, n)),
        (any::<usize>(), 1..200usize).prop_map(|(at, n)| Edit::Repeat(at, n)),
        (any::<usize>(), prop::collection::vec(any::<u8>(), 1..50))
            .prop_map(|(at, b)| Edit::Insert(at, b)),
    ]
}

fn apply(bytes: &mut Vec<u8>, edit: &Edit) {
    let at = |i: usize, len: usize| if len == 0 { 0 } else { i % len };
    match edit {
        Edit::Flip(i, x) if !bytes.is_empty() => {
            let i = at(*i, bytes.len());
            bytes[i] ^= x;
        }
        Edit::Delete(i, n) => {
            let i = at(*i, bytes.len());
            let end = (i + n).min(bytes.len());
            bytes.drain(i..end);
        }
        Edit::Repeat(i, n) => {
            let i = at(*i, bytes.len());
            let end = (i + n).min(bytes.len());
            let copy = bytes[i..end].to_vec();
            bytes.splice(i..i, copy);
        }
        Edit::Insert(i, b) => {
            let i = at(*i, bytes.len() + 1);
            bytes.splice(i..i, b.iter().copied());
        }
        Edit::Flip(..) => {}
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]

    #[test]
    fn arbitrary_bytes_never_panic_and_are_accounted(bytes in noisy_bytes(), cuts in prop::collection::vec(any::<usize>(), 0..8)) {
        for format in FORMATS {
            let (one, s1) = decode_in_pieces(&bytes, &[], format);
            let (many, s2) = decode_in_pieces(&bytes, &cuts, format);
            prop_assert!(accounted(&s1) && accounted(&s2), "{format:?}: {s1} / {s2}");
            prop_assert_eq!(one, many, "{:?}", format);
        }
    }

    #[test]
    fn mutated_captures_resync(edits in prop::collection::vec(edit(), 1..6), cuts in prop::collection::vec(any::<usize>(), 0..12)) {
        for (file, format) in CAPTURES {
            let original = decode(&data(file), Some(format)).epochs.len();
            let mut bytes = data(file);
            for e in &edits {
                apply(&mut bytes, e);
            }
            for f in [None, Some(format)] {
                let (one, s) = decode_in_pieces(&bytes, &[], f);
                let (many, _) = decode_in_pieces(&bytes, &cuts, f);
                prop_assert!(accounted(&s), "{file}: {s}");
                prop_assert_eq!(&one, &many, "{} {:?}", file, f);
            }
            // Each edit can spoil a few epochs, never conjure many: the checksums hold.
            let after = decode(&bytes, Some(format)).epochs.len();
            let repeats = edits.iter().filter(|e| matches!(e, Edit::Repeat(..))).count();
            prop_assert!(after <= original + 2 * repeats + edits.len(), "{file}: {original} -> {after}");
        }
    }

    #[test]
    fn nav_pvt_encodes_and_decodes(
        t in 1_000_000_000_000_000_000u64..4_000_000_000_000_000_000,
        v in prop::array::uniform3(-100.0f32..100.0),
        s_acc in 0.0f32..50.0,
        course in 0.0f32..360.0,
        course_acc in 0.0f32..180.0,
        valid in any::<bool>(),
    ) {
        let epoch = Epoch {
            time_ns: Some(t),
            v_north: v[0],
            v_east: v[1],
            v_down: Some(v[2]),
            speed_accuracy: s_acc,
            valid,
            course_deg: course,
            course_accuracy_deg: course_acc,
        };
        let mut frame = Vec::new();
        NavPvt::from_epoch(&epoch).write_frame(&mut frame);
        let got = decode(&frame, None);
        prop_assert_eq!(got.format, Some(Format::Ubx));
        let e = got.epochs[0];
        prop_assert_eq!((e.time_ns, e.valid), (Some(t), valid));
        for (a, b) in [(e.v_north, v[0]), (e.v_east, v[1]), (e.v_down.unwrap(), v[2]), (e.speed_accuracy, s_acc)] {
            prop_assert!((a - b).abs() <= 0.0005 + b.abs() * 1e-6, "{a} vs {b}");
        }
        let dc = (e.course_deg - course + 540.0).rem_euclid(360.0) - 180.0;
        prop_assert!(dc.abs() < 1e-3 && (e.course_accuracy_deg - course_acc).abs() < 1e-3);
    }

    #[test]
    fn generated_rmc_sentences_decode(
        knots in 0.0f64..200.0,
        course in prop::option::of(0.0f64..360.0),
        status in prop_oneof![Just('A'), Just('V')],
        talker in prop_oneof![Just("GP"), Just("GN"), Just("GL"), Just("GA"), Just("GB")],
    ) {
        let course_text = course.map(|c| format!("{c:.2}")).unwrap_or_default();
        let body = format!("{talker}RMC,123519.00,{status},4807.038,N,01131.000,E,{knots:.3},{course_text},230394,003.1,W,A");
        let ck = body.bytes().fold(0u8, |x, b| x ^ b);
        let sentence = format!("${body}*{ck:02X}\r\n");
        let got = decode(sentence.as_bytes(), None);
        prop_assert_eq!(got.epochs.len(), 1);
        let e = got.epochs[0];
        let speed = (knots * 1852.0 / 3600.0) as f32;
        let expect_valid = status == 'A' && (course.is_some() || speed <= 1.0);
        prop_assert_eq!(e.valid, expect_valid);
        if let Some(c) = course {
            prop_assert!((e.speed() - speed).abs() < 1e-3);
            prop_assert!((e.course_deg - (c as f32)).abs() < 0.006 || (e.course_deg - (c as f32)).abs() > 359.99);
        } else {
            prop_assert!(e.course_deg.is_nan());
        }
    }
}
