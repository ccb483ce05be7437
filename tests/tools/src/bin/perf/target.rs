//! The processes under test: the real `ghnetd` binary, or this binary re-spawned as
//! the model-free echo (`perf echo`), both started by the test kit. Each runs in a
//! private iceoryx2 namespace (its own `/dev/shm` prefix and root directory) with its
//! own service prefix and Zenoh port, so a run never meets another ghnet on the
//! machine (nor port 7447).

use std::path::PathBuf;
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::Duration;

use anyhow::Context;
use ghnet_client::IpcConfig;
use ghnet_testkit::{Ghnetd, Listen, TestNamespace};

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
    process: Ghnetd,
    _ns: TestNamespace,
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
        // A prefix per target: late headings of one never reach the next one's
        // subscribers on perf's shared Zenoh session.
        let n = SPAWNS.fetch_add(1, Ordering::Relaxed);
        let prefix = match spec.kind {
            Kind::Ghnetd => format!("perfd{n}"),
            Kind::Echo => format!("perfe{n}"),
        };
        let ns = TestNamespace::new("perf");
        let prepared = prepare(&ns.ipc().with_prefix(&prefix)?)?;
        // ghnetd as deployed (its own discovery interval), on tcp like a consumer.
        let mut builder = (Ghnetd::builder(&ns).prefix(&prefix))
            .default_discovery_interval()
            .listen(Listen::Tcp);
        builder = match spec.kind {
            Kind::Ghnetd => (builder.program(&env.ghnetd, &[]))
                .model(&env.model)
                .discovery(spec.discovery)
                .arg("--max-sources")
                .arg("1024"),
            Kind::Echo => builder.program(&env.this_exe, &["echo"]).no_model_flag(),
        };
        if let Some(c) = &spec.zenoh_connect {
            builder = builder.arg("--zenoh-connect").arg(c);
        }
        let builder = spec.sources.iter().fold(builder, |b, s| b.source(s));
        let process = builder.try_spawn()?;
        let target = Self {
            kind: spec.kind,
            process,
            _ns: ns,
        };
        Ok((target, prepared))
    }

    /// Service prefix and namespace of the target.
    pub fn ipc(&self) -> &IpcConfig {
        self.process.ipc()
    }

    pub fn pid(&self) -> u32 {
        self.process.pid()
    }

    /// Fails (with the end of the log) if the process has exited.
    pub fn check_running(&self) -> anyhow::Result<()> {
        (self.process.check_running()).with_context(|| self.kind.label())
    }

    /// Polls `ready` (every 200 µs) until it holds; fails if the target exits or
    /// after `timeout`.
    pub fn wait_until(
        &self,
        what: &str,
        timeout: Duration,
        ready: impl FnMut() -> bool,
    ) -> anyhow::Result<()> {
        let poll = Duration::from_micros(200);
        (self.process.try_wait_until(what, timeout, poll, ready)).with_context(|| self.kind.label())
    }

    /// SIGTERM, then waits for a successful exit (killed after 10 s).
    pub fn stop(self) -> anyhow::Result<()> {
        let label = self.kind.label();
        self.process
            .try_stop(Duration::from_secs(10))
            .context(label)?;
        Ok(())
    }
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

/// CPU time of a process's live threads, to the nanosecond: the sum of the first field
/// of `/proc/<pid>/task/*/schedstat` (time on a CPU). For short windows of a process
/// that keeps its threads, such as the idle measurement: [`cpu_time`] counts 10 ms
/// ticks, which over 10 s is a resolution of 0.1% of a core, the size of the margin
/// of the idle target. A thread that exits takes its time with it here.
pub fn cpu_time_ns(pid: u32) -> anyhow::Result<Duration> {
    let dir = format!("/proc/{pid}/task");
    let mut ns = 0u64;
    for task in std::fs::read_dir(&dir).with_context(|| dir.clone())? {
        let path = task?.path().join("schedstat");
        // A thread that ended between the listing and the read has nothing to add.
        let Ok(stat) = std::fs::read_to_string(&path) else {
            continue;
        };
        let on_cpu = stat
            .split_whitespace()
            .next()
            .and_then(|f| f.parse::<u64>().ok());
        ns += on_cpu.with_context(|| format!("malformed {}", path.display()))?;
    }
    Ok(Duration::from_nanos(ns))
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
