//! Every real receiver capture in `tests/data` (gpsd's regression logs, BSD-2-Clause;
//! see tests/data/README.md) decodes to the epoch count and skip counters checked
//! by hand: frames counted with an independent Python scan (UBX sync, length,
//! Fletcher checksum) and sentences with `grep`, as written down in the README.

use std::collections::BTreeMap;

use ghnet_receivers::{decode, Decoded, Decoder, Epoch, Format};
use serde::Deserialize;

fn data(name: &str) -> Vec<u8> {
    let path = format!("{}/tests/data/{name}", env!("CARGO_MANIFEST_DIR"));
    std::fs::read(&path).unwrap_or_else(|e| panic!("{path}: {e}"))
}

/// What a capture must give (tests/data/expected.json, one entry per capture, with a
/// note on what the capture is): format, epochs, invalid epochs, epochs without a
/// time, and the skip counters that are not zero, by name.
#[derive(Deserialize)]
struct Expect {
    file: String,
    format: String,
    epochs: u64,
    invalid: u64,
    untimed: usize,
    skips: BTreeMap<String, u64>,
}

fn expected() -> Vec<Expect> {
    serde_json::from_slice(&data("expected.json")).expect("tests/data/expected.json")
}

fn check(e: &Expect, d: &Decoded) {
    let s = &d.stats;
    assert_eq!(
        d.format.map(Format::name),
        Some(e.format.as_str()),
        "{}",
        e.file
    );
    assert_eq!(
        (s.epochs(), s.invalid_epochs()),
        (e.epochs, e.invalid),
        "{}: {s}",
        e.file
    );
    assert_eq!(d.epochs.len() as u64, e.epochs, "{}", e.file);
    let untimed = d.epochs.iter().filter(|e| e.time_ns.is_none()).count();
    assert_eq!(untimed, e.untimed, "{}", e.file);
    let skips: BTreeMap<String, u64> = s.skips().map(|(k, n)| (k.name().into(), n)).collect();
    assert_eq!(skips, e.skips, "{}: {s}", e.file);
    assert_eq!(
        s.bytes_in(),
        s.bytes_used() + s.bytes_skipped(),
        "{}",
        e.file
    );
}

#[test]
fn every_capture_gives_the_counted_epochs() {
    for e in &expected() {
        let bytes = data(&e.file);
        check(e, &decode(&bytes, None));
        check(e, &decode(&bytes, Some(e.format.parse().unwrap())));
    }
}

#[test]
fn chunking_never_changes_the_result() {
    for e in &expected() {
        let bytes = data(&e.file);
        let whole = format!("{:?}", decode(&bytes, None).epochs);
        for size in [1, 2, 7, 100, 4096] {
            let mut d = Decoder::new(None);
            let mut epochs = Vec::new();
            for chunk in bytes.chunks(size) {
                d.push(chunk, &mut epochs);
            }
            d.finish(&mut epochs);
            assert_eq!(
                format!("{epochs:?}"),
                whole,
                "{} in chunks of {size}",
                e.file
            );
        }
    }
}

/// The `ublox` crate decodes the same NAV-PVT fields from every UBX capture.
#[test]
fn ubx_fields_agree_with_the_ublox_crate() {
    use ublox::proto23::{PacketRef, Proto23};
    for e in expected().iter().filter(|e| e.format == "ubx") {
        let bytes = data(&e.file);
        let mine = decode(&bytes, Some(Format::Ubx)).epochs;
        let mut parser = ublox::ParserBuilder::new()
            .with_protocol::<Proto23>()
            .with_vec_buffer();
        let mut it = parser.consume_ubx(&bytes);
        let mut theirs = Vec::new();
        while let Some(packet) = it.next() {
            if let Ok(ublox::UbxPacket::Proto23(PacketRef::NavPvt(p))) = packet {
                let mm = |v: i32| (f64::from(v) / 1000.0) as f32;
                theirs.push((
                    mm(p.vel_north_raw()),
                    mm(p.vel_east_raw()),
                    mm(p.vel_down_raw()),
                    (f64::from(p.speed_accuracy_raw()) / 1000.0) as f32,
                    p.heading_motion_raw(),
                    p.fix_type_raw(),
                ));
            }
        }
        assert_eq!(theirs.len(), mine.len(), "{}", e.file);
        for (m, t) in mine.iter().zip(&theirs) {
            assert_eq!(
                (m.v_north, m.v_east, m.v_down, m.speed_accuracy),
                (t.0, t.1, Some(t.2), t.3)
            );
            let head = t.4 as f32 / 1e5;
            assert!(
                (m.course_deg - head.rem_euclid(360.0)).abs() < 1e-3,
                "{}",
                e.file
            );
            assert_eq!(m.valid, (2..=4).contains(&t.5), "{}", e.file);
        }
    }
}

fn epochs(file: &str) -> Vec<Epoch> {
    decode(&data(file), None).epochs
}

/// Values gpsd itself reports for the same captures (its `.chk` regression
/// output: TPV `time`, `speed`, `track`, `eps`).
#[test]
fn values_match_gpsd_expected_output() {
    let m8n = epochs("ublox-neo-m8n.log");
    // {"class":"TPV",...,"time":"2017-07-19T08:50:00.800Z",...,"track":31.4718,
    //  "speed":0.030,"eps":0.23,...}
    let first = m8n[0];
    let t = first.time_ns.unwrap();
    assert_eq!((t + 500_000) / 1_000_000, 1_500_454_200_800);
    assert!((first.speed() - 0.030).abs() < 0.001);
    assert!((first.course_deg - 31.4718).abs() < 1e-4);
    assert!((first.speed_accuracy - 0.23).abs() < 0.005);

    let m8l = epochs("ublox-neo-m8l.log");
    // The NAV-PVT of 15:32:10 (the second TPV of that time; the first is from
    // HNR-PVT): {"time":"2024-01-30T15:32:10.000Z",...,"track":340.1238,
    // "speed":1.356,"eps":0.15,...}
    let last = m8l[18];
    assert!((last.course_deg - 340.1234).abs() < 0.01, "{last:?}");
    assert!((last.speed() - 1.356).abs() < 0.001);
    assert_eq!(
        last.time_ns.map(|t| (t + 500_000_000) / 1_000_000_000),
        Some(1_706_628_730)
    );
}

/// The standstill capture ghnetd must never answer `Ok`: a frozen course while the
/// velocity is noise around zero.
#[test]
fn neo_m8n_is_a_standstill_with_a_frozen_course() {
    for e in epochs("ublox-neo-m8n.log") {
        assert!(e.valid && e.speed() < 0.05, "{e:?}");
        assert!((e.course_deg - 31.4718).abs() < 1e-3);
        assert!(e.course_accuracy_deg > 8.0);
    }
}

#[test]
fn nmea_standstill_has_no_course_and_driving_has_one() {
    let bt451 = epochs("bt451.log");
    // $GPRMC,152505.00,A,...,0.253,,091209,,,A: empty course at 0.13 m/s.
    let still = bt451[4];
    assert!(
        still.valid && still.course_deg.is_nan() && still.speed() == 0.0,
        "{still:?}"
    );
    // $GPRMC,143307.00,A,...,30.860,221.48,091209,,,A
    let driving = bt451[13];
    assert!(driving.valid && (driving.course_deg - 221.48).abs() < 1e-3);
    assert!((driving.speed() - 30.86 * 1852.0 / 3600.0).abs() < 1e-3);
    let heading = driving
        .v_east
        .atan2(driving.v_north)
        .to_degrees()
        .rem_euclid(360.0);
    assert!((heading - 221.48).abs() < 1e-3);
}

#[test]
fn gpsd_velocities_come_from_vel_ned_or_speed_and_track() {
    // {"class":"TPV","mode":2,"time":"2022-10-18T11:32:58.000Z",...,"track":247.1000,
    //  "magtrack":256.4000,"magvar":9.3,"speed":2.727}
    let garmin = epochs("garmin15x.gpsd.jsonl");
    let first = garmin[0];
    assert_eq!(first.time_ns, Some(1_666_092_778_000_000_000));
    assert!((first.speed() - 2.727).abs() < 1e-5 && (first.course_deg - 247.1).abs() < 1e-4);
    assert!(garmin.iter().all(|e| e.valid && e.speed() > 1.0));
    let m8l = epochs("ublox-neo-m8l.gpsd.jsonl");
    // {"time":"2024-01-30T15:31:52.100Z",...,"track":250.9091,...,"speed":0.832}
    let first = m8l[0];
    assert_eq!(first.time_ns, Some(1_706_628_712_100_000_000));
    assert!((first.speed() - 0.832).abs() < 1e-5 && (first.course_deg - 250.9091).abs() < 1e-4);
    assert!(first.v_down.is_none()); // no climb in that report
}
