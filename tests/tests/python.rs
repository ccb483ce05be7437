//! The Python examples against the real ghnetd: `publish_velocity.py` (PyPI
//! `iceoryx2==0.10.0`) feeds it over shared memory, `subscribe_heading.py` (PyPI
//! `eclipse-zenoh==1.10.2`) decodes its Zenoh headings with `struct`, and a Rust
//! subscriber on iceoryx2 and one on Zenoh see the same values.
//!
//! Needs `python3` with both packages: ignored unless asked for (`--include-ignored`;
//! `.ci/run` installs them and does).

use std::collections::BTreeMap;
use std::io::{BufRead, BufReader};
use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::sync::mpsc;

use ghnet_client::{encode_zenoh, HeadingEstimate, HeadingSubscriber, ZenohHeadingSubscriber};
use ghnet_testkit::{assert_success, zenoh_barrier, Ghnetd, Listen, TestNamespace, WATCHDOG};

fn python_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../examples/python")
}

#[test]
#[ignore = "needs python3 with iceoryx2==0.10.0 and eclipse-zenoh==1.10.2"]
fn python_publisher_gets_headings_and_python_subscriber_decodes_the_same_values() {
    let ns = TestNamespace::new("python");
    // The Python subscriber as documented: tcp to the daemon, another prefix than
    // the default one.
    let daemon = (Ghnetd::builder(&ns).prefix("py/ghnet"))
        .listen(Listen::Tcp)
        .start();
    let (ipc, endpoint) = (daemon.ipc().clone(), daemon.zenoh_endpoint());
    let prefix = ipc.prefix();

    // Rust subscribers first (iceoryx2 keeps no history).
    let ice = HeadingSubscriber::new(&ipc, "pysrc").unwrap();
    let session = daemon.connect();
    let zen = ZenohHeadingSubscriber::new(&session, &ipc, "pysrc").unwrap();
    zenoh_barrier(&session, &ipc);

    let n = 60u64;
    let count = n.to_string();
    // The Python subscriber prints one JSON line per heading, after a ready line.
    let mut py_sub = Command::new("python3")
        .arg(python_dir().join("subscribe_heading.py"))
        .args([
            "--prefix",
            prefix,
            "--source",
            "pysrc",
            "--connect",
            endpoint,
        ])
        .args(["--count", &count, "--json", "--timeout", "60"])
        .stdout(Stdio::piped())
        .spawn()
        .expect("python3 (with `pip install iceoryx2==0.10.0 eclipse-zenoh==1.10.2`)");
    let (tx, rx) = mpsc::channel();
    let stdout = py_sub.stdout.take().unwrap();
    std::thread::spawn(move || {
        for line in BufReader::new(stdout).lines().map_while(Result::ok) {
            if tx.send(line).is_err() {
                break;
            }
        }
    });
    let ready = rx
        .recv_timeout(WATCHDOG)
        .expect("python subscriber ready line");
    assert!(ready.starts_with("subscribed to"), "{ready}");

    // Read the iceoryx2 answers while the publisher runs: once it exits, ghnetd drops
    // the source and its heading publisher, and undelivered samples go with it.
    let mut publisher = Command::new("python3")
        .arg(python_dir().join("publish_velocity.py"))
        .args(["--prefix", prefix, "--source", "pysrc"])
        .args(["--count", &count, "--rate", "100", "--first-seq", "1000"])
        .args(ns.iceoryx2_flags())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("python3");
    let mut from_ice: BTreeMap<u64, HeadingEstimate> = BTreeMap::new();
    while from_ice.len() < n as usize {
        let Some(h) = ice.recv_timeout(WATCHDOG).unwrap() else {
            let _ = publisher.kill();
            let out = publisher.wait_with_output().expect("reap");
            panic!(
                "{} of {n} on iceoryx2; publish_velocity.py: {}\nghnetd log:\n{}",
                from_ice.len(),
                String::from_utf8_lossy(&out.stderr),
                daemon.log()
            );
        };
        from_ice.insert(h.seq, h);
    }
    let out = publisher.wait_with_output().expect("reap");
    assert_success(&out, "publish_velocity.py");
    assert_eq!(
        from_ice.keys().copied().collect::<Vec<_>>(),
        (1000..1000 + n).collect::<Vec<_>>()
    );
    let mut from_zenoh = BTreeMap::new();
    while from_zenoh.len() < n as usize {
        let h = zen.recv_timeout(WATCHDOG).unwrap().expect("zenoh heading");
        from_zenoh.insert(h.seq, h.to_le_bytes());
    }
    let ice_bytes: BTreeMap<u64, [u8; 64]> = from_ice
        .iter()
        .map(|(k, h)| (*k, h.to_le_bytes()))
        .collect();
    assert_eq!(from_zenoh, ice_bytes, "Rust Zenoh subscriber");

    let mut python = 0;
    for _ in 0..n {
        let line = rx
            .recv_timeout(WATCHDOG)
            .expect("a heading from the Python subscriber");
        let j: serde_json::Value =
            serde_json::from_str(&line).unwrap_or_else(|e| panic!("{e}: {line}"));
        let seq = j["seq"].as_u64().unwrap();
        let h = from_ice
            .get(&seq)
            .unwrap_or_else(|| panic!("unknown seq {seq}"));
        let ctx = format!("python {line}\nrust {h:?}");
        let hex: String = encode_zenoh(h).iter().map(|b| format!("{b:02x}")).collect();
        assert_eq!(j["payload_hex"].as_str(), Some(hex.as_str()), "{ctx}");
        assert_eq!(j["timestamp_ns"].as_u64(), Some(h.timestamp_ns), "{ctx}");
        assert_eq!(j["status"].as_u64(), Some(u64::from(h.status)), "{ctx}");
        assert_eq!(j["model_id"].as_u64(), Some(u64::from(h.model_id)), "{ctx}");
        assert_eq!(j["model_name"].as_str(), Some(h.model_name_str()), "{ctx}");
        for (key, v) in [
            ("heading_deg", h.heading_deg),
            ("heading_std_deg", h.heading_std_deg),
            ("atan2_deg", h.atan2_deg),
            ("speed", h.speed),
        ] {
            // Python's float is the f32 widened exactly and printed round-trip; NaN
            // is null. serde_json (without float_roundtrip) may be 1 ulp off in f64,
            // which rounding back to f32 removes: compare the f32 values.
            let want = (!v.is_nan()).then_some(v);
            assert_eq!(j[key].as_f64().map(|x| x as f32), want, "{key}: {ctx}");
        }
        python += 1;
    }
    let status = py_sub.wait().expect("reap python subscriber");
    assert!(status.success());
    assert_eq!(python, n);
    daemon.stop();
}
