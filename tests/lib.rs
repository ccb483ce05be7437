//! Harness for ghnet's cross-process tests: the real `ghnetd` binary, real iceoryx2
//! shared memory, the public client API. The tests themselves are in `tests/`
//! (one binary, `cross_process`, that `mod`s one file per topic).
//!
//! # Layout
//!
//! - [`ghnetd_binary`] — finds the `ghnetd` executable next to the test executable
//!   (`target/<profile>/ghnetd`); `GHNETD_BIN` overrides.
//! - [`Namespace`] — a private iceoryx2 namespace per test (own `/dev/shm` prefix
//!   and root directory, unique by pid + counter + random), removed on drop; the
//!   first one also sweeps leftovers of earlier crashed runs.
//! - [`Daemon`] — a running `ghnetd` in a namespace, its log in a file; SIGTERM,
//!   `kill -9`, log and counter queries; killed and reaped on drop.
//! - [`ChildPublisher`] — a publisher in another process (`ghnet-test-publisher`)
//!   that crash tests can `kill -9`; [`ChildSubscriber`] the same for a heading
//!   consumer (`ghnet-test-subscriber`).
//! - [`recv_answer`] — the next heading that answers a sample, skipping the `Stale`
//!   message ghnetd sends for a silent source (exactly-once checks use it).
//! - [`list_nodes`] — the iceoryx2 nodes of a namespace, alive and dead, to check
//!   that a killed process's resources are reclaimed.
//! - [`test_model`] — the model the daemon runs, loaded the way the daemon loads it,
//!   so tests can compare against an in-process computation.
//! - [`wait_until`], [`WATCHDOG`] — bounded waits; a test never asserts a duration.
//!
//! # Running
//!
//! ```text
//! cargo test --workspace                                # builds ghnetd too (CI does this)
//! cargo build -p ghnetd && cargo test -p ghnet-tests    # just these tests
//! GHNETD_BIN=/path/to/ghnetd cargo test -p ghnet-tests  # another daemon build
//! ```
//!
//! The tests run in parallel with the default test threads and take about two
//! seconds on two cores; waits are bounded by [`WATCHDOG`], never asserted.
//!
//! # Rules every test follows
//!
//! - Its own [`Namespace`] (tests run in parallel; a shared namespace collides on
//!   service names, limits and dead-node cleanup).
//! - Children are reaped before the namespace is dropped: an unreaped zombie keeps
//!   its iceoryx2 liveness lock. The guards do this; declare the [`Namespace`] first
//!   so it is dropped last.
//! - Children get `PR_SET_PDEATHSIG(SIGKILL)`: if the test process dies (a crashed
//!   or killed `cargo test`), its daemons and publishers die with it instead of
//!   running forever. Linux sends it when the *thread* that spawned the child ends,
//!   so spawn children on the test's own thread.

#![warn(missing_docs)]

use std::collections::BTreeMap;
use std::ffi::OsString;
use std::fs::File;
use std::hash::{BuildHasher, Hasher};
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Output, Stdio};
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::{Arc, Mutex, Once, OnceLock};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use ghnet_client::IpcConfig;
use ghnet_models::Model;

/// Upper bound of every wait. Generous on purpose: tests run in parallel on small
/// machines; this only turns a hang into a failure, it is not a performance limit.
pub const WATCHDOG: Duration = Duration::from_secs(60);

/// Polls `cond` every 5 ms until it holds; panics naming `what` after [`WATCHDOG`].
pub fn wait_until(what: &str, mut cond: impl FnMut() -> bool) {
    let t0 = Instant::now();
    while !cond() {
        assert!(
            t0.elapsed() < WATCHDOG,
            "watchdog: no {what} after {WATCHDOG:?}"
        );
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// Nanoseconds since the Unix epoch, for sample timestamps.
pub fn now_ns() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .expect("clock after 1970")
        .as_nanos() as u64
}

/// Path of the `ghnetd` executable under test.
///
/// `GHNETD_BIN` if set; else `ghnetd` in the directory of the test executable or one
/// of its parents (`target/<profile>/deps/cross_process-…` → `target/<profile>/ghnetd`).
/// A test crate cannot use `env!("CARGO_BIN_EXE_ghnetd")` for another package's
/// binary, so `cargo test -p ghnet-tests` alone does not build it: `cargo test
/// --workspace` does (the daemon has integration tests), or `cargo build -p ghnetd`
/// first. Warns when the binary is older than the sources it is built from.
pub fn ghnetd_binary() -> PathBuf {
    static PATH: OnceLock<PathBuf> = OnceLock::new();
    PATH.get_or_init(|| {
        if let Some(p) = std::env::var_os("GHNETD_BIN") {
            return PathBuf::from(p);
        }
        let exe = std::env::current_exe().expect("path of the test executable");
        let name = format!("ghnetd{}", std::env::consts::EXE_SUFFIX);
        let found = exe
            .ancestors()
            .skip(1)
            .take(3)
            .map(|dir| dir.join(&name))
            .find(|p| p.is_file())
            .unwrap_or_else(|| {
                panic!(
                    "cannot find the ghnetd binary near {}.\n\
                     Build it with the same profile and target dir as the tests: \
                     `cargo build -p ghnetd` (or run `cargo test --workspace`, which \
                     builds it), or point GHNETD_BIN at one.",
                    exe.display()
                )
            });
        warn_if_stale(&found);
        found
    })
    .clone()
}

/// Warns when sources that go into ghnetd are newer than the binary: `cargo test -p
/// ghnet-tests` does not rebuild it, and a stale daemon fails in confusing ways.
fn warn_if_stale(binary: &Path) {
    let Ok(built) = binary.metadata().and_then(|m| m.modified()) else {
        return;
    };
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let mut newest: Option<(SystemTime, PathBuf)> = None;
    let mut stack: Vec<PathBuf> = [
        "daemon/src",
        "client/src",
        "models/inference/src",
        "models/inference/weights",
    ]
    .iter()
    .map(|d| root.join(d))
    .collect();
    while let Some(dir) = stack.pop() {
        let Ok(entries) = std::fs::read_dir(&dir) else {
            continue;
        };
        for e in entries.flatten() {
            let p = e.path();
            let is_source = matches!(
                p.extension().and_then(|x| x.to_str()),
                Some("rs" | "safetensors")
            );
            if p.is_dir() && p.starts_with(root.join("daemon/src")) {
                stack.push(p);
            } else if is_source {
                if let Ok(t) = e.metadata().and_then(|m| m.modified()) {
                    if newest.as_ref().is_none_or(|(n, _)| t > *n) {
                        newest = Some((t, p));
                    }
                }
            }
        }
    }
    if let Some((t, p)) = newest {
        if t > built {
            eprintln!(
                "warning: {} is older than {}; run `cargo build -p ghnetd` to test the current code",
                binary.display(),
                p.display()
            );
        }
    }
}

/// Marks names of namespaces made by this harness: `gnt<pid>x<counter>r<random>_`.
const TAG: &str = "gnt";
static NAMESPACES: AtomicU32 = AtomicU32::new(0);

/// A private iceoryx2 namespace for one test: its own global prefix (separates
/// `/dev/shm`) and root path (separates `/tmp/iceoryx2`), unique across parallel
/// tests and across runs (pid + counter + random). Drop removes its files; drop it
/// after every process using it is reaped.
#[derive(Debug)]
pub struct Namespace {
    global_prefix: String,
    root: PathBuf,
}

impl Namespace {
    /// A fresh namespace. The first one of a process also removes what earlier runs
    /// that crashed (and so never dropped theirs) left behind.
    pub fn new() -> Self {
        static SWEEP: Once = Once::new();
        SWEEP.call_once(sweep_leftovers);
        let n = NAMESPACES.fetch_add(1, Ordering::Relaxed);
        let random = std::collections::hash_map::RandomState::new()
            .build_hasher()
            .finish() as u32;
        let id = format!("{TAG}{}x{n}r{random:08x}", std::process::id());
        Self {
            global_prefix: format!("{id}_"),
            root: std::env::temp_dir().join(format!("ghnet-it-{id}")),
        }
    }

    /// The iceoryx2 global prefix.
    pub fn global_prefix(&self) -> &str {
        &self.global_prefix
    }

    /// The iceoryx2 root path.
    pub fn root_path(&self) -> &Path {
        &self.root
    }

    /// Client side: default service prefix in this namespace.
    pub fn ipc(&self) -> IpcConfig {
        IpcConfig::isolated(&self.global_prefix, &self.root).expect("generated names are valid")
    }

    /// The `ghnetd` flags that put the daemon into this namespace.
    pub fn daemon_args(&self) -> Vec<OsString> {
        vec![
            "--iceoryx2-global-prefix".into(),
            self.global_prefix.clone().into(),
            "--iceoryx2-root-path".into(),
            self.root.clone().into(),
        ]
    }
}

impl Default for Namespace {
    fn default() -> Self {
        Self::new()
    }
}

impl Drop for Namespace {
    fn drop(&mut self) {
        remove_namespace_files(|name| name.starts_with(&self.global_prefix));
        let _ = std::fs::remove_dir_all(&self.root);
    }
}

fn remove_namespace_files(matches: impl Fn(&str) -> bool) {
    if let Ok(entries) = std::fs::read_dir("/dev/shm") {
        for e in entries.flatten() {
            if matches(&e.file_name().to_string_lossy()) {
                let _ = std::fs::remove_file(e.path());
            }
        }
    }
}

/// Removes namespaces of processes that no longer exist (a test run killed before
/// its guards ran). Their children died with them (`PR_SET_PDEATHSIG`).
fn sweep_leftovers() {
    let dead = |name: &str| -> bool {
        let Some(rest) = name.strip_prefix(TAG).or_else(|| {
            name.strip_prefix("ghnet-it-")
                .and_then(|r| r.strip_prefix(TAG))
        }) else {
            return false;
        };
        let Some((pid, _)) = rest.split_once('x') else {
            return false;
        };
        match pid.parse::<u32>() {
            Ok(pid) => pid != std::process::id() && !Path::new(&format!("/proc/{pid}")).exists(),
            Err(_) => false,
        }
    };
    remove_namespace_files(dead);
    if let Ok(entries) = std::fs::read_dir(std::env::temp_dir()) {
        for e in entries.flatten() {
            if dead(&e.file_name().to_string_lossy()) {
                let _ = std::fs::remove_dir_all(e.path());
            }
        }
    }
}

/// Makes a spawned child die with the test thread that spawned it.
fn die_with_parent(cmd: &mut Command) -> &mut Command {
    // SAFETY: only an async-signal-safe syscall between fork and exec.
    unsafe {
        cmd.pre_exec(|| {
            libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGKILL);
            Ok(())
        })
    }
}

/// The model under test, and how the daemon is told to use it.
#[derive(Debug)]
pub struct TestModel {
    /// The model, loaded like the daemon loads it (`Model::from_name_or_path`).
    pub model: Arc<Model>,
    /// The built-in name to pass as `--model`; `None` when it is the daemon's
    /// default (then no `--model` flag is passed at all).
    pub flag: Option<&'static str>,
}

/// The model every daemon in these tests runs, loaded the way the daemon loads it.
///
/// Normally the default built-in model (`ghnet_models::DEFAULT_MODEL`), so the tests
/// exercise what ships without a `--model` flag. While its embedded weights are a
/// placeholder (being retrained) and fail to load, the first other built-in model
/// that loads is used and passed as `--model <name>`, so the IPC tests still run; a
/// note says so. Panics if no built-in model loads.
pub fn test_model() -> &'static TestModel {
    static MODEL: OnceLock<TestModel> = OnceLock::new();
    MODEL.get_or_init(|| {
        let default = ghnet_models::DEFAULT_MODEL;
        let mut errors = Vec::new();
        let names = std::iter::once(default).chain(
            ghnet_models::model::BUILTIN
                .iter()
                .map(|(name, _)| *name)
                .filter(|n| *n != default),
        );
        for name in names {
            match Model::from_name_or_path(name) {
                Ok(m) => {
                    if name != default {
                        eprintln!(
                            "note: the default model does not load ({}); ghnetd runs `--model {name}` in these tests",
                            errors.join("; ")
                        );
                    }
                    return TestModel {
                        model: Arc::new(m),
                        flag: (name != default).then_some(name),
                    };
                }
                Err(e) => errors.push(e.to_string()),
            }
        }
        panic!("no built-in model loads: {}", errors.join("; "));
    })
}

/// Counters from one of the daemon's log lines, by key (`received`, `answered`,
/// `invalid`, and in `stats` lines also `gaps`, `duplicates`, `backwards`,
/// `send_errors`, `publishers`).
pub type StatsLine = BTreeMap<String, u64>;

/// A running `ghnetd` in a [`Namespace`], stderr (its log) in a file. Killed and
/// reaped on drop. Every wait on it fails at once, with the log, if the daemon
/// exits unexpectedly (e.g. it cannot load its model).
#[derive(Debug)]
pub struct Daemon {
    // A Mutex so that waits (`&self`, also from helper threads) can check liveness.
    child: Mutex<Option<Child>>,
    log: PathBuf,
    dir: tempfile::TempDir,
}

impl Daemon {
    /// Starts `ghnetd` in `ns` with fast housekeeping (`--discovery-interval-ms 50`),
    /// a stats line every second, the [`test_model`], and `extra` flags. Returns at
    /// once; wait for readiness with [`wait_serving`](Self::wait_serving) or
    /// [`wait_for_log`](Self::wait_for_log).
    pub fn start(ns: &Namespace, extra: &[&str]) -> Self {
        Self::start_wrapped(ns, &[], extra)
    }

    /// [`start`](Self::start) under a wrapper command that execs its arguments, e.g.
    /// `["ip", "netns", "exec", "<name>"]` to run the daemon in a network namespace.
    pub fn start_wrapped(ns: &Namespace, wrapper: &[&str], extra: &[&str]) -> Self {
        // Named like a namespace root, so a sweep after a crashed run removes it too.
        let dir = tempfile::Builder::new()
            .prefix(&format!("ghnet-it-{TAG}{}xlog", std::process::id()))
            .tempdir()
            .expect("temp dir");
        let log = dir.path().join("ghnetd.log");
        let mut cmd = match wrapper.split_first() {
            Some((program, args)) => {
                let mut c = Command::new(program);
                c.args(args).arg(ghnetd_binary());
                c
            }
            None => Command::new(ghnetd_binary()),
        };
        // Zenoh on any free loopback port (tests run in parallel) unless `extra` says
        // where; the port is in the log, see `zenoh_endpoint`.
        if !extra.contains(&"--zenoh-listen") {
            cmd.args(["--zenoh-listen", "tcp/127.0.0.1:0"]);
        }
        cmd.args(ns.daemon_args())
            .args(["--discovery-interval-ms", "50"])
            .args(["--stats-interval-s", "1"]);
        if let Some(name) = test_model().flag {
            cmd.args(["--model", name]);
        }
        // ghnetd's default log filter (info), whatever RUST_LOG the test runs with.
        cmd.args(extra)
            .env_remove("RUST_LOG")
            .env_remove("GHNETD_CONFIG")
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(File::create(&log).expect("log file"));
        let child = die_with_parent(&mut cmd)
            .spawn()
            .unwrap_or_else(|e| panic!("cannot start {}: {e}", ghnetd_binary().display()));
        Self {
            child: Mutex::new(Some(child)),
            log,
            dir,
        }
    }

    /// A scratch directory that lives as long as the daemon (config files, ...).
    pub fn dir(&self) -> &Path {
        self.dir.path()
    }

    /// The log so far.
    pub fn log(&self) -> String {
        std::fs::read_to_string(&self.log).unwrap_or_default()
    }

    fn child(&self) -> std::sync::MutexGuard<'_, Option<Child>> {
        // A panicking test thread may poison it; the child is still valid.
        self.child.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Whether the process is still running (reaps it if it exited).
    pub fn is_running(&self) -> bool {
        let mut child = self.child();
        let child = child.as_mut().expect("not yet stopped");
        child.try_wait().expect("try_wait").is_none()
    }

    /// Panics with the exit status and the log if the daemon is no longer running.
    pub fn assert_running(&self) {
        let status = {
            let mut child = self.child();
            let child = child.as_mut().expect("not yet stopped");
            child.try_wait().expect("try_wait")
        };
        if let Some(status) = status {
            panic!(
                "ghnetd exited unexpectedly ({status}); log:\n{}\n(ghnetd binary: {})",
                self.log(),
                ghnetd_binary().display()
            );
        }
    }

    /// Polls `cond` until it holds, failing on the watchdog or if the daemon exits.
    pub fn wait_until(&self, what: &str, mut cond: impl FnMut() -> bool) {
        let t0 = Instant::now();
        while !cond() {
            self.assert_running();
            if t0.elapsed() > WATCHDOG {
                panic!(
                    "watchdog: no {what} after {WATCHDOG:?}; ghnetd log:\n{}",
                    self.log()
                );
            }
            std::thread::sleep(Duration::from_millis(5));
        }
    }

    /// Waits until `publisher` has a subscriber: the daemon serves its source (static
    /// sources at start-up, discovered ones within a discovery interval).
    pub fn wait_serving(&self, publisher: &ghnet_client::VelocityPublisher) {
        let what = format!("subscriber on {}", publisher.service_name());
        self.wait_until(&what, || publisher.subscriber_count() >= 1);
    }

    /// Waits until the log contains `needle` at least `count` times.
    pub fn wait_for_log_count(&self, needle: &str, count: usize) {
        let what = format!("`{needle}` {count} times in the log");
        self.wait_until(&what, || self.log().matches(needle).count() >= count);
    }

    /// Waits until the log contains `needle`.
    pub fn wait_for_log(&self, needle: &str) {
        self.wait_for_log_count(needle, 1);
    }

    /// Waits for a counters line for `source` that satisfies `cond` (the daemon logs
    /// `stats` once a second here, and `source removed` when it drops a source), and
    /// returns it.
    pub fn wait_for_stats(&self, source: &str, cond: impl Fn(&StatsLine) -> bool) -> StatsLine {
        let mut found = None;
        self.wait_until(&format!("matching counters for {source}"), || {
            found = self.last_stats(source).filter(&cond);
            found.is_some()
        });
        found.expect("found")
    }

    /// The counters of the last log line for `source` that has them, if any (see
    /// [`last_stats_in`]).
    pub fn last_stats(&self, source: &str) -> Option<StatsLine> {
        last_stats_in(&self.log(), source)
    }

    /// The first endpoint the daemon's Zenoh session listens on, e.g.
    /// `tcp/127.0.0.1:40123` (the real port when it was started with port 0), read
    /// from its `zenoh session open` log line; waits for that line.
    pub fn zenoh_endpoint(&self) -> String {
        self.wait_for_log("zenoh session open");
        let log = self.log();
        let line = log
            .lines()
            .find(|l| l.contains("zenoh session open"))
            .expect("found");
        let rest = line
            .split_once("listening=[\"")
            .unwrap_or_else(|| panic!("no listening endpoints in `{line}`"))
            .1;
        rest.split('"').next().expect("an endpoint").to_owned()
    }

    /// The process id.
    pub fn pid(&self) -> u32 {
        self.child().as_ref().expect("not yet stopped").id()
    }

    /// Sends `signal` (e.g. `libc::SIGTERM`).
    pub fn signal(&self, signal: i32) {
        let pid = self.pid();
        // SAFETY: kill(2) on our own child, not yet reaped, so its pid is not reused.
        let rc = unsafe { libc::kill(pid as libc::pid_t, signal) };
        assert_eq!(rc, 0, "kill({pid}, {signal})");
    }

    /// Waits for the exit (watchdog: then SIGKILL and panic) and returns the status
    /// and the whole log.
    pub fn wait_exit(self) -> (ExitStatus, String) {
        let mut child = self.child().take().expect("not yet stopped");
        let t0 = Instant::now();
        loop {
            if let Some(status) = child.try_wait().expect("try_wait") {
                return (status, self.log());
            }
            if t0.elapsed() > WATCHDOG {
                let _ = child.kill();
                let _ = child.wait();
                panic!(
                    "watchdog: ghnetd still running {WATCHDOG:?} after being asked to stop; log:\n{}",
                    self.log()
                );
            }
            std::thread::sleep(Duration::from_millis(5));
        }
    }

    /// SIGTERM, then [`wait_exit`](Self::wait_exit).
    pub fn terminate(self) -> (ExitStatus, String) {
        self.signal(libc::SIGTERM);
        self.wait_exit()
    }

    /// `kill -9` and reap (so its iceoryx2 liveness lock is released, like a real
    /// crash once init reaps it). Its iceoryx2 resources stay behind.
    pub fn kill9(self) {
        let mut child = self.child().take().expect("not yet stopped");
        child.kill().expect("SIGKILL");
        child.wait().expect("reap");
    }
}

impl Drop for Daemon {
    fn drop(&mut self) {
        if let Some(mut child) = self.child().take() {
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}

/// The counters of the last line for `source` in a ghnetd log that carries them:
/// the periodic `stats` line, the final one at shutdown, or `source removed` (tracing's
/// plain format: `... INFO ghnetd::serve: stats source=a received=3 answered=3 ...`).
pub fn last_stats_in(log: &str, source: &str) -> Option<StatsLine> {
    let source_kv = format!("source={source}");
    log.lines()
        .rfind(|l| l.contains(" received=") && l.split_whitespace().any(|w| w == source_kv))
        .map(|l| {
            l.split_whitespace()
                .filter_map(|w| w.split_once('='))
                .filter_map(|(k, v)| Some((k.to_owned(), v.parse().ok()?)))
                .collect()
        })
}

/// Runs `ghnetd args…` to completion (for start-up failures), with a watchdog.
pub fn run_ghnetd(args: &[OsString]) -> Output {
    let mut cmd = Command::new(ghnetd_binary());
    cmd.args(args)
        .env_remove("GHNETD_CONFIG")
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    let mut child = die_with_parent(&mut cmd).spawn().expect("start ghnetd");
    let t0 = Instant::now();
    while child.try_wait().expect("try_wait").is_none() {
        if t0.elapsed() > WATCHDOG {
            let _ = child.kill();
            let out = child.wait_with_output().expect("reap");
            panic!(
                "watchdog: ghnetd {args:?} did not exit; stderr:\n{}",
                String::from_utf8_lossy(&out.stderr)
            );
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    child.wait_with_output().expect("collect output")
}

/// A `ghnet-test-publisher` process: sends `VelocitySample`s for one source
/// (v_north 3, v_east 4, seq from `first_seq` up, real timestamps) until killed.
/// Killed and reaped on drop.
#[derive(Debug)]
pub struct ChildPublisher {
    child: Option<Child>,
}

impl ChildPublisher {
    /// Starts `binary` (pass `env!("CARGO_BIN_EXE_ghnet-test-publisher")`) in `ns`.
    pub fn spawn(binary: &str, ns: &Namespace, source: &str, first_seq: u64, rate_hz: u32) -> Self {
        let mut cmd = Command::new(binary);
        cmd.arg(ns.global_prefix())
            .arg(ns.root_path())
            .arg(source)
            .arg(first_seq.to_string())
            .arg(rate_hz.to_string())
            .stdin(Stdio::null())
            .stdout(Stdio::null());
        let child = die_with_parent(&mut cmd)
            .spawn()
            .unwrap_or_else(|e| panic!("cannot start {binary}: {e}"));
        Self { child: Some(child) }
    }

    /// Whether it is still running.
    pub fn is_running(&mut self) -> bool {
        let child = self.child.as_mut().expect("not yet killed");
        child.try_wait().expect("try_wait").is_none()
    }

    /// `kill -9` and reap.
    pub fn kill9(mut self) {
        let mut child = self.child.take().expect("not yet killed");
        child.kill().expect("SIGKILL");
        child.wait().expect("reap");
    }
}

impl Drop for ChildPublisher {
    fn drop(&mut self) {
        if let Some(mut child) = self.child.take() {
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}

/// A loopback-only Zenoh peer session connected to `endpoint` (a daemon's, see
/// [`Daemon::zenoh_endpoint`]), listening nowhere, no scouting; returns once the
/// connection is up.
pub fn zenoh_session(endpoint: &str) -> ghnet_client::zenoh::Session {
    use ghnet_client::zenoh::Wait;
    let config = ghnet_client::peer_config(&[], &[endpoint.to_owned()]).expect("valid config");
    let session = ghnet_client::zenoh::open(config)
        .wait()
        .expect("zenoh session");
    wait_until(&format!("zenoh connection to {endpoint}"), || {
        session.info().peers_zid().wait().next().is_some()
    });
    session
}

/// Returns once the daemon on `session` answers its model query. The query travels
/// after every declaration made before it on the same link, so afterwards the daemon
/// knows this session's subscribers and no heading is missed.
pub fn zenoh_barrier(session: &ghnet_client::zenoh::Session, ipc: &IpcConfig) {
    use ghnet_client::zenoh::Wait;
    let key = ipc.zenoh_model_key();
    wait_until(&format!("an answer on {key}"), || {
        let replies = session.get(key.as_str()).wait().expect("query");
        matches!(replies.recv_timeout(WATCHDOG), Ok(Some(r)) if r.result().is_ok())
    });
}

/// A service prefix no other test (or run) uses, for Zenoh key isolation.
pub fn unique_prefix(tag: &str) -> String {
    let n = NAMESPACES.fetch_add(1, Ordering::Relaxed);
    format!("{tag}{}x{n}", std::process::id())
}

/// `|a - b| <= 1e-6 · max(1, |b|)`, both NaN counting as equal, and headings that
/// differ by a full turn (359.9999… vs 0) counting as equal when `wrap_360`.
pub fn close(a: f32, b: f32, wrap_360: bool) -> bool {
    if a.is_nan() || b.is_nan() {
        return a.is_nan() && b.is_nan();
    }
    let tol = 1e-6 * b.abs().max(1.0);
    let d = (a - b).abs();
    d <= tol || (wrap_360 && (d - 360.0).abs() <= 1e-6 * 360.0)
}

/// The next heading that answers a sample, skipping `Stale` messages (ghnetd sends
/// one when a source is silent for `sources.stale_after_ms`; it repeats the last
/// sequence number and is not an answer). `None` after `timeout` without an answer.
/// Exactly-once checks use this, so a slow test machine cannot turn a pause into a
/// spurious extra message.
pub fn recv_answer(
    headings: &ghnet_client::HeadingSubscriber,
    timeout: Duration,
) -> Option<ghnet_client::HeadingEstimate> {
    let deadline = Instant::now() + timeout;
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        let h = headings.recv_timeout(left).expect("receive")?;
        if h.heading_status() != Some(ghnet_client::HeadingStatus::Stale) {
            return Some(h);
        }
    }
}

/// The iceoryx2 nodes of `ns` by state: `(alive, dead)`, each as the `Debug` text of
/// the node id plus the node name. A dead node is a process that died without
/// releasing its resources; the next node created in the namespace (or ghnetd's
/// housekeeping) removes them.
pub fn list_nodes(ns: &Namespace) -> (Vec<String>, Vec<String>) {
    use iceoryx2::prelude::*;
    let mut alive = Vec::new();
    let mut dead = Vec::new();
    let describe = |id: &dyn std::fmt::Debug, details: &Option<iceoryx2::node::NodeDetails>| {
        let name = details
            .as_ref()
            .map(|d| d.name().to_string())
            .unwrap_or_default();
        format!("{id:?} {name}")
    };
    Node::<ipc::Service>::list(&ns.ipc().iceoryx2_config(), |state| {
        use iceoryx2::node::NodeView;
        match state {
            NodeState::Alive(v) => alive.push(describe(v.id(), v.details())),
            NodeState::Dead(v) => dead.push(describe(v.id(), v.details())),
            NodeState::Inaccessible(id) | NodeState::Undefined(id) => {
                dead.push(format!("{id:?} (inaccessible or undefined)"))
            }
        }
        CallbackProgression::Continue
    })
    .expect("list iceoryx2 nodes");
    (alive, dead)
}

/// A `ghnet-test-subscriber` process: a `HeadingSubscriber` for one source in another
/// process, printing `ready` once subscribed and then `<seq> <status>` per heading.
/// Its lines arrive on a channel ([`next_line`](Self::next_line)). Killed and reaped
/// on drop.
#[derive(Debug)]
pub struct ChildSubscriber {
    child: Option<Child>,
    lines: std::sync::mpsc::Receiver<String>,
}

impl ChildSubscriber {
    /// Starts `binary` (pass `env!("CARGO_BIN_EXE_ghnet-test-subscriber")`) in `ns` and
    /// waits for its `ready` line.
    pub fn spawn(binary: &str, ns: &Namespace, source: &str) -> Self {
        let mut cmd = Command::new(binary);
        cmd.arg(ns.global_prefix())
            .arg(ns.root_path())
            .arg(source)
            .stdin(Stdio::null())
            .stdout(Stdio::piped());
        let mut child = die_with_parent(&mut cmd)
            .spawn()
            .unwrap_or_else(|e| panic!("cannot start {binary}: {e}"));
        let stdout = child.stdout.take().expect("piped stdout");
        let (tx, lines) = std::sync::mpsc::channel();
        // Only reads a pipe; the child's lifetime stays tied to the test thread.
        std::thread::spawn(move || {
            use std::io::BufRead;
            for line in std::io::BufReader::new(stdout).lines() {
                let Ok(line) = line else { break };
                if tx.send(line).is_err() {
                    break;
                }
            }
        });
        let mut this = Self {
            child: Some(child),
            lines,
        };
        let first = this.next_line();
        assert_eq!(first.as_deref(), Some("ready"), "test subscriber start");
        this
    }

    /// The next line, `None` if the process ended or [`WATCHDOG`] passed.
    pub fn next_line(&mut self) -> Option<String> {
        self.lines.recv_timeout(WATCHDOG).ok()
    }

    /// Reads lines until a heading with `seq >= min_seq` that is not `Stale`; returns
    /// its seq. Panics if the process ends or the watchdog fires first.
    pub fn answer_at_least(&mut self, min_seq: u64) -> u64 {
        loop {
            let line = self
                .next_line()
                .unwrap_or_else(|| panic!("test subscriber: no heading with seq >= {min_seq}"));
            let (seq, status) = line.split_once(' ').expect("`<seq> <status>`");
            let seq: u64 = seq.parse().expect("seq");
            let stale = ghnet_client::HeadingStatus::Stale.as_u32().to_string();
            if seq >= min_seq && status != stale {
                return seq;
            }
        }
    }

    /// The process id.
    pub fn pid(&self) -> u32 {
        self.child.as_ref().expect("not yet killed").id()
    }

    /// `kill -9` and reap.
    pub fn kill9(mut self) {
        let mut child = self.child.take().expect("not yet killed");
        child.kill().expect("SIGKILL");
        child.wait().expect("reap");
    }
}

impl Drop for ChildSubscriber {
    fn drop(&mut self) {
        if let Some(mut child) = self.child.take() {
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}
