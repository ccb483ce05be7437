//! End-to-end: the real `ghnetd` binary, real iceoryx2, the public client API.
//!
//! Every test runs in its own iceoryx2 namespace (`TestNamespace`), passes it to the
//! daemon with `--iceoryx2-global-prefix/--iceoryx2-root-path`, and reaps every child
//! (an unreaped zombie keeps its iceoryx2 liveness lock). Waits are bounded by
//! watchdogs, never asserted as performance limits.

use std::fs::File;
use std::path::PathBuf;
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

use ghnet_client::testing::TestNamespace;
use ghnet_client::{
    flags, HeadingStatus, HeadingSubscriber, IpcConfig, VelocityPublisher, VelocitySample,
};

const WATCHDOG: Duration = Duration::from_secs(20);
const CHILD_ENV: &str = "GHNETD_E2E_CHILD_PUBLISHER";

/// Polls `cond` every 10 ms until it holds; panics with `what` after the watchdog.
fn wait_until(what: &str, mut cond: impl FnMut() -> bool) {
    let t0 = Instant::now();
    while !cond() {
        assert!(t0.elapsed() < WATCHDOG, "timed out waiting for {what}");
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// A running ghnetd whose stderr goes to a file; killed and reaped on drop.
struct Daemon {
    child: Option<Child>,
    log: PathBuf,
    _dir: tempfile::TempDir,
}

impl Daemon {
    fn start(ns: &TestNamespace, extra: &[&str]) -> Self {
        let dir = tempfile::tempdir().unwrap();
        let log = dir.path().join("ghnetd.log");
        let child = Command::new(env!("CARGO_BIN_EXE_ghnetd"))
            .args(["--model", TEST_MODEL])
            .args(["--iceoryx2-global-prefix", ns.global_prefix()])
            .arg("--iceoryx2-root-path")
            .arg(ns.root_path())
            .args(["--discovery-interval-ms", "50", "--stats-interval-s", "1"])
            // Any free loopback port: tests run in parallel.
            .args(["--zenoh-listen", "tcp/127.0.0.1:0"])
            .args(extra)
            .env("RUST_LOG", "info")
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(File::create(&log).unwrap())
            .spawn()
            .unwrap();
        Self {
            child: Some(child),
            log,
            _dir: dir,
        }
    }

    fn log(&self) -> String {
        std::fs::read_to_string(&self.log).unwrap_or_default()
    }

    fn wait_for_log(&self, needle: &str) {
        wait_until(&format!("`{needle}` in the ghnetd log"), || {
            self.log().contains(needle)
        });
    }

    /// The next answer, or a panic showing the daemon's log.
    fn answer(&self, headings: &HeadingSubscriber) -> ghnet_client::HeadingEstimate {
        match headings.recv_timeout(WATCHDOG).unwrap() {
            Some(h) => h,
            None => panic!("no answer from ghnetd; log:\n{}", self.log()),
        }
    }

    fn is_running(&mut self) -> bool {
        self.child.as_mut().unwrap().try_wait().unwrap().is_none()
    }

    fn signal(&self, sig: i32) {
        let pid = self.child.as_ref().unwrap().id() as i32;
        assert_eq!(unsafe { libc::kill(pid, sig) }, 0);
    }

    /// Sends SIGTERM and reaps; returns the exit status and how long the exit took.
    fn terminate(mut self) -> (ExitStatus, Duration, String) {
        self.signal(libc::SIGTERM);
        let t0 = Instant::now();
        let mut child = self.child.take().unwrap();
        let status = loop {
            if let Some(s) = child.try_wait().unwrap() {
                break s;
            }
            if t0.elapsed() > WATCHDOG {
                let _ = child.kill();
                let _ = child.wait();
                panic!("ghnetd ignored SIGTERM; log:\n{}", self.log());
            }
            std::thread::sleep(Duration::from_millis(5));
        };
        (status, t0.elapsed(), self.log())
    }

    /// kill -9 and reap.
    fn kill9(mut self) {
        let mut child = self.child.take().unwrap();
        child.kill().unwrap();
        child.wait().unwrap();
    }
}

impl Drop for Daemon {
    fn drop(&mut self) {
        if let Some(mut c) = self.child.take() {
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}

/// The model the daemon runs in these tests: the smaller built-in. The tests check
/// the daemon, not the weights, so they accept `Ok` or `LowSpeed` for valid input.
const TEST_MODEL: &str = "paper-s1";

fn moving_ok(h: &ghnet_client::HeadingEstimate) -> bool {
    matches!(
        h.heading_status(),
        Some(HeadingStatus::Ok | HeadingStatus::LowSpeed)
    )
}

fn sample(seq: u64) -> VelocitySample {
    let mut s = VelocitySample::new(1_000_000 + seq * 100, seq, 5.0, 5.0, 0.0);
    s.speed_accuracy = 0.1;
    s
}

#[test]
fn static_source_every_sample_answered_once_then_clean_sigterm() {
    let ns = TestNamespace::new("static");
    let ipc = ns.ipc();
    let daemon = Daemon::start(&ns, &["--source", "e2e", "--discovery", "false"]);
    let headings = HeadingSubscriber::new(&ipc, "e2e").unwrap();
    let gnss = VelocityPublisher::new(&ipc, "e2e").unwrap();
    wait_until("the daemon's subscriber", || gnss.subscriber_count() >= 1);

    // Ping-pong: each answer echoes its sample.
    let n = 100u64;
    for seq in 0..n {
        let mut s = sample(seq);
        if seq % 10 == 9 {
            s.v_north = f32::NAN; // invalid input is answered, not dropped
        }
        gnss.send(s).unwrap();
        let h = headings.recv_timeout(WATCHDOG).unwrap().expect("answer");
        assert_eq!((h.seq, h.timestamp_ns), (s.seq, s.timestamp_ns));
        if seq % 10 == 9 {
            assert_eq!(h.heading_status(), Some(HeadingStatus::InvalidInput));
            assert!(h.heading_deg.is_nan());
        } else {
            assert!(moving_ok(&h), "seq {seq}: {h:?}");
            assert!((h.atan2_deg - 45.0).abs() < 1e-3);
            assert!((0.0..360.0).contains(&h.heading_deg));
            assert_eq!(h.model_name_str(), TEST_MODEL);
        }
    }

    // A burst (below the subscriber buffer) in one notification: all answered, in order.
    for seq in n..2 * n {
        gnss.publish(sample(seq)).unwrap();
    }
    gnss.notify().unwrap();
    for seq in n..2 * n {
        let h = headings.recv_timeout(WATCHDOG).unwrap().expect("answer");
        assert_eq!(h.seq, seq);
    }
    // Exactly one answer per sample.
    assert!(headings
        .recv_timeout(Duration::from_millis(200))
        .unwrap()
        .is_none());

    // A gap, a duplicate and a timestamp going backwards are counted.
    gnss.send(sample(2 * n + 5)).unwrap(); // 5 missing
    gnss.send(sample(2 * n + 5)).unwrap(); // duplicate
    let mut back = sample(2 * n + 6);
    back.timestamp_ns = 1;
    back.flags = flags::SIMULATED;
    gnss.send(back).unwrap();
    for _ in 0..3 {
        headings.recv_timeout(WATCHDOG).unwrap().expect("answer");
    }

    let (status, took, log) = daemon.terminate();
    eprintln!("ghnetd exited {status:?} {took:?} after SIGTERM");
    assert!(status.success(), "{status:?}\n{log}");
    assert!(log.contains("source added"), "{log}");
    assert!(log.contains("ghnetd stopped"), "{log}");
    // Final stats line: 203 received, 203 answered, 10 NaN + 1 backwards invalid.
    let stats = log
        .lines()
        .rfind(|l| l.contains(" stats") && l.contains("source=e2e"))
        .unwrap_or_else(|| panic!("no stats line:\n{log}"))
        .to_owned();
    for kv in [
        "received=203",
        "answered=203",
        "invalid=11",
        "gaps=5",
        "duplicates=1",
        "backwards=1",
    ] {
        assert!(stats.contains(kv), "{kv} missing in {stats}");
    }
}

/// Not a test on its own: the body of the child publisher process spawned below.
#[test]
#[ignore = "spawned as a child process by discovered_source_survives_publisher_kill9"]
fn child_publisher() {
    let Ok(spec) = std::env::var(CHILD_ENV) else {
        return;
    };
    let (prefix, root) = spec.split_once('|').unwrap();
    let ipc = IpcConfig::isolated(prefix, root).unwrap();
    let gnss = VelocityPublisher::new(&ipc, "disc").unwrap();
    for seq in 0.. {
        gnss.send(sample(seq)).unwrap();
        std::thread::sleep(Duration::from_millis(10));
    }
}

fn spawn_child_publisher(ns: &TestNamespace) -> Child {
    Command::new(std::env::current_exe().unwrap())
        .args(["--exact", "child_publisher", "--ignored", "--nocapture"])
        .env(
            CHILD_ENV,
            format!("{}|{}", ns.global_prefix(), ns.root_path().display()),
        )
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap()
}

#[test]
fn discovered_source_survives_publisher_kill9() {
    let ns = TestNamespace::new("disc");
    let ipc = ns.ipc();
    let mut daemon = Daemon::start(&ns, &[]);
    let headings = HeadingSubscriber::new(&ipc, "disc").unwrap();

    // A publisher in another process appears: discovered and served without restart.
    let mut child = spawn_child_publisher(&ns);
    let h = daemon.answer(&headings);
    assert!(moving_ok(&h), "{h:?}");
    daemon.wait_for_log("source added");

    // kill -9 the publisher (and reap it, so its liveness lock is released).
    child.kill().unwrap();
    child.wait().unwrap();
    daemon.wait_for_log("source removed");
    assert!(daemon.is_running(), "ghnetd must survive a dead publisher");

    // A new publisher under the same name is served again.
    let gnss = VelocityPublisher::new(&ipc, "disc").unwrap();
    wait_until("rediscovery", || gnss.subscriber_count() >= 1);
    while headings.try_recv().unwrap().is_some() {} // answers still in flight from the child
    gnss.send(sample(1_000)).unwrap();
    assert_eq!(daemon.answer(&headings).seq, 1_000);

    let (status, _, log) = daemon.terminate();
    assert!(status.success(), "{status:?}\n{log}");
    assert_eq!(log.matches("source added").count(), 2, "{log}");
}

#[test]
fn restart_after_daemon_kill9_needs_no_cleanup() {
    let ns = TestNamespace::new("restart");
    let ipc = ns.ipc();
    let gnss = VelocityPublisher::new(&ipc, "r").unwrap();
    let headings = HeadingSubscriber::new(&ipc, "r").unwrap();

    let first = Daemon::start(&ns, &["--source", "r"]);
    wait_until("first daemon", || gnss.subscriber_count() >= 1);
    gnss.send(sample(0)).unwrap();
    assert_eq!(first.answer(&headings).seq, 0);
    first.kill9();

    // The dead daemon's subscriber still counts until someone cleans up; the new
    // daemon does that on start, so the count settles at exactly one.
    let second = Daemon::start(&ns, &["--source", "r"]);
    second.wait_for_log("ghnetd starting");
    wait_until("second daemon alone", || gnss.subscriber_count() == 1);
    gnss.send(sample(1)).unwrap();
    assert_eq!(second.answer(&headings).seq, 1);
    let (status, _, log) = second.terminate();
    assert!(status.success(), "{log}");
}

#[test]
fn bad_config_is_one_line_and_nonzero() {
    let ns = TestNamespace::new("badcfg");
    let out = Command::new(env!("CARGO_BIN_EXE_ghnetd"))
        .args(["--model", "/nonexistent/model.safetensors"])
        .args(["--iceoryx2-global-prefix", ns.global_prefix()])
        .arg("--iceoryx2-root-path")
        .arg(ns.root_path())
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    let last = err.lines().last().unwrap_or_default();
    assert!(last.starts_with("error: model.name"), "{err}");
    assert!(last.contains("/nonexistent/model.safetensors"), "{err}");

    let out = Command::new(env!("CARGO_BIN_EXE_ghnetd"))
        .args(["--source", "bad/name"])
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(err.starts_with("error: sources.static"), "{err}");
}

#[test]
fn print_config_prints_effective_toml() {
    let out = Command::new(env!("CARGO_BIN_EXE_ghnetd"))
        .args(["--print-config", "--source", "gnss0", "--max-speed", "50"])
        .output()
        .unwrap();
    assert!(out.status.success());
    let text = String::from_utf8(out.stdout).unwrap();
    let cfg = ghnetd::Config::from_toml(&text).unwrap();
    assert_eq!(cfg.sources.static_sources, vec!["gnss0"]);
    assert_eq!(cfg.model.max_speed, 50.0);
}
