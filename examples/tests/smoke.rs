//! The README's main command works: `demo` shows headings flowing and shuts down
//! cleanly (in a private namespace, so it runs next to a real ghnetd and in parallel).

use std::process::{Command, Stdio};

#[test]
fn demo_answers_every_sample_and_exits_zero() {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_demo"));
    cmd.args(["--isolated", "--duration", "1", "--rate", "20"])
        .env("RUST_LOG", "warn")
        .stdin(Stdio::null());
    // While the default model's embedded weights are being retrained, use the model
    // the cross-process tests fall back to.
    if let Some(name) = ghnet_testkit::test_model().flag {
        cmd.args(["--model", name]);
    }
    let out = cmd.output().expect("run demo");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{:?}\n{stdout}\n{stderr}", out.status);
    assert!(stdout.contains("status"), "table header:\n{stdout}");
    let summary = stdout.lines().last().unwrap_or_default();
    // "demo: sent N, answered N (ghnetd: received N, invalid N)"
    let numbers: Vec<u64> = summary
        .split(|c: char| !c.is_ascii_digit())
        .filter_map(|w| w.parse().ok())
        .take(4)
        .collect();
    assert!(summary.starts_with("demo: sent"), "{stdout}");
    let (sent, answered, received, invalid) = (numbers[0], numbers[1], numbers[2], numbers[3]);
    assert!(sent >= 10, "{summary}");
    assert_eq!((answered, received, invalid), (sent, sent, 0), "{summary}");
    // One table row per simulated second (the first epoch of each), and the scores.
    let rows = stdout
        .lines()
        .filter(|l| l.trim_start().starts_with(|c: char| c.is_ascii_digit()))
        .count();
    assert!(rows >= 1, "{stdout}");
    assert!(stdout.contains("mean |error|"), "{stdout}");
}
