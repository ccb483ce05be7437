//! `soak`: N sources at a fixed rate against ghnetd for a long time. Every sample must
//! get exactly one heading on iceoryx2 and on Zenoh (same value on both), and ghnetd's
//! resident memory must stay flat after a warm-up.
//!
//! Teaches: the exactly-once contract (`seq` is echoed; `Stale` status messages answer
//! no sample), one `WaitSet` for many heading subscribers, and how to watch a daemon's
//! memory. The logic is `ghnet_examples::soak` (the CI soak test runs it too).
//! Exit status 0 = pass, 1 = loss, duplicate, mismatch or memory growth, 2 = error.
//!
//! ```text
//! cargo build --release -p ghnetd -p ghnet-examples
//! # its own ghnetd (next to this binary), private namespace, Zenoh on a free port:
//! target/release/soak --spawn-daemon --sources 100 --rate 10 --duration 3600 --report-every 60
//! # against a running ghnetd (discovery on, sources.max_sources >= --sources):
//! target/release/soak --sources 20 --daemon-pid "$(pidof ghnetd)"
//! ```

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use anyhow::Context;
use clap::Parser;
use ghnet_examples::soak::{self, ghnetd_next_to_exe, Options, SpawnedGhnetd};
use ghnet_examples::CommonArgs;

/// Soak test: N sources × rate × duration; exactly-once on iceoryx2 and Zenoh, and
/// ghnetd's resident memory flat after the warm-up.
#[derive(Parser)]
struct Args {
    #[command(flatten)]
    common: CommonArgs,
    /// Number of sources, named `soak<pid>-<i>`.
    #[arg(long, default_value_t = 100)]
    sources: usize,
    /// Samples per second per source.
    #[arg(long, default_value_t = 10.0)]
    rate: f64,
    /// Seconds to publish.
    #[arg(long, default_value_t = 60.0)]
    duration: f64,
    /// Start a ghnetd of its own (this binary, or `ghnetd` next to `soak`) in a private
    /// iceoryx2 namespace, serving exactly the soak's sources, Zenoh on a free
    /// loopback port; SIGTERM at the end. It reads `GHNETD_CONFIG` (e.g. the model).
    #[arg(long, value_name = "PATH")]
    spawn_daemon: Option<Option<PathBuf>>,
    /// Where the spawned ghnetd logs (default: a file in the temp dir, named at start).
    #[arg(long, value_name = "FILE")]
    daemon_log: Option<PathBuf>,
    /// Seconds between the spawned ghnetd's per-source counter lines.
    #[arg(long, default_value_t = 60, value_name = "S")]
    daemon_stats_interval: u64,
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

fn seconds(s: f64, what: &str) -> anyhow::Result<Duration> {
    Duration::try_from_secs_f64(s).with_context(|| format!("{what}: {s} is not a duration"))
}

fn run(args: Args) -> anyhow::Result<bool> {
    let prefix = &args.common.prefix;
    let mut opts = Options::new(args.common.ipc()?, &format!("soak{}", std::process::id()));
    opts.sources = args.sources;
    opts.rate_hz = args.rate;
    opts.duration = seconds(args.duration, "--duration")?;
    opts.warmup = args.warmup.map(|w| seconds(w, "--warmup")).transpose()?;
    opts.rss_limit_kb = args.rss_limit_kb;
    opts.report_every = seconds(args.report_every, "--report-every")?;
    opts.drain_timeout = seconds(args.drain_timeout, "--drain-timeout")?;
    anyhow::ensure!(
        args.rate > 0.0 && args.rate.is_finite(),
        "--rate must be > 0"
    );

    let daemon = match &args.spawn_daemon {
        Some(path) => {
            let bin = match path {
                Some(p) => p.clone(),
                None => ghnetd_next_to_exe().context(
                    "no ghnetd next to this binary: `cargo build --release -p ghnetd` \
                     or pass --spawn-daemon PATH",
                )?,
            };
            let log = (args.daemon_log.clone()).unwrap_or_else(|| {
                std::env::temp_dir().join(format!("ghnet-soak-{}-ghnetd.log", std::process::id()))
            });
            let d = SpawnedGhnetd::start(
                &bin,
                prefix,
                &opts.daemon_sources(),
                args.daemon_stats_interval,
                &log,
                opts.patience,
            )?;
            println!(
                "ghnetd {} (pid {}), log {}",
                bin.display(),
                d.pid(),
                log.display()
            );
            opts.ipc = d.ipc(prefix)?;
            opts.zenoh_connect = (!args.no_zenoh).then(|| d.zenoh_endpoint().to_owned());
            opts.daemon_pid = Some(d.pid());
            Some(d)
        }
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
        println!("ghnetd exited: {}", d.stop(Duration::from_secs(10))?);
    }
    let failures = report.failures();
    let interrupted = if report.interrupted {
        format!(
            " (interrupted: {} of {} samples per source)",
            report.sent, report.planned
        )
    } else {
        String::new()
    };
    if failures.is_empty() {
        let zenoh = if report.zenoh_checked {
            " and Zenoh"
        } else {
            ""
        };
        println!("PASS: every sample answered exactly once on iceoryx2{zenoh}{interrupted}");
    } else {
        println!("FAIL{interrupted}: {}", failures.join("; "));
    }
    Ok(failures.is_empty())
}
