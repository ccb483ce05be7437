//! The ROS 2 bridge against real ROS 2: a real ghnetd, the `ghnet-ros2` binary on
//! DDS, and an rclpy node (`client/ros2/tests/rclpy_listener.py`, the ROS 2 wheels from
//! PyPI with `rmw_fastrtps_cpp`) that prints every message it gets. Every field of
//! every Imu is checked against ghnetd's own answers on iceoryx2 (read here by a
//! subscriber of this test), the status rules included, and `/diagnostics` against the
//! counts.
//!
//! DDS discovery is multicast: the bridge and the rclpy node run in a network
//! namespace of their own with multicast on its loopback, so no packet leaves it.
//! iceoryx2 is shared memory, which network namespaces do not separate: ghnetd and
//! this test stay in the machine's namespace.
//!
//! Needs root, `ip`, and `python3` with `ros-rclpy ros-rmw-fastrtps-cpp
//! ros-sensor-msgs ros-diagnostic-msgs`: ignored unless asked for.

use std::io::{BufRead, BufReader};
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use ghnet_client::{
    flags, HeadingEstimate, HeadingStatus, HeadingSubscriber, VelocityPublisher, VelocitySample,
};
use ghnet_testkit::{find_binary, now_ns, Ghnetd, NetNamespace, TestNamespace, WATCHDOG};
use serde_json::Value;

const DOMAIN_ID: &str = "17";
const FRAME_ID: &str = "gnss_antenna";
/// Source names that are not ROS names, and the topics they map to.
const FRONT: (&str, &str) = ("gnss-front", "/ghnet/gnss_front/heading");
const SECOND: (&str, &str) = ("2nd-rx", "/ghnet/s_2nd_rx/heading");

/// A child process that dies with the test thread and is killed and reaped on drop.
struct Proc(Child);

impl Proc {
    fn spawn(cmd: &mut Command) -> Self {
        // SAFETY: only an async-signal-safe syscall between fork and exec.
        unsafe {
            cmd.pre_exec(|| {
                libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGKILL);
                Ok(())
            });
        }
        Proc(cmd.spawn().unwrap_or_else(|e| panic!("{cmd:?}: {e}")))
    }

    /// SIGTERM, then the exit status (killed after the watchdog).
    fn terminate(&mut self) -> std::process::ExitStatus {
        // SAFETY: kill(2) on our own child, not yet reaped.
        unsafe { libc::kill(self.0.id() as libc::pid_t, libc::SIGTERM) };
        let t0 = Instant::now();
        loop {
            if let Some(s) = self.0.try_wait().expect("try_wait") {
                return s;
            }
            assert!(t0.elapsed() < WATCHDOG, "no exit after SIGTERM");
            std::thread::sleep(Duration::from_millis(10));
        }
    }
}

impl Drop for Proc {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// The lines a child prints, from a reader thread.
fn lines_of(child: &mut Child) -> mpsc::Receiver<String> {
    let stdout = child.stdout.take().expect("piped stdout");
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stdout).lines().map_while(Result::ok) {
            if tx.send(line).is_err() {
                break;
            }
        }
    });
    rx
}

fn listener_script() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../client/ros2/tests/rclpy_listener.py")
}

/// Everything the rclpy node printed, by topic.
#[derive(Default)]
struct Heard {
    imu: Vec<(String, Value)>,
    diagnostics: Vec<Value>,
}

impl Heard {
    fn take(&mut self, lines: &mpsc::Receiver<String>, wait: Duration) {
        let mut next = lines.recv_timeout(wait).ok();
        while let Some(line) = next {
            let v: Value = serde_json::from_str(&line).unwrap_or_else(|e| panic!("{line}: {e}"));
            let topic = v["topic"].as_str().expect("topic").to_owned();
            if topic == "/diagnostics" {
                self.diagnostics.push(v);
            } else {
                self.imu.push((topic, v));
            }
            next = lines.try_recv().ok();
        }
    }

    fn on(&self, topic: &str) -> Vec<&Value> {
        self.imu
            .iter()
            .filter(|(t, _)| t == topic)
            .map(|(_, v)| v)
            .collect()
    }
}

/// A sample at `t_s` seconds after `t0`: `speed` m/s towards `course_deg`, speed
/// accuracy 0.1 m/s.
fn sample(t0: u64, seq: u64, t_s: f64, speed: f32, course_deg: f32) -> VelocitySample {
    let (s, c) = course_deg.to_radians().sin_cos();
    let mut v = VelocitySample::new(t0 + (t_s * 1e9) as u64, seq, speed * c, speed * s, 0.0);
    v.speed_accuracy = 0.1;
    v
}

/// One source's ends and the answers ghnetd gave it.
struct Feed {
    gnss: VelocityPublisher,
    headings: HeadingSubscriber,
    answers: Vec<HeadingEstimate>,
    seq: u64,
    t0: u64,
}

impl Feed {
    fn new(daemon: &Ghnetd, source: &str) -> Self {
        let (gnss, headings) = daemon.ends(source);
        Feed {
            gnss,
            headings,
            answers: Vec::new(),
            seq: 0,
            t0: now_ns(),
        }
    }

    /// Sends the next sample (1 s of sample time after the last) and returns ghnetd's
    /// answer. A sample nobody answers within a second (a restarted ghnetd that was
    /// not subscribed yet: the dead one's subscriber counts until it is cleaned up)
    /// is followed by the next; every message ghnetd sends meanwhile is kept.
    fn send(&mut self, speed: f32, course_deg: f32, invalid: bool) -> HeadingEstimate {
        let t0 = Instant::now();
        loop {
            let mut s = sample(self.t0, self.seq, self.seq as f64, speed, course_deg);
            if invalid {
                s.flags |= flags::INVALID;
            }
            self.seq += 1;
            self.gnss.send(s).unwrap();
            let deadline = Instant::now() + Duration::from_secs(1);
            let left = || deadline.saturating_duration_since(Instant::now());
            while let Some(h) = self.headings.recv_timeout(left()).unwrap() {
                assert!(h.seq <= s.seq, "answers in order: {h:?} after {s:?}");
                self.answers.push(h);
                if h.seq == s.seq && h.heading_status() != Some(HeadingStatus::Stale) {
                    return h;
                }
            }
            assert!(t0.elapsed() < WATCHDOG, "watchdog: no answer to {s:?}");
        }
    }

    /// Waits for ghnetd's `Stale` message after the source went quiet.
    fn await_stale(&mut self) {
        let h = self
            .headings
            .recv_timeout(WATCHDOG)
            .unwrap()
            .expect("Stale");
        assert_eq!(h.heading_status(), Some(HeadingStatus::Stale), "{h:?}");
        self.answers.push(h);
    }
}

/// Sends with `send` every 50 ms until the rclpy node heard something on `topic` (DDS
/// matching takes a moment, and volatile topics keep nothing for late readers).
fn warm_up(heard: &mut Heard, lines: &mpsc::Receiver<String>, topic: &str, mut send: impl FnMut()) {
    let t0 = Instant::now();
    while heard.on(topic).is_empty() {
        assert!(
            t0.elapsed() < WATCHDOG,
            "watchdog: nothing heard on {topic}"
        );
        send();
        heard.take(lines, Duration::from_millis(50));
    }
}

fn floats(v: &Value, n: usize) -> Vec<f64> {
    let a: Vec<f64> = v
        .as_array()
        .expect("array")
        .iter()
        .map(|x| x.as_f64().expect("number"))
        .collect();
    assert_eq!(a.len(), n, "{v}");
    a
}

/// Checks one Imu against the answer it relays. `first_of_stop`: the answer is the
/// first `Held` of a stop (the only one of the stop a filter should fuse).
fn check_imu(h: &HeadingEstimate, m: &Value, first_of_stop: bool) {
    let ctx = format!("{h:?} → {m}");
    let stamp = [
        h.timestamp_ns / 1_000_000_000,
        h.timestamp_ns % 1_000_000_000,
    ];
    assert_eq!(m["stamp"], serde_json::json!(stamp), "{ctx}");
    assert_eq!(m["frame_id"], FRAME_ID, "{ctx}");
    let q = floats(&m["orientation"], 4);
    let cov = floats(&m["orientation_covariance"], 9);
    let status = h.heading_status();
    let with_heading = matches!(
        status,
        Some(HeadingStatus::Ok | HeadingStatus::LowSpeed | HeadingStatus::Held)
    );
    if with_heading {
        // REP-103: ENU yaw = 90° − heading; q = (0, 0, sin(yaw/2), cos(yaw/2)) up to sign.
        let yaw = (90.0 - f64::from(h.heading_deg)).to_radians();
        let (s, c) = (yaw / 2.0).sin_cos();
        assert_eq!((q[0], q[1]), (0.0, 0.0), "{ctx}");
        assert!(((q[2] * s + q[3] * c).abs() - 1.0).abs() < 1e-12, "{ctx}");
        let var = f64::from(h.heading_std_deg).to_radians().powi(2);
        assert!((cov[8] - var).abs() <= 1e-12 * var, "{ctx}");
        assert!(cov[4] >= 1e3, "{ctx}");
        let fused = status != Some(HeadingStatus::Held) || first_of_stop;
        if fused {
            assert!(cov[0] >= 1e3, "{ctx}");
        } else {
            assert_eq!(cov[0], -1.0, "{ctx}");
        }
        for i in [1, 2, 3, 5, 6, 7] {
            assert_eq!(cov[i], 0.0, "{ctx}");
        }
    } else {
        assert_eq!(q, [0.0, 0.0, 0.0, 1.0], "{ctx}");
        assert_eq!(cov[0], -1.0, "{ctx}");
    }
    for (value, covariance) in [
        ("angular_velocity", "angular_velocity_covariance"),
        ("linear_acceleration", "linear_acceleration_covariance"),
    ] {
        assert_eq!(floats(&m[value], 3), [0.0; 3], "{ctx}");
        assert_eq!(floats(&m[covariance], 9)[0], -1.0, "{ctx}");
    }
}

/// Checks what rclpy heard on `topic` against `answers`: from the first message heard
/// on, every answer, in order, each field.
fn check_topic(heard: &Heard, topic: &str, answers: &[HeadingEstimate]) {
    let got = heard.on(topic);
    let skip = answers.len() - got.len();
    let mut in_stop = false;
    for (i, h) in answers.iter().enumerate() {
        let st = h.heading_status();
        let first_of_stop = st == Some(HeadingStatus::Held) && !in_stop;
        match st {
            Some(HeadingStatus::Held) => in_stop = true,
            Some(HeadingStatus::Stale) => {}
            _ => in_stop = false,
        }
        if i >= skip {
            check_imu(h, got[i - skip], first_of_stop);
        }
    }
}

/// The status of `source` in a `/diagnostics` message, if there.
fn diag_of<'a>(d: &'a Value, source: &str) -> Option<&'a Value> {
    let name = format!("ghnet: {source}");
    d["status"]
        .as_array()?
        .iter()
        .find(|s| s["name"] == name.as_str())
}

#[test]
#[ignore = "needs root, ip, and python3 with ros-rclpy ros-rmw-fastrtps-cpp ros-sensor-msgs ros-diagnostic-msgs"]
fn rclpy_hears_every_answer_as_imu_with_the_status_rules_and_diagnostics() {
    let ns = TestNamespace::new("ros2");
    let host = NetNamespace::create("ros2").expect("network namespace");
    host.enable_loopback_multicast().expect("multicast on lo");
    let daemon = Ghnetd::builder(&ns)
        .source(FRONT.0)
        .source(SECOND.0)
        .discovery(false)
        .model("ghnet-temporal")
        .arg("--stale-after-ms=300")
        .start();
    let mut front = Feed::new(&daemon, FRONT.0);
    let mut second = Feed::new(&daemon, SECOND.0);

    let log = ns.scratch_dir("ros2").join("bridge.log");
    let mut bridge = spawn_bridge(
        &ns,
        &host,
        &log,
        &[
            "--source",
            FRONT.0,
            "--source",
            SECOND.0,
            "--domain-id",
            DOMAIN_ID,
            "--frame-id",
            FRAME_ID,
        ],
    );
    let (_listener, lines) = spawn_listener(
        &host,
        DOMAIN_ID,
        &["--imu", FRONT.1, "--imu", SECOND.1, "--diagnostics"],
        &log,
    );
    let mut heard = Heard::default();

    // A car drives east until rclpy hears it, then 10 s more (Ok, LowSpeed at first),
    // stops (Held), drives south, sends an invalid fix, stops again, falls silent
    // (Stale).
    warm_up(&mut heard, &lines, FRONT.1, || {
        front.send(8.0, 90.0, false);
    });
    for _ in 0..10 {
        front.send(8.0, 90.0, false);
    }
    for _ in 0..4 {
        front.send(0.01, 0.0, false);
    }
    for _ in 0..6 {
        front.send(8.0, 180.0, false);
    }
    front.send(8.0, 180.0, true);
    for _ in 0..3 {
        front.send(0.01, 0.0, false);
    }
    // A receiver that never moves: Stationary.
    warm_up(&mut heard, &lines, SECOND.1, || {
        second.send(0.0, 0.0, false);
    });
    for _ in 0..3 {
        second.send(0.0, 0.0, false);
    }
    front.await_stale();
    second.await_stale();
    let statuses: Vec<_> = front.answers.iter().map(|h| h.heading_status()).collect();
    for want in [
        HeadingStatus::Ok,
        HeadingStatus::Held,
        HeadingStatus::InvalidInput,
    ] {
        assert!(statuses.contains(&Some(want)), "{want:?} in {statuses:?}");
    }
    let stationary = second
        .answers
        .iter()
        .filter(|h| h.heading_status() == Some(HeadingStatus::Stationary));
    assert!(stationary.count() >= 4);

    // Everything arrives (reliable), then diagnostics show the final counts.
    let t0 = Instant::now();
    let done = |heard: &Heard| {
        heard.on(FRONT.1).last().map(|m| m["stamp"].clone())
            == front.answers.last().map(|h| {
                serde_json::json!([
                    h.timestamp_ns / 1_000_000_000,
                    h.timestamp_ns % 1_000_000_000
                ])
            })
            && heard.on(FRONT.1).len() > front.answers.len() - 5
            && heard.on(SECOND.1).len() >= 5
            && heard.diagnostics.last().is_some_and(|d| {
                [(FRONT.0, &front), (SECOND.0, &second)]
                    .iter()
                    .all(|(s, f)| {
                        diag_of(d, s).is_some_and(|x| {
                            x["values"]["relayed"] == f.answers.len().to_string().as_str()
                        })
                    })
            })
    };
    while !done(&heard) {
        assert!(
            t0.elapsed() < WATCHDOG,
            "watchdog: rclpy heard {} Imu, {} diagnostics; bridge log:\n{}",
            heard.imu.len(),
            heard.diagnostics.len(),
            std::fs::read_to_string(&log).unwrap_or_default()
        );
        heard.take(&lines, Duration::from_millis(100));
    }
    check_topic(&heard, FRONT.1, &front.answers);
    check_topic(&heard, SECOND.1, &second.answers);

    let last = heard.diagnostics.last().unwrap();
    for (source, feed) in [(FRONT.0, &front), (SECOND.0, &second)] {
        let d = diag_of(last, source).unwrap_or_else(|| panic!("{source} in {last}"));
        assert_eq!(d["level"], 3, "STALE after Stale: {d}");
        assert_eq!(d["hardware_id"], source, "{d}");
        let v = &d["values"];
        assert_eq!(v["status"], "stale", "{d}");
        assert_eq!(v["send_failures"], "0", "{d}");
        assert_eq!(v["missed"], "0", "{d}");
        assert_eq!(v["seq"], (feed.seq - 1).to_string().as_str(), "{d}");
        for key in ["heading_deg", "heading_std_deg"] {
            assert!(v[key].is_string(), "{key} in {d}");
        }
    }
    // The levels seen along the way: OK while driving, WARN held, ERROR invalid show up
    // only when a second boundary falls on them; every message names both sources.
    for d in &heard.diagnostics {
        assert!(
            diag_of(d, FRONT.0).is_some() && diag_of(d, SECOND.0).is_some(),
            "{d}"
        );
    }

    let status = bridge.terminate();
    let text = std::fs::read_to_string(&log).unwrap();
    assert!(status.success(), "{status}: {text}");
    assert!(text.contains("summary"), "{text}");
}

fn zenoh_script() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../client/ros2/tests/zenoh_rosbags.py")
}

/// `bytes` from hex.
fn unhex(s: &str) -> Vec<u8> {
    (0..s.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&s[i..i + 2], 16).expect("hex"))
        .collect()
}

/// Waits until `log` contains `needle`.
fn wait_for_log(log: &std::path::Path, needle: &str) {
    let t0 = Instant::now();
    loop {
        let text = std::fs::read_to_string(log).unwrap_or_default();
        if text.contains(needle) {
            return;
        }
        assert!(
            t0.elapsed() < WATCHDOG,
            "watchdog: `{needle}` not in the log:\n{text}"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

const IMU_HASH: &str = "RIHS01_7d9a00ff131080897a5ec7e26e315954b8eae3353c3f995c55faf71574000b5b";
const DIAG_HASH: &str = "RIHS01_5a8a36efb05fb25070fa0fb3810290c0e6cd4862b54a8fb975a1ee8dc55a333e";

#[test]
#[ignore = "needs python3 with eclipse-zenoh==1.10.2 and rosbags"]
fn rmw_zenoh_wire_is_what_rosbags_reads_and_a_late_router_is_waited_for() {
    let ns = TestNamespace::new("ros2z");
    // No Stale message: every heading here answers a sample.
    let daemon = Ghnetd::builder(&ns)
        .source("gnss-0")
        .discovery(false)
        .arg("--stale-after-ms=0")
        .start();
    let mut feed = Feed::new(&daemon, "gnss-0");
    let router_at = format!("tcp/127.0.0.1:{}", ghnet_testkit::free_tcp_port());
    let log = ns.scratch_dir("ros2z").join("bridge.log");
    let bin = find_binary("ghnet-ros2").expect("ghnet-ros2 is built by cargo test --workspace");
    let t_start = now_ns() as i64;
    // The bridge first, with no router there: it keeps running and says so.
    let mut bridge = Proc::spawn(
        Command::new(bin)
            .args([
                "--rmw",
                "zenoh",
                "--zenoh-router",
                &router_at,
                "--domain-id",
                "4",
            ])
            .args(["--source", "gnss-0", "--frame-id", FRAME_ID])
            .args(ns.iceoryx2_flags())
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(std::fs::File::create(&log).unwrap()),
    );
    wait_for_log(&log, "no Zenoh router connected yet");
    wait_for_log(&log, "ghnet-ros2 started"); // subscribed to the heading service
    for _ in 0..3 {
        feed.send(8.0, 45.0, false);
    }
    let _router = ghnet_testkit::ChildRouter::spawn(&[], &[&router_at]);
    wait_for_log(&log, "Zenoh router reached");
    let mut reader = Proc::spawn(
        Command::new("python3")
            .arg(zenoh_script())
            .args([&router_at, "4"])
            .stdin(Stdio::piped())
            .stdout(Stdio::piped()),
    );
    let lines = lines_of(&mut reader.0);
    assert_eq!(lines.recv_timeout(WATCHDOG).as_deref(), Ok("ready"));
    let imu_key = format!("4/ghnet/gnss_0/heading/sensor_msgs::msg::dds_::Imu_/{IMU_HASH}");
    let diag_key =
        format!("4/diagnostics/diagnostic_msgs::msg::dds_::DiagnosticArray_/{DIAG_HASH}");
    let (mut imu, mut diag) = (Vec::<Value>::new(), Vec::<Value>::new());
    let take = |wait: Duration, imu: &mut Vec<Value>, diag: &mut Vec<Value>| {
        let mut next = lines.recv_timeout(wait).ok();
        while let Some(line) = next {
            let v: Value = serde_json::from_str(&line).unwrap_or_else(|e| panic!("{line}: {e}"));
            // The hash rosbags computes from the definitions is the one in the key.
            let key = v["key"].as_str().expect("key");
            assert!(key.ends_with(v["rihs01"].as_str().unwrap()), "{v}");
            assert_eq!(v["cdr_header"], "00010000", "{v}");
            assert_eq!(v["same_bytes"], true, "rosbags writes other bytes: {v}");
            match key {
                k if k == imu_key => imu.push(v),
                k if k == diag_key => diag.push(v),
                other => panic!("unexpected key {other}"),
            }
            next = lines.try_recv().ok();
        }
    };
    let t0 = Instant::now();
    while imu.is_empty() {
        assert!(t0.elapsed() < WATCHDOG, "watchdog: no Imu over Zenoh");
        feed.send(8.0, 45.0, false);
        take(Duration::from_millis(50), &mut imu, &mut diag);
    }
    for _ in 0..10 {
        feed.send(8.0, 300.0, false);
    }
    let sent = feed.answers.len();
    let t0 = Instant::now();
    let relayed_all = |diag: &[Value]| {
        diag.last().is_some_and(|d| {
            diag_of(&d["msg"], "gnss-0")
                .is_some_and(|s| s["values"]["relayed"] == sent.to_string().as_str())
        })
    };
    let last_stamp = {
        let h = feed.answers[sent - 1];
        serde_json::json!([
            h.timestamp_ns / 1_000_000_000,
            h.timestamp_ns % 1_000_000_000
        ])
    };
    while imu.last().map(|v| &v["msg"]["stamp"]) != Some(&last_stamp) || !relayed_all(&diag) {
        assert!(
            t0.elapsed() < WATCHDOG,
            "watchdog: {} Imu (last {:?}, want {last_stamp}), {} diagnostics (last {:?}), {sent} sent; bridge log:\n{}",
            imu.len(),
            imu.last().map(|v| &v["msg"]["stamp"]),
            diag.len(),
            diag.last().map(|d| &d["msg"]),
            std::fs::read_to_string(&log).unwrap_or_default()
        );
        take(Duration::from_millis(100), &mut imu, &mut diag);
    }
    let t_end = now_ns() as i64;

    // Attachment: consecutive sequence numbers per publisher, the publish time, a
    // length byte and one id per publisher. Every Imu is the answer of its stamp.
    let gid = unhex(imu[0]["attachment"].as_str().unwrap())[17..].to_vec();
    let index_of = |v: &Value| {
        let stamp = &v["msg"]["stamp"];
        let stamp_of = |h: &HeadingEstimate| {
            serde_json::json!([
                h.timestamp_ns / 1_000_000_000,
                h.timestamp_ns % 1_000_000_000
            ])
        };
        feed.answers
            .iter()
            .position(|h| &stamp_of(h) == stamp)
            .unwrap_or_else(|| panic!("no answer for {v}"))
    };
    let (first_seq, first_index) = (attachment_seq(&imu[0]), index_of(&imu[0]));
    assert!(first_seq >= 1);
    for v in &imu {
        let a = unhex(v["attachment"].as_str().unwrap());
        assert_eq!(a.len(), 33, "{v}");
        let i = index_of(v);
        assert_eq!(
            attachment_seq(v) - first_seq,
            (i - first_index) as i64,
            "consecutive: {v}"
        );
        let time = i64::from_le_bytes(a[8..16].try_into().unwrap());
        assert!(
            (t_start..=t_end).contains(&time),
            "{time} in {t_start}..{t_end}"
        );
        assert_eq!((a[16], &a[17..]), (16, gid.as_slice()), "{v}");
        check_imu(&feed.answers[i], &v["msg"], false);
    }
    assert_eq!(
        index_of(imu.last().unwrap()),
        sent - 1,
        "the last answer arrived"
    );
    assert_eq!(
        imu.len(),
        sent - first_index,
        "every Imu from the first heard on"
    );
    let diag_gid = unhex(diag[0]["attachment"].as_str().unwrap())[17..].to_vec();
    assert_ne!(diag_gid, gid, "one id per publisher");
    let d = diag_of(&diag.last().unwrap()["msg"], "gnss-0")
        .unwrap()
        .clone();
    let failures: u64 = d["values"]["send_failures"]
        .as_str()
        .unwrap()
        .parse()
        .unwrap();
    assert!(
        failures >= 3,
        "answers put before the router came are counted: {d}"
    );

    // Liveliness tokens: the node and its publishers, as rmw_zenoh declares them.
    use std::io::Write;
    writeln!(reader.0.stdin.as_mut().unwrap(), "tokens").unwrap();
    let tokens: Value = loop {
        let line = lines.recv_timeout(WATCHDOG).expect("tokens");
        let v: Value = serde_json::from_str(&line).unwrap();
        if v.get("tokens").is_some() {
            break v;
        }
    };
    let tokens: Vec<&str> = tokens["tokens"]
        .as_array()
        .unwrap()
        .iter()
        .map(|t| t.as_str().unwrap())
        .collect();
    let has = |suffix: &str| {
        tokens
            .iter()
            .any(|t| t.starts_with("@ros2_lv/4/") && t.ends_with(suffix))
    };
    assert!(has("/0/0/NN/%/%/ghnet"), "{tokens:?}");
    assert!(has(&format!("/MP/%/%/ghnet/%ghnet%gnss_0%heading/sensor_msgs::msg::dds_::Imu_/{IMU_HASH}/::,10:,:,:,,")), "{tokens:?}");
    assert!(has(&format!("/MP/%/%/ghnet/%diagnostics/diagnostic_msgs::msg::dds_::DiagnosticArray_/{DIAG_HASH}/::,10:,:,:,,")), "{tokens:?}");

    let status = bridge.terminate();
    let text = std::fs::read_to_string(&log).unwrap();
    assert!(status.success(), "{status}: {text}");
}

/// The sequence number in a sample's attachment.
fn attachment_seq(v: &Value) -> i64 {
    let a = unhex(v["attachment"].as_str().expect("attachment"));
    i64::from_le_bytes(a[..8].try_into().expect("33 bytes"))
}

/// Starts `ghnet-ros2` in `host` with `args` and the namespace's iceoryx2 flags; its
/// log goes to `log`.
fn spawn_bridge(
    ns: &TestNamespace,
    host: &NetNamespace,
    log: &std::path::Path,
    args: &[&str],
) -> Proc {
    let bin = find_binary("ghnet-ros2").expect("ghnet-ros2 is built by cargo test --workspace");
    Proc::spawn(
        Command::new("ip")
            .args(["netns", "exec", host.name()])
            .arg(bin)
            .args(args)
            .args(ns.iceoryx2_flags())
            .env_remove("ROS_DOMAIN_ID")
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(std::fs::File::create(log).unwrap()),
    )
}

/// Starts the rclpy listener in `host` on `domain` with `args`; its lines after
/// `ready`. If it is not ready in time, the bridge's log (`bridge_log`) says why.
fn spawn_listener(
    host: &NetNamespace,
    domain: &str,
    args: &[&str],
    bridge_log: &Path,
) -> (Proc, mpsc::Receiver<String>) {
    let mut p = Proc::spawn(
        Command::new("ip")
            .args(["netns", "exec", host.name(), "python3"])
            .arg(listener_script())
            .args(args)
            .env("ROS_DOMAIN_ID", domain)
            .env("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp")
            .stdin(Stdio::null())
            .stdout(Stdio::piped()),
    );
    let lines = lines_of(&mut p.0);
    let ready = lines.recv_timeout(WATCHDOG).expect("rclpy listener ready");
    let why = || std::fs::read_to_string(bridge_log).unwrap_or_default();
    assert_eq!(ready, "ready", "{}", why());
    (p, lines)
}

/// Reads until a `/diagnostics` message satisfies `cond`; returns it.
fn await_diagnostics(
    heard: &mut Heard,
    lines: &mpsc::Receiver<String>,
    what: &str,
    cond: impl Fn(&Value) -> bool,
) -> Value {
    let t0 = Instant::now();
    loop {
        if let Some(d) = heard.diagnostics.iter().rev().find(|d| cond(d)) {
            return d.clone();
        }
        assert!(
            t0.elapsed() < WATCHDOG,
            "watchdog: {what}; last: {:?}",
            heard.diagnostics.last()
        );
        heard.take(lines, Duration::from_millis(100));
    }
}

/// Reads until the last Imu on `topic` is the answer `h`.
fn await_imu(heard: &mut Heard, lines: &mpsc::Receiver<String>, topic: &str, h: &HeadingEstimate) {
    let stamp = serde_json::json!([
        h.timestamp_ns / 1_000_000_000,
        h.timestamp_ns % 1_000_000_000
    ]);
    let t0 = Instant::now();
    while heard.on(topic).last().map(|m| &m["stamp"]) != Some(&stamp) {
        assert!(
            t0.elapsed() < WATCHDOG,
            "watchdog: {h:?} not heard on {topic}"
        );
        heard.take(lines, Duration::from_millis(100));
    }
}

#[test]
#[ignore = "needs root, ip, and python3 with ros-rclpy ros-rmw-fastrtps-cpp ros-sensor-msgs ros-diagnostic-msgs"]
fn a_bridge_before_ghnetd_finds_the_source_survives_a_kill_and_a_stuck_reader() {
    const TOPIC: &str = "/ghnet/late_src/heading";
    let ns = TestNamespace::new("ros2f");
    let host = NetNamespace::create("ros2f").expect("network namespace");
    host.enable_loopback_multicast().expect("multicast on lo");
    // No ghnetd, no --source: the bridge runs, and finds the source once served.
    let log = ns.scratch_dir("ros2f").join("bridge.log");
    let mut bridge = spawn_bridge(
        &ns,
        &host,
        &log,
        &["--domain-id", "19", "--frame-id", FRAME_ID],
    );
    let (_listener, lines) = spawn_listener(
        &host,
        "19",
        &[
            "--imu",
            TOPIC,
            "--diagnostics",
            "--wait-for",
            "/diagnostics",
        ],
        &log,
    );
    // A reader that never reads: it must slow nobody.
    let (_stuck, _) = spawn_listener(
        &host,
        "19",
        &["--imu", TOPIC, "--stuck", "--wait-for", "/diagnostics"],
        &log,
    );
    let mut heard = Heard::default();
    let empty = await_diagnostics(&mut heard, &lines, "diagnostics without ghnetd", |_| true);
    assert_eq!(empty["status"], serde_json::json!([]), "{empty}");

    let daemon = Ghnetd::builder(&ns).arg("--stale-after-ms=0").start();
    let mut feed = Feed::new(&daemon, "late-src");
    warm_up(&mut heard, &lines, TOPIC, || {
        feed.send(8.0, 30.0, false);
    });
    for _ in 0..10 {
        feed.send(8.0, 30.0, false);
    }
    await_imu(&mut heard, &lines, TOPIC, feed.answers.last().unwrap());

    // ghnetd dies without a word: the source goes STALE in /diagnostics.
    daemon.kill9();
    let stale = await_diagnostics(&mut heard, &lines, "late-src STALE after kill -9", |d| {
        diag_of(d, "late-src").is_some_and(|s| s["level"] == 3)
    });
    let s = diag_of(&stale, "late-src").unwrap();
    assert!(
        s["message"]
            .as_str()
            .unwrap()
            .contains("no message from ghnetd"),
        "{s}"
    );

    // A new ghnetd on the same services: relayed again, nothing to do.
    let daemon = Ghnetd::builder(&ns).arg("--stale-after-ms=0").start();
    daemon.wait_serving(&feed.gnss);
    for _ in 0..5 {
        feed.send(8.0, 30.0, false);
    }
    await_imu(&mut heard, &lines, TOPIC, feed.answers.last().unwrap());
    // The bridge relays what it sees from the moment it found the source: its last
    // message is the last answer, none missed, none refused.
    let last = (feed.seq - 1).to_string();
    let back = await_diagnostics(&mut heard, &lines, "late-src after the restart", |d| {
        diag_of(d, "late-src").is_some_and(|s| s["values"]["seq"] == last.as_str())
    });
    let s = diag_of(&back, "late-src").unwrap();
    assert_ne!(s["level"], 3, "{s}");
    // Samples the restarted ghnetd never saw are gaps in seq, which the bridge counts.
    let unanswered = feed.seq as usize - feed.answers.len();
    assert_eq!(
        s["values"]["missed"],
        unanswered.to_string().as_str(),
        "{s}"
    );
    assert_eq!(
        s["values"]["send_failures"], "0",
        "the stuck reader slowed nothing: {s}"
    );
    check_topic(&heard, TOPIC, &feed.answers);

    let status = bridge.terminate();
    let text = std::fs::read_to_string(&log).unwrap();
    assert!(status.success(), "{status}: {text}");
}
