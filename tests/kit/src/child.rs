//! Processes of the kit: the handle every spawned process lives in (`Process`:
//! dies with the test, killed and reaped on drop), the child publisher and
//! subscriber (the kit's bins) that tests `kill -9`, and the Zenoh router of the fleet
//! tests ([`ChildRouter`]).

use std::ffi::OsStr;
use std::io::Read;
use std::os::unix::process::CommandExt;
use std::process::{Child, ChildStdout, Command, ExitStatus, Stdio};
use std::sync::mpsc;
use std::sync::{Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use crate::{find_binary, TestNamespace, WATCHDOG};

/// A spawned process: dies with the thread that spawned it (`PR_SET_PDEATHSIG`), is
/// killed and reaped on drop (an unreaped zombie keeps its iceoryx2 liveness lock).
/// Behind a mutex, so that waits from helper threads can check liveness.
#[derive(Debug)]
pub(crate) struct Process {
    child: Mutex<Child>,
    pid: u32,
}

impl Process {
    /// Spawns `cmd` (stdin closed unless the caller set it).
    pub(crate) fn spawn(cmd: &mut Command) -> anyhow::Result<Self> {
        // SAFETY: only an async-signal-safe syscall between fork and exec.
        unsafe {
            cmd.pre_exec(|| {
                libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGKILL);
                Ok(())
            });
        }
        let child = cmd
            .spawn()
            .map_err(|e| anyhow::anyhow!("cannot start {:?}: {e}", cmd.get_program()))?;
        Ok(Self {
            pid: child.id(),
            child: Mutex::new(child),
        })
    }

    fn child(&self) -> MutexGuard<'_, Child> {
        // A panicking test thread may poison it; the child is still valid.
        self.child.lock().unwrap_or_else(|e| e.into_inner())
    }

    pub(crate) fn pid(&self) -> u32 {
        self.pid
    }

    /// `None` while it runs; its exit status once it has exited (reaped then).
    pub(crate) fn exit_status(&self) -> Option<ExitStatus> {
        self.child().try_wait().expect("try_wait")
    }

    pub(crate) fn take_stdout(&self) -> Option<ChildStdout> {
        self.child().stdout.take()
    }

    /// Readers of the piped stdout and stderr, each to its end (so that a full pipe
    /// never blocks the process).
    pub(crate) fn take_output(&self) -> (JoinHandle<Vec<u8>>, JoinHandle<Vec<u8>>) {
        fn read_all(mut pipe: Option<impl Read + Send + 'static>) -> JoinHandle<Vec<u8>> {
            std::thread::spawn(move || {
                let mut bytes = Vec::new();
                if let Some(p) = pipe.as_mut() {
                    let _ = p.read_to_end(&mut bytes);
                }
                bytes
            })
        }
        let mut child = self.child();
        (read_all(child.stdout.take()), read_all(child.stderr.take()))
    }

    /// Sends `signal`; an error once the process has been reaped.
    pub(crate) fn signal(&self, signal: i32) -> anyhow::Result<()> {
        // Held across kill(2): nobody reaps the child meanwhile, so its pid is not
        // reused by another process.
        let mut child = self.child();
        anyhow::ensure!(child.try_wait()?.is_none(), "already exited");
        // SAFETY: kill(2) on our own child, not yet reaped.
        let rc = unsafe { libc::kill(self.pid as libc::pid_t, signal) };
        anyhow::ensure!(rc == 0, "kill({}, {signal}) failed", self.pid);
        Ok(())
    }

    /// `kill -9` and reap, like a crash that init reaps.
    pub(crate) fn kill9(&self) {
        let mut child = self.child();
        let _ = child.kill();
        child.wait().expect("reap");
    }

    /// Waits up to `timeout` for the exit; then kills it and fails.
    pub(crate) fn wait_exit(&self, timeout: Duration) -> anyhow::Result<ExitStatus> {
        let t0 = Instant::now();
        loop {
            if let Some(status) = self.exit_status() {
                return Ok(status);
            }
            if t0.elapsed() > timeout {
                self.kill9();
                anyhow::bail!("still running {timeout:?} after being asked to stop; killed");
            }
            std::thread::sleep(Duration::from_millis(5));
        }
    }
}

impl Drop for Process {
    fn drop(&mut self) {
        let child = self.child.get_mut().unwrap_or_else(|e| e.into_inner());
        let _ = child.kill();
        let _ = child.wait();
    }
}

/// A kit binary by name, or a panic saying how to build it.
fn kit_binary(name: &str) -> std::path::PathBuf {
    find_binary(name).unwrap_or_else(|e| panic!("{e:#}"))
}

/// `program` run under `wrapper`, a command that execs its arguments (e.g. `["ip",
/// "netns", "exec", "<name>"]`); `program` alone for an empty wrapper.
pub(crate) fn wrapped(wrapper: &[impl AsRef<OsStr>], program: impl AsRef<OsStr>) -> Command {
    match wrapper.split_first() {
        Some((w, rest)) => {
            let mut c = Command::new(w);
            c.args(rest).arg(program);
            c
        }
        None => Command::new(program),
    }
}

/// Spawns a kit bin that prints `ready` once it is set up, then lines of its own;
/// returns once `ready` came, with a channel of the lines after it.
fn spawn_ready(wrapper: &[&str], bin: &str, args: &[&str]) -> (Process, mpsc::Receiver<String>) {
    let mut cmd = wrapped(wrapper, kit_binary(bin));
    cmd.args(args).stdin(Stdio::null()).stdout(Stdio::piped());
    let process = Process::spawn(&mut cmd).unwrap_or_else(|e| panic!("{e:#}"));
    let stdout = process.take_stdout().expect("piped stdout");
    let (tx, lines) = mpsc::channel();
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
    let first = lines.recv_timeout(WATCHDOG).ok();
    assert_eq!(first.as_deref(), Some("ready"), "{bin} start");
    (process, lines)
}

/// A `ghnet-test-publisher` process: sends `VelocitySample`s for one source (v_north 3,
/// v_east 4, speed accuracy 0.1, seq from `first_seq` up, real timestamps) at a fixed
/// rate until killed. Killed and reaped on drop.
#[derive(Debug)]
pub struct ChildPublisher {
    process: Process,
}

impl ChildPublisher {
    /// Starts publishing `source` in `ns`.
    pub fn spawn(ns: &TestNamespace, source: &str, first_seq: u64, rate_hz: u32) -> Self {
        Self::spawn_wrapped(&[], ns, None, source, first_seq, rate_hz)
    }

    /// [`spawn`](Self::spawn) under `wrapper` (e.g. [`NetNamespace::exec`]: a
    /// vehicle's receiver on the vehicle's "host"; iceoryx2 itself does not see network
    /// namespaces), for a daemon with `service_prefix` (`None`: the default).
    ///
    /// [`NetNamespace::exec`]: crate::NetNamespace::exec
    pub fn spawn_wrapped(
        wrapper: &[&str],
        ns: &TestNamespace,
        service_prefix: Option<&str>,
        source: &str,
        first_seq: u64,
        rate_hz: u32,
    ) -> Self {
        let mut cmd = wrapped(wrapper, kit_binary("ghnet-test-publisher"));
        cmd.arg(ns.global_prefix())
            .arg(ns.root_path())
            .args([source, &first_seq.to_string(), &rate_hz.to_string()])
            .args(service_prefix)
            .stdin(Stdio::null())
            .stdout(Stdio::null());
        let process = Process::spawn(&mut cmd).unwrap_or_else(|e| panic!("{e:#}"));
        Self { process }
    }

    /// Whether it is still running.
    pub fn is_running(&self) -> bool {
        self.process.exit_status().is_none()
    }

    /// `kill -9` and reap.
    pub fn kill9(self) {
        self.process.kill9();
    }
}

/// One heading as a [`ChildSubscriber`] printed it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Heading {
    /// Echoed sequence number.
    pub seq: u64,
    /// The wire status (`HeadingStatus::as_u32`).
    pub status: u32,
    /// The 64 bytes of the heading (`encode_zenoh`, the same as `to_le_bytes`) in hex.
    pub hex: String,
}

/// A `ghnet-test-subscriber` process: a heading consumer for one source in another
/// process (on iceoryx2, or on Zenoh from another network namespace). It prints
/// `ready` once subscribed, then `<seq> <status> <hex>` per heading; the lines arrive
/// on a channel. Killed and reaped on drop.
#[derive(Debug)]
pub struct ChildSubscriber {
    process: Process,
    lines: mpsc::Receiver<String>,
}

impl ChildSubscriber {
    /// An iceoryx2 `HeadingSubscriber` for `source` in `ns`; returns once it is
    /// subscribed.
    pub fn spawn(ns: &TestNamespace, source: &str) -> Self {
        let root = ns.root_path().to_string_lossy();
        Self::start(&[], &["iceoryx2", ns.global_prefix(), &root, source])
    }

    /// A Zenoh subscriber on `<prefix>/<source>/heading`, connected to `endpoint`,
    /// run under `wrapper` (e.g. `["ip", "netns", "exec", "<name>"]`); returns once
    /// the daemon behind `endpoint` knows the subscription.
    pub fn zenoh(wrapper: &[&str], endpoint: &str, prefix: &str, source: &str) -> Self {
        Self::start(wrapper, &["zenoh", endpoint, prefix, source])
    }

    fn start(wrapper: &[&str], args: &[&str]) -> Self {
        let (process, lines) = spawn_ready(wrapper, "ghnet-test-subscriber", args);
        Self { process, lines }
    }

    /// The next heading, `None` if the process ended or [`WATCHDOG`] passed.
    pub fn next(&self) -> Option<Heading> {
        let line = self.lines.recv_timeout(WATCHDOG).ok()?;
        let mut fields = line.split(' ');
        let mut field = || {
            fields
                .next()
                .unwrap_or_else(|| panic!("short line `{line}`"))
        };
        Some(Heading {
            seq: field().parse().expect("seq"),
            status: field().parse().expect("status"),
            hex: field().to_owned(),
        })
    }

    /// Reads headings until one with `seq >= min_seq` that is not `Stale`; returns its
    /// seq. Panics if the process ends or the watchdog fires first.
    pub fn answer_at_least(&self, min_seq: u64) -> u64 {
        let stale = ghnet_client::HeadingStatus::Stale.as_u32();
        loop {
            let h = self
                .next()
                .unwrap_or_else(|| panic!("test subscriber: no heading with seq >= {min_seq}"));
            if h.seq >= min_seq && h.status != stale {
                return h.seq;
            }
        }
    }

    /// `kill -9` and reap.
    pub fn kill9(self) {
        self.process.kill9();
    }
}

/// A `ghnet-test-router` process: a Zenoh router (the zenoh crate in router mode, as
/// `zenohd` runs it, no scouting) listening on the endpoints given, until killed. A
/// process rather than a session in the test, so that it can run in a network
/// namespace of its own and be killed like a real router. Killed and reaped on drop.
#[derive(Debug)]
pub struct ChildRouter {
    process: Process,
}

impl ChildRouter {
    /// Starts a router listening on `endpoints`, under `wrapper` (e.g.
    /// [`NetNamespace::exec`](crate::NetNamespace::exec)); returns once it listens.
    pub fn spawn(wrapper: &[&str], endpoints: &[&str]) -> Self {
        let (process, _lines) = spawn_ready(wrapper, "ghnet-test-router", endpoints);
        Self { process }
    }

    /// Whether it is still running.
    pub fn is_running(&self) -> bool {
        self.process.exit_status().is_none()
    }

    /// `kill -9` and reap: the router crashes, its connections drop.
    pub fn kill9(self) {
        self.process.kill9();
    }
}
