//! Real receiver captures through the real bridge into a real ghnetd: every capture in
//! `client/receivers/tests/data` (u-blox UBX, NMEA, gpsd JSON) is played by the
//! `ghnet-gnss` binary at `--replay-speed 0` into a ghnetd spawned by the kit, and
//! every epoch gets exactly one answer (counted on the heading service and in
//! `@ghnetd/stats`). The epoch counts are the hand-checked ones of
//! `expected.json`.

use std::path::PathBuf;
use std::process::{Child, Command, Stdio};

use ghnet_client::{HeadingStatus, HeadingSubscriber};
use ghnet_testkit::{assert_success, find_binary, recv_answer, Ghnetd, TestNamespace};

fn data_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../client/receivers/tests/data")
}

/// (file, epochs) of every capture.
fn captures() -> Vec<(String, u64)> {
    let text = std::fs::read_to_string(data_dir().join("expected.json")).unwrap();
    let entries: serde_json::Value = serde_json::from_str(&text).unwrap();
    let list = entries.as_array().expect("a list of captures");
    let capture = |e: &serde_json::Value| {
        let file = e["file"].as_str().expect("file").to_owned();
        (file, e["epochs"].as_u64().expect("epochs"))
    };
    list.iter().map(capture).collect()
}

/// Starts `ghnet-gnss` playing `file` as source `source` of `ns`, one sample in flight.
fn bridge(ns: &TestNamespace, source: &str, file: &str) -> Child {
    let bin = find_binary("ghnet-gnss").expect("ghnet-gnss is built by cargo test --workspace");
    Command::new(bin)
        .args([
            "--source",
            source,
            "--replay-speed",
            "0",
            "--answer-timeout",
            "10",
        ])
        .arg("--iceoryx2-global-prefix")
        .arg(ns.global_prefix())
        .arg("--iceoryx2-root-path")
        .arg(ns.root_path())
        .arg(data_dir().join(file))
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("run ghnet-gnss")
}

/// Waits for the bridge to end and checks it succeeded.
fn finish(bridge: Child, file: &str) {
    let out = bridge.wait_with_output().expect("wait for ghnet-gnss");
    assert_success(&out, file);
}

/// The statuses of every answer on `headings` until the bridge's `epochs` are in.
fn answers(headings: &HeadingSubscriber, epochs: u64, file: &str) -> Vec<HeadingStatus> {
    let mut statuses = Vec::new();
    for seq in 0..epochs {
        let h = recv_answer(headings, ghnet_testkit::WATCHDOG)
            .unwrap_or_else(|| panic!("{file}: no answer to epoch {seq} of {epochs}"));
        statuses.push(h.heading_status().expect("a known status"));
    }
    statuses
}

#[test]
fn every_real_capture_gets_one_answer_per_epoch_through_the_bridge() {
    let ns = TestNamespace::new("gnss_logs");
    let captures = captures();
    let mut builder = Ghnetd::builder(&ns).discovery(false);
    let sources: Vec<String> = (0..captures.len()).map(|i| format!("rx{i}")).collect();
    for s in &sources {
        builder = builder.source(s);
    }
    let daemon = builder.start();
    for ((file, epochs), source) in captures.iter().zip(&sources) {
        let headings = HeadingSubscriber::new(&ns.ipc(), source).unwrap();
        // Read while it plays: the heading service keeps only the newest answers.
        let child = bridge(&ns, source, file);
        let statuses = answers(&headings, *epochs, file);
        finish(child, file);
        ghnet_testkit::assert_silent(&headings, std::time::Duration::from_millis(200));
        let c = daemon.wait_for_counters(source, |c| c["answered"] >= *epochs);
        assert_eq!(
            (c["received"], c["answered"]),
            (*epochs, *epochs),
            "{file}: {c:?}"
        );
        if file == "ublox-neo-m8n.log" {
            // A parked receiver whose course is frozen: speed is noise, never Ok.
            assert!(
                !statuses.contains(&HeadingStatus::Ok),
                "{file}: {statuses:?}"
            );
        }
    }
    daemon.assert_running();
}
