//! The bridge end to end, without ghnetd: real iceoryx2 (a private namespace per
//! test), a pseudo-terminal as the serial device, local TCP servers speaking raw
//! UBX and gpsd's protocol, and the binary's `--print` output. Tests that need a
//! real ghnetd live in `tests/tests/gnss.rs` (with the shared test kit).
//!
//! No test asserts a duration: waits are bounded by a watchdog that fails the test.

use std::io::{Read, Write};
use std::net::{TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread;
use std::time::{Duration, Instant};

use ghnet_client::testing::{assert_success, TestNamespace};
use ghnet_client::{flags, HeadingEstimate, HeadingPublisher, VelocitySample, VelocitySubscriber};
use ghnet_gnss::{Config, Input, Output, Summary};
use ghnet_receivers::ubx::NavPvt;
use ghnet_receivers::{decode, Epoch, Format};

/// Longest any wait in these tests may take before the test fails.
const WATCHDOG: Duration = Duration::from_secs(60);

fn data_path(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../receivers/tests/data")
        .join(name)
}

/// Polls `what` until true; panics after [`WATCHDOG`].
fn wait_until(what: &str, mut cond: impl FnMut() -> bool) {
    let deadline = Instant::now() + WATCHDOG;
    while !cond() {
        assert!(Instant::now() < deadline, "watchdog: {what}");
        thread::sleep(Duration::from_millis(10));
    }
}

/// Runs the bridge on its own thread (iceoryx2 ports are per thread); the returned
/// flag stops it.
fn spawn_bridge(config: Config) -> (Arc<AtomicBool>, thread::JoinHandle<Summary>) {
    let stop = Arc::new(AtomicBool::new(false));
    let flag = stop.clone();
    let handle = thread::spawn(move || {
        ghnet_gnss::run(&config, &|| flag.load(Ordering::Relaxed)).expect("bridge run")
    });
    (stop, handle)
}

fn stop_bridge(stop: Arc<AtomicBool>, handle: thread::JoinHandle<Summary>) -> Summary {
    stop.store(true, Ordering::Relaxed);
    handle.join().expect("bridge thread")
}

fn live_config(source: &str, input: Input, ns: &TestNamespace) -> Config {
    let mut c = Config::new(source, input);
    c.output = Output::Publish(Box::new(ns.ipc()));
    c.backoff.max = Duration::from_millis(200);
    c
}

/// Collects samples until `n` arrived.
fn receive(sub: &VelocitySubscriber, n: usize, into: &mut Vec<VelocitySample>) {
    let target = into.len() + n;
    wait_until(&format!("{n} samples (have {})", into.len()), || {
        while let Some(s) = sub.try_recv().expect("recv") {
            into.push(s);
        }
        into.len() >= target
    });
    assert_eq!(into.len(), target, "more samples than epochs");
}

fn assert_monotonic(samples: &[VelocitySample]) {
    for (i, w) in samples.windows(2).enumerate() {
        assert_eq!(w[1].seq, w[0].seq + 1, "seq at {i}");
        assert!(w[1].timestamp_ns >= w[0].timestamp_ns, "time at {i}");
    }
}

/// `n` moving epochs at 5 Hz from `t0` (UBX NAV-PVT frames).
fn ubx_frames(t0: u64, n: u64) -> Vec<u8> {
    let mut out = Vec::new();
    for i in 0..n {
        let epoch = Epoch {
            time_ns: Some(t0 + i * 200_000_000),
            v_north: 1.0 + i as f32 * 0.1,
            v_east: 2.0,
            v_down: Some(0.0),
            speed_accuracy: 0.3,
            valid: true,
            course_deg: f32::NAN,
            course_accuracy_deg: f32::NAN,
        };
        NavPvt::from_epoch(&epoch).write_frame(&mut out);
    }
    out
}

#[test]
fn print_gives_one_row_per_epoch_of_every_capture() {
    let dir = data_path("");
    let mut names: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .filter_map(|e| e.ok().map(|e| e.file_name().to_string_lossy().into_owned()))
        .filter(|n| n.ends_with(".log") || n.ends_with(".jsonl"))
        .collect();
    names.sort();
    assert!(names.len() >= 10, "{names:?}");
    for name in names {
        let path = data_path(&name);
        let want = decode(&std::fs::read(&path).unwrap(), None).epochs;
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_ghnet-gnss"))
            .args(["--source", "print", "--print", "--replay-speed", "0"])
            .arg(&path)
            .output()
            .expect("run ghnet-gnss");
        assert_success(&out, &name);
        let text = String::from_utf8(out.stdout).unwrap();
        let rows: Vec<&str> = text.lines().skip(1).collect();
        assert_eq!(rows.len(), want.len(), "{name}");
        for (row, (i, e)) in rows.iter().zip(want.iter().enumerate()) {
            let cols: Vec<&str> = row.split(',').collect();
            assert_eq!(cols[0], i.to_string(), "{name}: seq");
            let flags: u32 = cols[6].parse().unwrap();
            assert_eq!(flags & flags::INVALID == 0, e.valid, "{name} row {i}");
            assert_ne!(flags & flags::SIMULATED, 0, "{name}: a replay is flagged");
        }
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(
            stderr.contains(&format!("published {} samples", want.len())),
            "{stderr}"
        );
    }
}

/// At `--replay-speed 0` the bridge sends a sample only after ghnetd answered the
/// one before; a stand-in daemon answers here.
#[test]
fn replay_at_speed_zero_waits_for_each_answer() {
    let ns = TestNamespace::new("gnss_replay");
    let ipc = ns.ipc();
    let daemon_stop = Arc::new(AtomicBool::new(false));
    let flag = daemon_stop.clone();
    let daemon_ipc = ipc.clone();
    let (ready_tx, ready_rx) = std::sync::mpsc::channel();
    let daemon = thread::spawn(move || {
        let samples = VelocitySubscriber::new(&daemon_ipc, "replay").unwrap();
        let answers = HeadingPublisher::new(&daemon_ipc, "replay").unwrap();
        ready_tx.send(()).unwrap();
        let mut seen = Vec::new();
        while !flag.load(Ordering::Relaxed) {
            if let Some(s) = samples.recv_timeout(Duration::from_millis(50)).unwrap() {
                // Only one sample may be in flight at a time.
                assert!(samples.try_recv().unwrap().is_none(), "bridge did not wait");
                let mut h = HeadingEstimate::from_le_bytes(&[0; HeadingEstimate::SIZE]);
                (h.seq, h.timestamp_ns) = (s.seq, s.timestamp_ns);
                answers.send(h).unwrap();
                seen.push(s);
            }
        }
        seen
    });
    ready_rx.recv().unwrap();
    let mut config = Config::new("replay", Input::File(data_path("ublox-neo-m8n.log")));
    config.output = Output::Publish(Box::new(ipc));
    config.replay_speed = 0.0;
    let summary = ghnet_gnss::run(&config, &|| false).unwrap();
    daemon_stop.store(true, Ordering::Relaxed);
    let seen = daemon.join().unwrap();
    assert_eq!(summary.published, 24, "{summary}");
    let answers = summary.answered.expect("a replay counts answers");
    assert_eq!((answers.total(), answers.ok), (24, 24), "{summary}");
    assert_eq!(seen.len(), 24);
    assert_monotonic(&seen);
    let first = seen[0];
    assert_eq!(first.flags, flags::SIMULATED);
    assert!((first.speed_accuracy - 0.229).abs() < 1e-6 && (first.v_down - 0.038).abs() < 1e-6);
}

/// A pseudo-terminal plays real u-blox logs as a serial device behind a by-id style
/// symlink: the NEO-M8N capture, then the device disappears (master closed, link
/// removed) and returns as a new pseudo-terminal playing the ZED-F9P capture. The
/// bridge reopens it; numbering and time go on.
#[test]
fn serial_device_that_disappears_and_returns_is_reopened() {
    let ns = TestNamespace::new("gnss_pty");
    let dir = tempdir("pty");
    let link = dir.join("gps0");
    let sub = VelocitySubscriber::new(&ns.ipc(), "pty").unwrap();
    let pty = Pty::open();
    std::os::unix::fs::symlink(&pty.slave_path, &link).unwrap();

    let input = Input::parse(link.to_str().unwrap(), None).unwrap();
    assert!(matches!(input, Input::Serial { .. }), "{input:?}");
    let (stop, bridge) = spawn_bridge(live_config("pty", input, &ns));
    let mut got = Vec::new();
    pty.wait_opened_raw();
    pty.write(&std::fs::read(data_path("ublox-neo-m8n.log")).unwrap());
    receive(&sub, 24, &mut got);

    drop(pty); // unplugged
    std::fs::remove_file(&link).unwrap();
    thread::sleep(Duration::from_millis(300)); // a few failed reopen attempts
    let pty = Pty::open();
    std::os::unix::fs::symlink(&pty.slave_path, &link).unwrap();
    pty.wait_opened_raw();
    pty.write(&std::fs::read(data_path("ublox-zed-f9p-hp.log")).unwrap());
    receive(&sub, 29, &mut got);

    let summary = stop_bridge(stop, bridge);
    assert_monotonic(&got);
    assert_eq!(summary.published, 24 + 29, "{summary}");
    assert!(summary.reconnects >= 1, "{summary}");
    assert_eq!(summary.format, Some(Format::Ubx));
    assert!(got.iter().all(|s| s.flags == 0), "live, valid, with v_down");
    assert!((got[0].speed_accuracy - 0.229).abs() < 1e-6, "{:?}", got[0]);
    drop(pty);
    let _ = std::fs::remove_dir_all(dir);
}

/// A local server speaks gpsd's protocol (VERSION, then JSON after `?WATCH`) from
/// recorded TPV lines, stops (gpsd restarting) and comes back on the same port,
/// replaying the old reports first: the bridge reconnects, skips what it already
/// published and sends only the new fixes.
#[test]
fn gpsd_server_restart_is_survived() {
    let ns = TestNamespace::new("gnss_gpsd");
    let sub = VelocitySubscriber::new(&ns.ipc(), "gpsd").unwrap();
    let first = std::fs::read(data_path("garmin15x.gpsd.jsonl")).unwrap();
    let m8l = std::fs::read_to_string(data_path("ublox-neo-m8l.gpsd.jsonl")).unwrap();
    let newer: String = m8l.lines().take(30).map(|l| format!("{l}\n")).collect();
    let n_first = decode(&first, Some(Format::Gpsd)).epochs.len();
    let n_newer = decode(newer.as_bytes(), Some(Format::Gpsd)).epochs.len();
    assert_eq!((n_first, n_newer), (7, 28));

    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = listener.local_addr().unwrap();
    let input = Input::parse(&format!("gpsd://{addr}"), None).unwrap();
    let (stop, bridge) = spawn_bridge(live_config("gpsd", input, &ns));
    let mut got = Vec::new();

    serve_gpsd(&listener, &first);
    receive(&sub, n_first, &mut got);
    drop(listener); // gpsd stops: connections refused for a while
    thread::sleep(Duration::from_millis(300));
    let listener = TcpListener::bind(addr).expect("rebind the same port");
    let mut replay = first.clone();
    replay.extend_from_slice(newer.as_bytes());
    serve_gpsd(&listener, &replay);
    receive(&sub, n_newer, &mut got);

    let summary = stop_bridge(stop, bridge);
    assert_monotonic(&got);
    assert_eq!(summary.published as usize, n_first + n_newer, "{summary}");
    assert!(summary.reconnects >= 1, "{summary}");
    // Skipped: the 26 repeats in the first session, the whole first session again
    // (33 TPV already published or older), 2 out-of-order lines among the new ones.
    let d = &summary.decoder;
    let repeats =
        d.skipped(ghnet_receivers::Skip::Duplicate) + d.skipped(ghnet_receivers::Skip::OutOfOrder);
    assert_eq!(repeats, 26 + 33 + 2, "{summary}");
}

/// One gpsd session: greet, check the `?WATCH` command, answer, send `reports`,
/// hang up.
fn serve_gpsd(listener: &TcpListener, reports: &[u8]) {
    let (mut conn, _) = accept(listener);
    conn.write_all(b"{\"class\":\"VERSION\",\"release\":\"3.25\",\"rev\":\"3.25\",\"proto_major\":3,\"proto_minor\":15}\r\n")
        .unwrap();
    let mut command = Vec::new();
    let mut byte = [0u8; 1];
    while !command.ends_with(b"\n") {
        assert_eq!(
            conn.read(&mut byte).unwrap(),
            1,
            "client hung up before ?WATCH"
        );
        command.push(byte[0]);
    }
    assert_eq!(command, ghnet_receivers::gpsd::WATCH_COMMAND);
    conn.write_all(b"{\"class\":\"DEVICES\",\"devices\":[{\"class\":\"DEVICE\",\"path\":\"/dev/ttyACM0\",\"driver\":\"u-blox\"}]}\r\n")
        .unwrap();
    conn.write_all(b"{\"class\":\"WATCH\",\"enable\":true,\"json\":true}\r\n")
        .unwrap();
    conn.write_all(reports).unwrap();
}

fn accept(listener: &TcpListener) -> (TcpStream, std::net::SocketAddr) {
    listener.set_nonblocking(true).unwrap();
    let mut conn = None;
    wait_until("the bridge connects", || match listener.accept() {
        Ok(c) => {
            conn = Some(c);
            true
        }
        Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => false,
        Err(e) => panic!("accept: {e}"),
    });
    let (stream, peer) = conn.unwrap();
    stream.set_nonblocking(false).unwrap();
    (stream, peer)
}

/// A raw UBX stream over TCP (ser2net style); the peer hangs up and comes back.
#[test]
fn raw_tcp_stream_reconnects() {
    let ns = TestNamespace::new("gnss_tcp");
    let sub = VelocitySubscriber::new(&ns.ipc(), "tcp").unwrap();
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let input = Input::parse(&format!("tcp://{}", listener.local_addr().unwrap()), None).unwrap();
    let (stop, bridge) = spawn_bridge(live_config("tcp", input, &ns));
    let mut got = Vec::new();
    let bytes = ubx_frames(1_700_000_000_000_000_000, 8);
    // The first session ends in the middle of a frame: that frame is lost (counted),
    // the next session starts clean.
    accept(&listener)
        .0
        .write_all(&bytes[..bytes.len() - 30])
        .unwrap();
    receive(&sub, 7, &mut got);
    accept(&listener)
        .0
        .write_all(&ubx_frames(1_700_000_002_000_000_000, 3))
        .unwrap();
    receive(&sub, 3, &mut got);
    let summary = stop_bridge(stop, bridge);
    assert_monotonic(&got);
    assert_eq!(
        summary.decoder.skipped(ghnet_receivers::Skip::Truncated),
        1,
        "{summary}"
    );
    assert!(summary.reconnects >= 1);
}

fn tempdir(tag: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("ghnet-gnss-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A pseudo-terminal pair; the test holds the master side (the "receiver").
struct Pty {
    master: std::fs::File,
    slave_path: PathBuf,
    /// Kept open until the bridge has its own: a pty whose slave was never opened
    /// discards what the master writes.
    _slave: std::fs::File,
}

impl Pty {
    fn open() -> Pty {
        use std::os::fd::FromRawFd;
        let (mut master, mut slave) = (0, 0);
        // SAFETY: openpty writes two descriptors into the pointers given; no name
        // buffer, default termios and window size.
        let rc = unsafe {
            libc::openpty(
                &mut master,
                &mut slave,
                std::ptr::null_mut(),
                std::ptr::null(),
                std::ptr::null(),
            )
        };
        assert_eq!(rc, 0, "openpty: {}", std::io::Error::last_os_error());
        let slave_path = std::fs::read_link(format!("/proc/self/fd/{slave}")).unwrap();
        // SAFETY: both descriptors were just created and are owned by nobody else.
        let (master, slave) = unsafe {
            (
                std::fs::File::from_raw_fd(master),
                std::fs::File::from_raw_fd(slave),
            )
        };
        Pty {
            master,
            slave_path,
            _slave: slave,
        }
    }

    /// Waits until the bridge has opened the device and made it raw (no echo, no
    /// line editing), so what the master writes reaches it byte for byte.
    fn wait_opened_raw(&self) {
        use std::os::fd::AsRawFd;
        wait_until("the bridge opens the serial device", || {
            // SAFETY: a zeroed termios is a valid out-parameter for tcgetattr.
            let mut t: libc::termios = unsafe { std::mem::zeroed() };
            // SAFETY: the master descriptor is open for the lifetime of self.
            let rc = unsafe { libc::tcgetattr(self.master.as_raw_fd(), &mut t) };
            rc == 0 && t.c_lflag & libc::ICANON == 0
        });
    }

    fn write(&self, bytes: &[u8]) {
        (&self.master).write_all(bytes).unwrap();
    }
}

/// SIGTERM (systemd's stop) ends a live run cleanly: exit status 0, the samples so
/// far printed, the summary logged.
#[test]
fn sigterm_stops_a_live_run_cleanly() {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = listener.local_addr().unwrap();
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_ghnet-gnss"))
        .args(["--source", "term", "--print", &format!("tcp://{addr}")])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("spawn ghnet-gnss");
    let (mut conn, _) = accept(&listener);
    conn.write_all(&std::fs::read(data_path("nl2008u.log")).unwrap())
        .unwrap();
    // The peer stays connected: only the signal can end this run. A thread reads
    // stdout so the watchdog, not a blocking read, bounds the wait.
    let stdout = child.stdout.take().unwrap();
    let (rows_tx, rows) = std::sync::mpsc::channel();
    thread::spawn(move || {
        use std::io::BufRead;
        for line in std::io::BufReader::new(stdout).lines() {
            let _ = rows_tx.send(line.unwrap());
        }
    });
    for i in 0..10 {
        rows.recv_timeout(WATCHDOG)
            .unwrap_or_else(|_| panic!("watchdog: row {i}"));
    }
    // SAFETY: kill(2) on the pid of a child we spawned and have not reaped.
    assert_eq!(unsafe { libc::kill(child.id() as i32, libc::SIGTERM) }, 0);
    let out = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(
        stderr.contains("stop requested") && stderr.contains("published 9 samples"),
        "{stderr}"
    );
    drop(conn);
}
