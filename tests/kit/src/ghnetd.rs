//! [`Ghnetd`]: a real `ghnetd` process in a [`TestNamespace`], from spawn to reaping.
//!
//! The test chooses where the daemon's Zenoh session listens ([`Listen`]), so nothing
//! is read back from the log: the kit connects a session of its own to that endpoint
//! for readiness (the model query answers) and for the counters (`@ghnetd/stats`, the
//! same JSON any consumer reads). The log goes to a file in a scratch directory of the
//! namespace; failures quote it.
//!
//! Every method comes in the form a test wants (panics, with the log, after
//! [`WATCHDOG`]) and, where a tool needs it, a fallible one (`try_…`, with a timeout).

use std::collections::BTreeMap;
use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::process::{Command, ExitStatus, Output, Stdio};
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::OnceLock;
use std::time::Duration;

use ghnet_client::zenoh::query::ConsolidationMode;
use ghnet_client::zenoh::{self, Wait};
use ghnet_client::{HeadingSubscriber, IpcConfig, VelocityPublisher};

use crate::child::Process;
use crate::{find_binary, model_answers, test_model, TestNamespace, WATCHDOG};

/// Where the daemon's Zenoh session listens; the kit and the test connect there.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub enum Listen {
    /// `unixsock-stream/<scratch dir>/zenoh.sock`: private to the test, no port to
    /// race another test for.
    #[default]
    UnixSocket,
    /// `tcp/127.0.0.1:<a free port>`, for what a unix socket cannot show (the
    /// loopback-only listener, tcp consumers).
    Tcp,
    /// This endpoint as given, e.g. `tcp/192.0.2.1:7447` in a network namespace.
    Endpoint(String),
    /// `--zenoh false`: no Zenoh session; readiness is the iceoryx2 node alone and
    /// there are no stats to read.
    Off,
}

/// Counters of one source from `@ghnetd/stats`: every numeric field of its object
/// (`received`, `answered`, `invalid`, `gaps`, `duplicates`, `backwards`,
/// `send_errors`, `stale`, `last_seq`, …), by name.
pub type Counters = BTreeMap<String, u64>;

static SPAWNS: AtomicU32 = AtomicU32::new(0);

/// How to start a [`Ghnetd`]: `Ghnetd::builder(&ns).source("a").discovery(false).start()`.
///
/// Always passed: the namespace (`--iceoryx2-global-prefix`, `--iceoryx2-root-path`),
/// the Zenoh endpoint (or `--zenoh false`), and unless changed a fast discovery
/// interval (50 ms) and the [`test_model`]. `RUST_LOG` and `GHNETD_CONFIG` of the
/// caller are not passed on: the daemon logs with its default filter.
#[derive(Debug)]
pub struct GhnetdBuilder<'a> {
    ns: &'a TestNamespace,
    program: Option<(PathBuf, Vec<OsString>)>,
    wrapper: Vec<OsString>,
    prefix: Option<String>,
    sources: Vec<String>,
    discovery: Option<bool>,
    discovery_interval_ms: Option<u64>,
    model: ModelFlag,
    listen: Listen,
    args: Vec<OsString>,
    log: Option<PathBuf>,
}

/// What the builder passes as `--model`.
#[derive(Debug, Clone, PartialEq, Eq)]
enum ModelFlag {
    /// The [`test_model`]'s flag, if it has one.
    Test,
    /// This name or path.
    Named(String),
    /// Nothing: the program's own default (or its config file's).
    None,
}

impl<'a> GhnetdBuilder<'a> {
    /// `--service-prefix`: the daemon's service prefix (default `ghnet`).
    pub fn prefix(mut self, prefix: &str) -> Self {
        self.prefix = Some(prefix.to_owned());
        self
    }

    /// `--source`: a static source, served from the start.
    pub fn source(mut self, name: &str) -> Self {
        self.sources.push(name.to_owned());
        self
    }

    /// `--discovery`: whether sources that appear are served too (ghnetd's default:
    /// yes).
    pub fn discovery(mut self, on: bool) -> Self {
        self.discovery = Some(on);
        self
    }

    /// ghnetd's own discovery interval instead of the kit's 50 ms (for measurements
    /// of the daemon as deployed).
    pub fn default_discovery_interval(mut self) -> Self {
        self.discovery_interval_ms = None;
        self
    }

    /// `--model`: a built-in name or a `.safetensors` path instead of the [`test_model`].
    pub fn model(mut self, name_or_path: &str) -> Self {
        self.model = ModelFlag::Named(name_or_path.to_owned());
        self
    }

    /// No `--model` at all: the daemon's default model, or its config file's (and
    /// what a program other than ghnetd expects, see [`program`](Self::program)).
    pub fn no_model_flag(mut self) -> Self {
        self.model = ModelFlag::None;
        self
    }

    /// Where Zenoh listens (default: [`Listen::UnixSocket`]).
    pub fn listen(mut self, listen: Listen) -> Self {
        self.listen = listen;
        self
    }

    /// Any other flag, passed after the kit's.
    pub fn arg(mut self, arg: impl Into<OsString>) -> Self {
        self.args.push(arg.into());
        self
    }

    /// Runs the daemon under a command that execs its arguments, e.g.
    /// `["ip", "netns", "exec", "<name>"]`.
    pub fn wrapper(mut self, command: &[&str]) -> Self {
        self.wrapper = command.iter().map(Into::into).collect();
        self
    }

    /// Another program than the `ghnetd` under test, started as `program args…
    /// <flags>`: another ghnetd build, or perf's model-free echo, which takes ghnetd's
    /// namespace, `--service-prefix`, `--source`, `--discovery-interval-ms` and
    /// `--zenoh-*` flags (give it [`no_model_flag`](Self::no_model_flag)).
    pub fn program(mut self, program: &Path, args: &[&str]) -> Self {
        self.program = Some((program.to_owned(), args.iter().map(Into::into).collect()));
        self
    }

    /// Log (stderr) to this file instead of one in a scratch directory of the
    /// namespace (which goes with the namespace).
    pub fn log_file(mut self, path: &Path) -> Self {
        self.log = Some(path.to_owned());
        self
    }

    /// Starts the process and returns at once (see [`Ghnetd::wait_ready`]).
    pub fn spawn(self) -> Ghnetd {
        self.try_spawn().unwrap_or_else(|e| panic!("{e:#}"))
    }

    /// [`spawn`](Self::spawn), then [`Ghnetd::wait_ready`].
    pub fn start(self) -> Ghnetd {
        let daemon = self.spawn();
        daemon.wait_ready();
        daemon
    }

    /// The fallible [`spawn`](Self::spawn), for tools.
    pub fn try_spawn(self) -> anyhow::Result<Ghnetd> {
        let n = SPAWNS.fetch_add(1, Ordering::Relaxed);
        let dir = self.ns.scratch_dir(&format!("ghnetd{n}"));
        let endpoint = match &self.listen {
            Listen::UnixSocket => Some(format!(
                "unixsock-stream/{}",
                dir.join("zenoh.sock").display()
            )),
            Listen::Tcp => Some(format!("tcp/127.0.0.1:{}", crate::free_tcp_port())),
            Listen::Endpoint(e) => Some(e.clone()),
            Listen::Off => None,
        };
        let log = self.log.clone().unwrap_or_else(|| dir.join("ghnetd.log"));
        let mut cmd = self.command(endpoint.as_deref())?;
        let stderr = std::fs::File::create(&log)
            .map_err(|e| anyhow::anyhow!("cannot create {}: {e}", log.display()))?;
        cmd.env_remove("RUST_LOG")
            .env_remove("GHNETD_CONFIG")
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(stderr);
        let mut ipc = self.ns.ipc();
        if let Some(p) = &self.prefix {
            ipc = ipc.with_prefix(p)?;
        }
        Ok(Ghnetd {
            process: Process::spawn(&mut cmd)?,
            ipc,
            endpoint,
            log,
            dir,
            session: OnceLock::new(),
        })
    }

    /// The command line: wrapper, program, the kit's flags, then the caller's.
    fn command(&self, endpoint: Option<&str>) -> anyhow::Result<Command> {
        let (program, program_args) = match &self.program {
            Some((p, a)) => (p.clone(), a.clone()),
            None => (ghnetd_binary()?, Vec::new()),
        };
        let mut cmd = crate::child::wrapped(&self.wrapper, program);
        cmd.args(program_args)
            .arg("--iceoryx2-global-prefix")
            .arg(self.ns.global_prefix())
            .arg("--iceoryx2-root-path")
            .arg(self.ns.root_path());
        if let Some(p) = &self.prefix {
            cmd.args(["--service-prefix", p]);
        }
        for s in &self.sources {
            cmd.args(["--source", s]);
        }
        if let Some(on) = self.discovery {
            cmd.args(["--discovery", if on { "true" } else { "false" }]);
        }
        if let Some(ms) = self.discovery_interval_ms {
            cmd.args(["--discovery-interval-ms", &ms.to_string()]);
        }
        let model = match &self.model {
            ModelFlag::Test => test_model().flag,
            ModelFlag::Named(m) => Some(m.as_str()),
            ModelFlag::None => None,
        };
        if let Some(m) = model {
            cmd.args(["--model", m]);
        }
        match endpoint {
            Some(e) => cmd.args(["--zenoh-listen", e]),
            None => cmd.args(["--zenoh", "false"]),
        };
        cmd.args(&self.args);
        Ok(cmd)
    }
}

/// The `ghnetd` executable under test: `GHNETD_BIN` if set, else the one next to the
/// running executable ([`find_binary`]). Warns once when sources that go into it are
/// newer than it (`cargo test -p <crate>` does not rebuild it).
pub fn ghnetd_binary() -> anyhow::Result<PathBuf> {
    static PATH: OnceLock<PathBuf> = OnceLock::new();
    if let Some(p) = PATH.get() {
        return Ok(p.clone());
    }
    let path = match std::env::var_os("GHNETD_BIN") {
        Some(p) => PathBuf::from(p),
        None => {
            let found = find_binary("ghnetd")?;
            warn_if_stale(&found);
            found
        }
    };
    Ok(PATH.get_or_init(|| path).clone())
}

/// Warns when sources that go into ghnetd are newer than the binary: a stale daemon
/// fails in confusing ways.
fn warn_if_stale(binary: &Path) {
    let Ok(built) = binary.metadata().and_then(|m| m.modified()) else {
        return;
    };
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let dirs = ["daemon/src", "client/src", "models/inference/src"];
    let mut stack: Vec<PathBuf> = dirs.iter().map(|d| root.join(d)).collect();
    while let Some(dir) = stack.pop() {
        for e in std::fs::read_dir(&dir).into_iter().flatten().flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
            } else if e
                .metadata()
                .and_then(|m| m.modified())
                .is_ok_and(|t| t > built)
            {
                eprintln!(
                    "warning: {} is older than {}; run `cargo build -p ghnetd` to test the current code",
                    binary.display(),
                    p.display()
                );
                return;
            }
        }
    }
}

/// Runs `ghnetd` in `ns` with `args` (and nothing else of the kit's) to its exit, for
/// start-up failures; stdout and stderr are captured. Panics after [`WATCHDOG`].
pub fn run_ghnetd(ns: &TestNamespace, args: &[OsString]) -> Output {
    let binary = ghnetd_binary().unwrap_or_else(|e| panic!("{e:#}"));
    let mut cmd = Command::new(binary);
    cmd.arg("--iceoryx2-global-prefix")
        .arg(ns.global_prefix())
        .arg("--iceoryx2-root-path")
        .arg(ns.root_path())
        .args(args)
        .env_remove("GHNETD_CONFIG")
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    let process = Process::spawn(&mut cmd).unwrap_or_else(|e| panic!("{e:#}"));
    let (stdout, stderr) = process.take_output();
    if let Err(e) = process.wait_exit(WATCHDOG) {
        panic!("ghnetd {args:?}: {e:#}");
    }
    let status = process.exit_status().expect("exited");
    let join = |h: std::thread::JoinHandle<Vec<u8>>| h.join().expect("pipe reader");
    Output {
        status,
        stdout: join(stdout),
        stderr: join(stderr),
    }
}

/// A running `ghnetd` (or a program with its flags, see [`GhnetdBuilder::program`]).
/// Killed and reaped on drop. Every wait on it fails at once, with the log, if the
/// daemon exits unexpectedly (e.g. it cannot load its model).
#[derive(Debug)]
pub struct Ghnetd {
    process: Process,
    ipc: IpcConfig,
    endpoint: Option<String>,
    log: PathBuf,
    dir: PathBuf,
    /// The kit's own session to the daemon, opened on first use.
    session: OnceLock<zenoh::Session>,
}

impl Ghnetd {
    /// A builder for a daemon in `ns`.
    pub fn builder(ns: &TestNamespace) -> GhnetdBuilder<'_> {
        GhnetdBuilder {
            ns,
            program: None,
            wrapper: Vec::new(),
            prefix: None,
            sources: Vec::new(),
            discovery: None,
            discovery_interval_ms: Some(50),
            model: ModelFlag::Test,
            listen: Listen::default(),
            args: Vec::new(),
            log: None,
        }
    }

    /// The process id.
    pub fn pid(&self) -> u32 {
        self.process.pid()
    }

    /// The client side of this daemon: its namespace and service prefix.
    pub fn ipc(&self) -> &IpcConfig {
        &self.ipc
    }

    /// The Zenoh endpoint the daemon listens on; panics for [`Listen::Off`].
    pub fn zenoh_endpoint(&self) -> &str {
        self.endpoint.as_deref().expect("a daemon with Zenoh")
    }

    /// A scratch directory that lives as long as the namespace (config files, …).
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The log so far.
    pub fn log(&self) -> String {
        std::fs::read_to_string(&self.log).unwrap_or_default()
    }

    /// The log file.
    pub fn log_path(&self) -> &Path {
        &self.log
    }

    /// Whether the process is still running.
    pub fn is_running(&self) -> bool {
        self.process.exit_status().is_none()
    }

    /// An error with the exit status and the end of the log once the process exited.
    pub fn check_running(&self) -> anyhow::Result<()> {
        match self.process.exit_status() {
            None => Ok(()),
            Some(status) => anyhow::bail!(
                "ghnetd exited unexpectedly ({status}); {}",
                self.log_tail(40)
            ),
        }
    }

    /// Panics with the exit status and the log if the daemon is no longer running.
    pub fn assert_running(&self) {
        if let Err(e) = self.check_running() {
            panic!("{e:#}");
        }
    }

    /// The last `lines` lines of the log, with its path.
    pub fn log_tail(&self, lines: usize) -> String {
        let log = self.log();
        let all: Vec<&str> = log.lines().collect();
        let tail = all[all.len().saturating_sub(lines)..].join("\n");
        format!("log {} (end):\n{tail}", self.log.display())
    }

    /// Polls `cond` every `poll` until it holds; fails if the daemon exits or after
    /// `timeout`. The fallible [`wait_until`](Self::wait_until), for tools.
    pub fn try_wait_until(
        &self,
        what: &str,
        timeout: Duration,
        poll: Duration,
        mut cond: impl FnMut() -> bool,
    ) -> anyhow::Result<()> {
        let mut exited = None;
        let waited = crate::poll_until(what, timeout, poll, || {
            exited = self.check_running().err();
            exited.is_some() || cond()
        });
        match exited {
            Some(e) => Err(e),
            None => waited.map_err(|e| e.context(self.log_tail(40))),
        }
    }

    /// Polls `cond` until it holds, failing on the [`WATCHDOG`] or if the daemon exits.
    pub fn wait_until(&self, what: &str, cond: impl FnMut() -> bool) {
        let poll = Duration::from_millis(5);
        if let Err(e) = self.try_wait_until(what, WATCHDOG, poll, cond) {
            panic!("watchdog: {e:#}");
        }
    }

    /// Waits until the daemon is up: its iceoryx2 node is alive and, with Zenoh, its
    /// model query answers (so its prefix lock is held and its queryables exist).
    pub fn wait_ready(&self) {
        if let Err(e) = self.try_wait_ready(WATCHDOG) {
            panic!("watchdog: {e:#}");
        }
    }

    /// The fallible [`wait_ready`](Self::wait_ready).
    pub fn try_wait_ready(&self, timeout: Duration) -> anyhow::Result<()> {
        let poll = Duration::from_millis(5);
        self.try_wait_until("iceoryx2 node", timeout, poll, || self.node_alive())?;
        if self.endpoint.is_some() {
            let session = self.try_session(timeout)?;
            let ipc = &self.ipc;
            self.try_wait_until("answer to the model query", timeout, poll, || {
                model_answers(session, ipc)
            })?;
        }
        Ok(())
    }

    /// Whether an alive iceoryx2 node of this process exists in the namespace.
    fn node_alive(&self) -> bool {
        use iceoryx2::node::NodeView;
        use iceoryx2::prelude::*;
        let mut found = false;
        let _ = Node::<ipc::Service>::list(&self.ipc.iceoryx2_config(), |state| {
            if let NodeState::Alive(v) = state {
                let pid = v.id().pid::<ipc::Service>().map(|p| p.value() as u32);
                found |= pid.is_ok_and(|p| p == self.pid());
            }
            CallbackProgression::Continue
        });
        found
    }

    /// Waits until `publisher` has a subscriber: the daemon serves its source (static
    /// sources at start-up, discovered ones within a discovery interval).
    pub fn wait_serving(&self, publisher: &VelocityPublisher) {
        let what = format!("subscriber on {}", publisher.service_name());
        self.wait_until(&what, || publisher.subscriber_count() >= 1);
    }

    /// A publisher and a heading subscriber for `source` on the daemon's prefix, once
    /// the daemon serves the publisher (static sources at once, discovered ones within
    /// a discovery interval).
    pub fn ends(&self, source: &str) -> (VelocityPublisher, HeadingSubscriber) {
        let headings = HeadingSubscriber::new(&self.ipc, source).expect("heading subscriber");
        let gnss = VelocityPublisher::new(&self.ipc, source).expect("velocity publisher");
        self.wait_serving(&gnss);
        (gnss, headings)
    }

    /// Waits until the log contains `needle` at least `count` times (for events that
    /// are log lines by design, e.g. a source's removal).
    pub fn wait_for_log_count(&self, needle: &str, count: usize) {
        let what = format!("`{needle}` {count} times in the log");
        self.wait_until(&what, || self.log().matches(needle).count() >= count);
    }

    /// Waits until the log contains `needle`.
    pub fn wait_for_log(&self, needle: &str) {
        self.wait_for_log_count(needle, 1);
    }

    /// A new Zenoh session connected to the daemon (and nothing else); returns once
    /// the connection is up.
    pub fn connect(&self) -> zenoh::Session {
        self.open_session(WATCHDOG)
            .unwrap_or_else(|e| panic!("watchdog: {e:#}"))
    }

    fn open_session(&self, timeout: Duration) -> anyhow::Result<zenoh::Session> {
        let endpoint = self.zenoh_endpoint().to_owned();
        let mut config = ghnet_client::peer_config(&[], std::slice::from_ref(&endpoint))
            .map_err(|e| anyhow::anyhow!("zenoh config for {endpoint}: {e}"))?;
        // Zenoh retries a failed connect after 1 s, 2 s, 4 s by default; the kit may
        // connect before the daemon listens.
        config
            .insert_json5(
                "connect/retry",
                r#"{period_init_ms: 20, period_max_ms: 200}"#,
            )
            .map_err(|e| anyhow::anyhow!("zenoh retry config: {e}"))?;
        let session = zenoh::open(config)
            .wait()
            .map_err(|e| anyhow::anyhow!("zenoh session to {endpoint}: {e}"))?;
        let what = format!("zenoh connection to {endpoint}");
        self.try_wait_until(&what, timeout, Duration::from_millis(5), || {
            session.info().peers_zid().wait().next().is_some()
        })?;
        Ok(session)
    }

    /// The kit's own session to the daemon (opened on first use).
    fn try_session(&self, timeout: Duration) -> anyhow::Result<&zenoh::Session> {
        if let Some(s) = self.session.get() {
            return Ok(s);
        }
        let session = self.open_session(timeout)?;
        Ok(self.session.get_or_init(|| session))
    }

    /// The daemon's answer to `<prefix>/@ghnetd/stats` (JSON: `daemon`, `sources`).
    pub fn stats(&self) -> serde_json::Value {
        self.try_stats().unwrap_or_else(|e| panic!("{e:#}"))
    }

    /// The fallible [`stats`](Self::stats).
    pub fn try_stats(&self) -> anyhow::Result<serde_json::Value> {
        let key = self.ipc.zenoh_stats_key();
        let replies = (self.try_session(WATCHDOG)?.get(key.as_str()))
            .consolidation(ConsolidationMode::None)
            .timeout(WATCHDOG)
            .wait()
            .map_err(|e| anyhow::anyhow!("query {key}: {e}"))?;
        let reply = replies
            .recv()
            .map_err(|_| anyhow::anyhow!("no answer on {key}; {}", self.log_tail(40)))?;
        let sample = reply
            .result()
            .map_err(|e| anyhow::anyhow!("{key}: error reply {e:?}"))?;
        Ok(serde_json::from_slice(&sample.payload().to_bytes())?)
    }

    /// The counters of `source` from [`stats`](Self::stats); `None` while the daemon
    /// does not list it.
    pub fn counters(&self, source: &str) -> Option<Counters> {
        let stats = self.stats();
        let object = stats["sources"][source].as_object()?;
        let numbers = object
            .iter()
            .filter_map(|(k, v)| Some((k.clone(), v.as_u64()?)));
        Some(numbers.collect())
    }

    /// Waits until the counters of `source` satisfy `cond` (ghnetd refreshes them on
    /// every wake-up of the source), and returns them.
    pub fn wait_for_counters(&self, source: &str, cond: impl Fn(&Counters) -> bool) -> Counters {
        let mut found = None;
        // 20 ms: the daemon skips a refresh while a query reads its snapshot.
        let poll = Duration::from_millis(20);
        let what = format!("matching counters for {source}");
        let result = self.try_wait_until(&what, WATCHDOG, poll, || {
            found = self.counters(source).filter(&cond);
            found.is_some()
        });
        if let Err(e) = result {
            let last = self
                .try_stats()
                .map_or_else(|e| format!("{e:#}"), |s| s.to_string());
            panic!("watchdog: {e:#}\nlast stats: {last}");
        }
        found.expect("found")
    }

    /// Sends `signal` (e.g. `libc::SIGTERM`).
    pub fn signal(&self, signal: i32) {
        if let Err(e) = self.process.signal(signal) {
            panic!("signal {signal} to ghnetd: {e:#}");
        }
    }

    /// Waits for the exit (watchdog: then SIGKILL and panic) and returns the status
    /// and the whole log.
    pub fn wait_exit(self) -> (ExitStatus, String) {
        match self.process.wait_exit(WATCHDOG) {
            Ok(status) => (status, self.log()),
            Err(e) => panic!("watchdog: ghnetd {e:#}; log:\n{}", self.log()),
        }
    }

    /// SIGTERM, then [`wait_exit`](Self::wait_exit).
    pub fn terminate(self) -> (ExitStatus, String) {
        self.signal(libc::SIGTERM);
        self.wait_exit()
    }

    /// SIGTERM; the exit must be a success (else a panic with the log). Returns the log.
    pub fn stop(self) -> String {
        let (status, log) = self.terminate();
        assert!(status.success(), "ghnetd exited with {status}; log:\n{log}");
        log
    }

    /// SIGTERM, then up to `grace` for the exit, which must be a success. The
    /// fallible [`terminate`](Self::terminate), for tools.
    pub fn try_stop(self, grace: Duration) -> anyhow::Result<ExitStatus> {
        self.process.signal(libc::SIGTERM)?;
        let status = self.process.wait_exit(grace)?;
        anyhow::ensure!(
            status.success(),
            "exited with {status}; {}",
            self.log_tail(40)
        );
        Ok(status)
    }

    /// `kill -9` and reap (so its iceoryx2 liveness lock is released, like a real
    /// crash once init reaps it). Its iceoryx2 resources stay behind.
    pub fn kill9(self) {
        self.process.kill9();
    }
}

/// The setup most tests start from: a namespace of its own, a ghnetd serving one
/// static source (discovery off), and that source's two ends on iceoryx2, connected.
///
/// Fields drop in declaration order: the ports, then the daemon, the namespace last.
/// Destructure with the namespace first (`let OneSource { ns: _ns, daemon, .. }`):
/// bindings drop in reverse.
pub struct OneSource {
    /// Publishes the source's samples; ghnetd serves it.
    pub gnss: VelocityPublisher,
    /// The source's headings.
    pub headings: HeadingSubscriber,
    /// The daemon.
    pub daemon: Ghnetd,
    /// The namespace everything lives in.
    pub ns: TestNamespace,
}

impl OneSource {
    /// Starts ghnetd for `source` (plus whatever `configure` adds to the builder) and
    /// returns once it serves the publisher.
    pub fn start(source: &str, configure: impl FnOnce(GhnetdBuilder) -> GhnetdBuilder) -> Self {
        let ns = TestNamespace::new(source);
        let builder = Ghnetd::builder(&ns).source(source).discovery(false);
        let daemon = configure(builder).start();
        let (gnss, headings) = daemon.ends(source);
        Self {
            gnss,
            headings,
            daemon,
            ns,
        }
    }
}
