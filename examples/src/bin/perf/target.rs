//! The processes under test: the real `ghnetd` binary, or this binary re-spawned as
//! the model-free echo (`--role echo`). Each runs in a private iceoryx2 namespace
//! (its own `/dev/shm` prefix and root directory) with its own service prefix and
//! Zenoh port, so a run never meets another ghnet on the machine (nor port 7447).

use std::fs::File;
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::{Duration, Instant};

use anyhow::Context;
use ghnet_client::testing::TestNamespace;
use ghnet_client::IpcConfig;

/// Which program answers the samples.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// The real daemon: validation, model, status, counters, both outputs.
    Ghnetd,
    /// The same transport path without any of that: the raw baseline.
    Echo,
}

impl Kind {
    pub fn label(self) -> &'static str {
        match self {
            Kind::Ghnetd => "ghnetd",
            Kind::Echo => "raw echo",
        }
    }
}

/// How to start a target.
#[derive(Debug, Clone)]
pub struct Spec {
    pub kind: Kind,
    /// Sources served from the start (static sources for ghnetd).
    pub sources: Vec<String>,
    /// ghnetd only: also discover sources (the deployed default).
    pub discovery: bool,
    /// Zenoh endpoint of the perf process's session the target connects to; `None`
    /// for a target that only listens.
    pub zenoh_connect: Option<String>,
}

/// Paths and options shared by every spawn.
#[derive(Debug, Clone)]
pub struct Env {
    pub ghnetd: PathBuf,
    pub this_exe: PathBuf,
    pub model: String,
}

static SPAWNS: AtomicU32 = AtomicU32::new(0);

/// A running target. Dropping it kills and reaps the process, then removes its
/// namespace (in that order: an unreaped process keeps its iceoryx2 locks).
pub struct Target {
    pub kind: Kind,
    pub ipc: IpcConfig,
    child: Option<Child>,
    log: PathBuf,
    // Dropped after the child is reaped (see Drop).
    _ns: TestNamespace,
}

/// A free TCP port on loopback (the kernel picks; it is free again a moment later
/// for whoever binds it next, which is the target).
pub fn free_port() -> anyhow::Result<u16> {
    let l = std::net::TcpListener::bind("127.0.0.1:0").context("bind 127.0.0.1:0")?;
    Ok(l.local_addr()?.port())
}

impl Target {
    /// Starts the target and returns at once (see [`Target::wait_until`]).
    pub fn spawn(env: &Env, spec: &Spec) -> anyhow::Result<Self> {
        Ok(Self::spawn_with(env, spec, |_| Ok(()))?.0)
    }

    /// Like [`spawn`](Self::spawn), but first calls `prepare` with the target's
    /// [`IpcConfig`] (e.g. to open ports before the process exists, for timing).
    pub fn spawn_with<R>(
        env: &Env,
        spec: &Spec,
        prepare: impl FnOnce(&IpcConfig) -> anyhow::Result<R>,
    ) -> anyhow::Result<(Self, R)> {
        let n = SPAWNS.fetch_add(1, Ordering::Relaxed);
        let ns = TestNamespace::new(&format!("perf{n}"));
        let prefix = match spec.kind {
            Kind::Ghnetd => format!("perfd{n}"),
            Kind::Echo => format!("perfe{n}"),
        };
        let ipc = ns.ipc().with_prefix(&prefix)?;
        let listen = format!("tcp/127.0.0.1:{}", free_port()?);
        let log = std::env::temp_dir().join(format!("ghnet-perf-{}-{n}.log", std::process::id()));
        let prepared = prepare(&ipc)?;

        let mut cmd = match spec.kind {
            Kind::Ghnetd => {
                let mut c = Command::new(&env.ghnetd);
                c.args(["--model", &env.model])
                    .args(["--discovery", if spec.discovery { "true" } else { "false" }])
                    .args(["--max-sources", "1024"])
                    .arg("--iceoryx2-global-prefix")
                    .arg(ns.global_prefix())
                    .arg("--iceoryx2-root-path")
                    .arg(ns.root_path())
                    .env_remove("GHNETD_CONFIG")
                    .env_remove("RUST_LOG"); // ghnetd's default: info
                c
            }
            Kind::Echo => {
                let mut c = Command::new(&env.this_exe);
                c.args(["--role", "echo"])
                    .arg("--global-prefix")
                    .arg(ns.global_prefix())
                    .arg("--root")
                    .arg(ns.root_path());
                c
            }
        };
        cmd.args(["--service-prefix", &prefix])
            .args(["--zenoh-listen", &listen]);
        if let Some(c) = &spec.zenoh_connect {
            cmd.args(["--zenoh-connect", c]);
        }
        for s in &spec.sources {
            cmd.args(["--source", s]);
        }
        cmd.stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(File::create(&log).context("log file")?);
        // SAFETY: only an async-signal-safe syscall between fork and exec. The child
        // dies with us if perf is killed, instead of holding shared memory forever.
        unsafe {
            cmd.pre_exec(|| {
                libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGKILL);
                Ok(())
            });
        }
        let child = cmd
            .spawn()
            .with_context(|| format!("cannot start {:?}", cmd.get_program()))?;
        let target = Self {
            kind: spec.kind,
            ipc,
            child: Some(child),
            log,
            _ns: ns,
        };
        Ok((target, prepared))
    }

    pub fn pid(&self) -> u32 {
        self.child.as_ref().map_or(0, |c| c.id())
    }

    /// Fails (with the end of the log) if the process has exited.
    pub fn check_running(&mut self) -> anyhow::Result<()> {
        let child = self.child.as_mut().expect("child until drop");
        if let Some(status) = child.try_wait()? {
            anyhow::bail!(
                "{} exited ({status}); log {}:\n{}",
                self.kind.label(),
                self.log.display(),
                tail(&self.log, 20)
            );
        }
        Ok(())
    }

    /// Polls `ready` (every 200 µs) until it holds; fails if the target exits or
    /// after `timeout`.
    pub fn wait_until(
        &mut self,
        what: &str,
        timeout: Duration,
        mut ready: impl FnMut() -> bool,
    ) -> anyhow::Result<()> {
        let t0 = Instant::now();
        while !ready() {
            self.check_running()?;
            anyhow::ensure!(
                t0.elapsed() < timeout,
                "{}: no {what} within {timeout:?}; log:\n{}",
                self.kind.label(),
                tail(&self.log, 20)
            );
            std::thread::sleep(Duration::from_micros(200));
        }
        Ok(())
    }

    /// SIGTERM, then waits for the exit (killed after 10 s).
    pub fn stop(mut self) -> anyhow::Result<()> {
        let mut child = self.child.take().expect("child until drop");
        // SAFETY: kill(2) on our own child, not yet reaped, so its pid is not reused.
        unsafe { libc::kill(child.id() as libc::pid_t, libc::SIGTERM) };
        let t0 = Instant::now();
        while t0.elapsed() < Duration::from_secs(10) {
            if let Some(status) = child.try_wait()? {
                anyhow::ensure!(
                    status.success(),
                    "{} exited with {status}; log:\n{}",
                    self.kind.label(),
                    tail(&self.log, 20)
                );
                let _ = std::fs::remove_file(&self.log);
                return Ok(());
            }
            std::thread::sleep(Duration::from_millis(5));
        }
        let _ = child.kill();
        let _ = child.wait();
        anyhow::bail!("{} ignored SIGTERM for 10 s", self.kind.label())
    }
}

impl Drop for Target {
    fn drop(&mut self) {
        if let Some(mut child) = self.child.take() {
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}

fn tail(path: &Path, lines: usize) -> String {
    let text = std::fs::read_to_string(path).unwrap_or_default();
    let all: Vec<&str> = text.lines().collect();
    all[all.len().saturating_sub(lines)..].join("\n")
}

/// CPU time (user + system) a process has used so far, from `/proc/<pid>/stat`.
pub fn cpu_time(pid: u32) -> anyhow::Result<Duration> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat"))
        .with_context(|| format!("/proc/{pid}/stat"))?;
    // The command name (field 2) may contain spaces; fields after it are plain.
    let rest = stat
        .rsplit_once(')')
        .map(|(_, r)| r)
        .context("malformed /proc/<pid>/stat")?;
    let fields: Vec<&str> = rest.split_whitespace().collect();
    // After ")": state is field 3, so utime (14) and stime (15) are at 11 and 12.
    let ticks: u64 = fields
        .get(11..13)
        .context("short /proc/<pid>/stat")?
        .iter()
        .map(|f| f.parse::<u64>().unwrap_or(0))
        .sum();
    // SAFETY: sysconf has no preconditions.
    let hz = unsafe { libc::sysconf(libc::_SC_CLK_TCK) }.max(1) as u64;
    Ok(Duration::from_nanos(ticks * 1_000_000_000 / hz))
}

/// Resident memory of a process, from `/proc/<pid>/status`, in KiB.
#[derive(Debug, Clone, Copy, Default)]
pub struct Rss {
    /// `VmRSS`: everything resident (anonymous + file + shared memory).
    pub total_kib: u64,
    /// `RssAnon`: the process's own heap and stacks.
    pub anon_kib: u64,
    /// `RssShmem`: iceoryx2 shared-memory pages this process touched.
    pub shmem_kib: u64,
    /// `VmHWM`: peak resident.
    pub peak_kib: u64,
}

impl Rss {
    pub fn of(pid: u32) -> anyhow::Result<Self> {
        let status = std::fs::read_to_string(format!("/proc/{pid}/status"))
            .with_context(|| format!("/proc/{pid}/status"))?;
        let field = |name: &str| -> u64 {
            status
                .lines()
                .find_map(|l| l.strip_prefix(name))
                .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
                .unwrap_or(0)
        };
        Ok(Self {
            total_kib: field("VmRSS:"),
            anon_kib: field("RssAnon:"),
            shmem_kib: field("RssShmem:"),
            peak_kib: field("VmHWM:"),
        })
    }

    pub fn total_mib(&self) -> f64 {
        self.total_kib as f64 / 1024.0
    }
}
