//! `soak`: N sources at a fixed rate against ghnetd for a long time. Every sample must
//! get exactly one heading on iceoryx2 and on Zenoh (same value on both), and ghnetd's
//! resident memory must stay flat after a warm-up. The logic is `ghnet_tools::soak`
//! (the CI soak test runs it too). Exit status 0 = pass, 1 = loss, duplicate, mismatch
//! or memory growth, 2 = error.
//!
//! ```text
//! cargo build --release -p ghnetd -p ghnet-tools
//! # its own ghnetd (next to this binary), private namespace, Zenoh on a unix socket:
//! target/release/soak --spawn-daemon --sources 100 --rate 10 --duration 3600 --report-every 60
//! # against a running ghnetd (discovery on, sources.max_sources >= --sources):
//! target/release/soak --sources 20 --daemon-pid "$(pidof ghnetd)"
//! ```

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use anyhow::Context;
use clap::Parser;
use ghnet_client::IpcConfig;
use ghnet_testkit::{Ghnetd, TestNamespace};
use ghnet_tools::soak::{self, Options, Report};

/// Soak test: N sources × rate × duration; exactly-once on iceoryx2 and Zenoh, and
/// ghnetd's resident memory flat after the warm-up.
#[derive(Parser)]
struct Args {
    /// Service prefix: must match ghnetd's `ipc.service_prefix`.
    #[arg(long, default_value = ghnet_client::DEFAULT_PREFIX)]
    prefix: String,
    /// Number of sources, named `soak<pid>-<i>`.
    #[arg(long, default_value_t = 100)]
    sources: usize,
    /// Samples per second per source.
    #[arg(long, default_value_t = 10.0)]
    rate: f64,
    /// Seconds to publish.
    #[arg(long, default_value_t = 60.0)]
    duration: f64,
    /// Start a ghnetd of its own (`ghnetd` next to `soak`, or PATH) in a private
    /// iceoryx2 namespace, serving exactly the soak's sources, Zenoh on a unix socket;
    /// SIGTERM at the end. `GHNETD_CONFIG`, if set, is passed as its `--config`.
    #[arg(long, value_name = "PATH")]
    spawn_daemon: Option<Option<PathBuf>>,
    /// Where the spawned ghnetd logs (default: a file in the temp dir, named at start).
    #[arg(long, value_name = "FILE")]
    daemon_log: Option<PathBuf>,
    /// A running ghnetd's process id, to watch its memory (`pidof ghnetd`).
    #[arg(long, value_name = "PID", conflicts_with = "spawn_daemon")]
    daemon_pid: Option<u32>,
    /// A running ghnetd's Zenoh listen endpoint.
    #[arg(long, value_name = "ENDPOINT", conflicts_with = "spawn_daemon",
          default_value_t = format!("tcp/127.0.0.1:{}", ghnet_client::DEFAULT_ZENOH_PORT))]
    connect: String,
    /// Check iceoryx2 only (for a ghnetd with `zenoh.enabled = false`).
    #[arg(long)]
    no_zenoh: bool,
    /// Seconds of memory samples not judged; default 20% of the run, at least 10.
    #[arg(long, value_name = "S")]
    warmup: Option<f64>,
    /// Fail when ghnetd's RSS grows by this many kB or more after the warm-up.
    #[arg(long, default_value_t = 1024, value_name = "KB")]
    rss_limit_kb: u64,
    /// Seconds between progress lines (answers, RSS first/last/min/max).
    #[arg(long, default_value_t = 10.0, value_name = "S")]
    report_every: f64,
    /// Seconds to wait for the last headings after the last sample.
    #[arg(long, default_value_t = 10.0, value_name = "S")]
    drain_timeout: f64,
}

fn main() -> ExitCode {
    match run(Args::parse()) {
        Ok(true) => ExitCode::SUCCESS,
        Ok(false) => ExitCode::from(1),
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(2)
        }
    }
}

fn run(args: Args) -> anyhow::Result<bool> {
    let mut opts = options(&args)?;
    // Declared before the daemon: dropped after it is reaped.
    let ns = TestNamespace::new("soak");
    let daemon = match &args.spawn_daemon {
        Some(path) => Some(spawn_daemon(&args, path.as_ref(), &ns, &mut opts)?),
        None => {
            opts.zenoh_connect = (!args.no_zenoh).then(|| args.connect.clone());
            opts.daemon_pid = args.daemon_pid;
            None
        }
    };
    let report = soak::run(&opts).with_context(|| {
        format!(
            "soak of {} sources (a running ghnetd needs discovery on and \
             sources.max_sources >= {})",
            opts.sources, opts.sources
        )
    })?;
    print!("{report}");
    if let Some(d) = daemon {
        let warnings: Vec<String> = (d.log().lines())
            .filter(|l| l.contains(" WARN ") || l.contains(" ERROR "))
            .map(|l| format!("ghnetd: {l}\n"))
            .collect();
        print!("{}", warnings.concat());
        println!("ghnetd exited: {}", d.try_stop(Duration::from_secs(10))?);
    }
    print_verdict(&report);
    Ok(report.failures().is_empty())
}

fn options(args: &Args) -> anyhow::Result<Options> {
    let seconds = |s: f64, what: &str| {
        Duration::try_from_secs_f64(s).with_context(|| format!("{what}: {s} is not a duration"))
    };
    let ipc = IpcConfig::new(&args.prefix).context("--prefix")?;
    let mut opts = Options::new(ipc, &format!("soak{}", std::process::id()));
    opts.sources = args.sources;
    opts.rate_hz = args.rate;
    opts.duration = seconds(args.duration, "--duration")?;
    opts.warmup = args.warmup.map(|w| seconds(w, "--warmup")).transpose()?;
    opts.rss_limit_kb = args.rss_limit_kb;
    opts.report_every = seconds(args.report_every, "--report-every")?;
    opts.drain_timeout = seconds(args.drain_timeout, "--drain-timeout")?;
    Ok(opts)
}

/// A ghnetd for the soak in `ns`; points `opts` at it.
fn spawn_daemon(
    args: &Args,
    path: Option<&PathBuf>,
    ns: &TestNamespace,
    opts: &mut Options,
) -> anyhow::Result<Ghnetd> {
    let log = (args.daemon_log.clone()).unwrap_or_else(|| {
        std::env::temp_dir().join(format!("ghnet-soak-{}-ghnetd.log", std::process::id()))
    });
    let mut builder = (opts.daemon(ns).default_discovery_interval())
        .no_model_flag()
        .log_file(&log);
    if let Some(p) = path {
        builder = builder.program(p, &[]);
    }
    if let Some(config) = std::env::var_os("GHNETD_CONFIG") {
        builder = builder.arg("--config").arg(config);
    }
    let d = builder.try_spawn()?;
    d.try_wait_ready(opts.patience)?;
    println!("ghnetd (pid {}), log {}", d.pid(), log.display());
    opts.ipc = d.ipc().clone();
    opts.zenoh_connect = (!args.no_zenoh).then(|| d.zenoh_endpoint().to_owned());
    opts.daemon_pid = Some(d.pid());
    Ok(d)
}

fn print_verdict(report: &Report) {
    let failures = report.failures();
    let interrupted = if report.interrupted {
        format!(
            " (interrupted: {} of {} samples per source)",
            report.sent,
            report.planned()
        )
    } else {
        String::new()
    };
    if failures.is_empty() {
        let zenoh = if report.zenoh_checked() {
            " and Zenoh"
        } else {
            ""
        };
        println!("PASS: every sample answered exactly once on iceoryx2{zenoh}{interrupted}");
    } else {
        println!("FAIL{interrupted}: {}", failures.join("; "));
    }
}
