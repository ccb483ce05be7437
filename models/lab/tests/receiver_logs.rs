//! `ghnet infer` on real receiver captures (the gpsd regression logs committed under
//! client/receivers/tests/data, BSD-2): one output row per epoch, the receiver's own
//! course beside ghnet's heading, invalid epochs answered `invalid`.

use std::process::Command;

fn capture(name: &str) -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../client/receivers/tests/data")
        .join(name)
}

/// Runs `ghnet infer` on `file` and returns the output's rows as maps column → value.
fn infer(file: &str, extra: &[&str]) -> Vec<std::collections::BTreeMap<String, String>> {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out.csv");
    let status = Command::new(env!("CARGO_BIN_EXE_ghnet"))
        .args(["infer", "--model", "kf", "--input"])
        .arg(capture(file))
        .arg("--output")
        .arg(&out)
        .args(extra)
        .status()
        .unwrap();
    assert!(status.success(), "{file}: {status}");
    let mut rdr = csv::Reader::from_path(&out).unwrap();
    let header = rdr.headers().unwrap().clone();
    rdr.records()
        .map(|r| {
            let r = r.unwrap();
            header
                .iter()
                .map(String::from)
                .zip(r.iter().map(String::from))
                .collect()
        })
        .collect()
}

#[test]
fn a_ubx_log_gives_one_row_per_nav_pvt_with_headmot_and_headacc() {
    // NEO-M8L moving at 0.4-1.4 m/s: 19 NAV-PVT (tests/data/expected.json).
    let rows = infer("ublox-neo-m8l.log", &[]);
    assert_eq!(rows.len(), 19);
    for r in &rows {
        let course: f32 = r["receiver_course_deg"].parse().unwrap();
        let acc: f32 = r["receiver_course_acc_deg"].parse().unwrap();
        assert!((0.0..360.0).contains(&course) && acc > 0.0, "{r:?}");
        assert_ne!(r["status"], "invalid", "{r:?}");
        assert!(r["heading_deg"].parse::<f32>().is_ok(), "{r:?}");
    }
}

#[test]
fn an_nmea_log_gives_one_row_per_epoch_and_its_void_fixes_are_invalid() {
    // SiRF-II: 74 RMC epochs, 6 of them void (tests/data/expected.json); `--format`
    // given explicitly this time.
    let rows = infer("haicom-305N.log", &["--format", "nmea"]);
    assert_eq!(rows.len(), 74);
    let invalid = rows.iter().filter(|r| r["status"] == "invalid").count();
    assert_eq!(invalid, 6);
    assert!(rows.iter().all(|r| r["receiver_course_acc_deg"].is_empty()));
    let moving = rows
        .iter()
        .find(|r| r["receiver_valid"] == "1" && !r["receiver_course_deg"].is_empty())
        .expect("a moving epoch with a course");
    assert!(moving["heading_deg"].parse::<f32>().is_ok());
}

#[test]
fn a_file_that_is_neither_csv_nor_a_receiver_log_is_one_error() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("notes.txt");
    std::fs::write(&input, "hello\nworld\n").unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_ghnet"))
        .args(["infer", "--input"])
        .arg(&input)
        .arg("--output")
        .arg(dir.path().join("out.csv"))
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("v_north"),
        "the CSV reader names the column: {err}"
    );
}
