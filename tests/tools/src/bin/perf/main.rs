//! `perf`: the daemon-level benchmark in one run — latency, throughput,
//! footprint and allocations of the real `ghnetd`, each beside the raw transport
//! doing the same hops without a model, printed as one Markdown table.
//!
//! How it measures fairly: the baseline is this binary re-spawned as `perf echo`
//! (same process layout, same WaitSet wake-up, same iceoryx2 + Zenoh outputs, no
//! model), the model cost is measured in the same run with `ghnet_inference::Predictor`,
//! and every target lives in a private iceoryx2 namespace on its own Zenoh port
//! (started by the test kit), so nothing else on the machine is touched.
//!
//! ```text
//! cargo build --release -p ghnetd -p ghnet-tools
//! target/release/perf            # full run, about 2-3 min
//! target/release/perf --quick    # about 1 min, fewer samples
//! target/release/perf --only ros2 # the ROS 2 bridge (root, ip, python3 + ROS 2 wheels;
//!                                 # cargo build --release -p ghnet-ros2 -p ghnet-testkit first)
//! ```
//!
//! `ghnetd` is taken from next to this executable (`GHNETD_BIN` or `--ghnetd`
//! override). Progress goes to stderr, the table to stdout. Exit status 0 = every
//! target met, 1 = a target missed, 2 = error.
//!
//! # Layout
//!
//! - `main.rs` — arguments, the phases in order, the report.
//! - `inference` — the model alone; `latency`, `throughput`, `footprint`, `alloc` —
//!   one phase each, its measurement and its rows of the table; `ros2` — the ROS 2
//!   bridge, only with `--only ros2`.
//! - `target` — the processes under test (ghnetd or the echo) on the test kit.
//! - `echo` — `perf echo`, the raw transport baseline.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::{Duration, Instant};

use anyhow::Context;
use clap::{Parser, Subcommand};
use ghnet_client::zenoh::{self, Wait};
use ghnet_inference::DEFAULT_MODEL;

mod alloc;
mod echo;
mod footprint;
mod inference;
mod latency;
mod ros2;
mod target;
mod throughput;

use target::Env;
use throughput::Notify;

#[derive(Parser)]
#[command(args_conflicts_with_subcommands = true)]
struct Cli {
    #[command(subcommand)]
    role: Option<Role>,
    #[command(flatten)]
    args: Args,
}

/// The roles perf spawns itself in.
#[derive(Subcommand)]
enum Role {
    /// The raw transport baseline (spawned by perf itself).
    #[command(hide = true)]
    Echo(echo::EchoArgs),
}

/// Daemon latency, throughput and footprint against the raw transport, one table.
#[derive(clap::Args)]
struct Args {
    /// Measured round trips per latency pass (four passes: iceoryx2 and Zenoh
    /// output, raw echo and ghnetd; echo and ghnetd take turns in blocks of 5,000).
    #[arg(long, default_value_t = 100_000)]
    samples: u64,
    /// Unmeasured round trips before each latency pass (and 200 at the start of
    /// every later block).
    #[arg(long, default_value_t = 2_000)]
    warmup_samples: u64,
    /// Seconds of the throughput measurement window (after 1 s of warm-up).
    #[arg(long, default_value_t = 10.0)]
    throughput_seconds: f64,
    /// Sources publishing at once in the throughput test.
    #[arg(long, default_value_t = 100)]
    sources: usize,
    /// Unanswered samples allowed per source (the subscriber buffers hold 128).
    #[arg(long, default_value_t = 64)]
    in_flight: u64,
    /// How throughput publishers wake the target.
    #[arg(long, value_enum, default_value = "sample")]
    notify: Notify,
    /// Seconds of the idle-CPU window.
    #[arg(long, default_value_t = 10.0)]
    idle_seconds: f64,
    /// Connected, silent sources during the idle-CPU window.
    #[arg(long, default_value_t = 10)]
    idle_sources: usize,
    /// ghnetd starts for the start-to-ready figure.
    #[arg(long, default_value_t = 5)]
    ready_runs: usize,
    /// About one minute: 20,000 samples per latency pass, 3 s throughput, 5 s idle,
    /// 3 starts (overrides those options).
    #[arg(long)]
    quick: bool,
    /// Run only these phases (comma-separated; default all). The model-alone rows
    /// are always measured.
    #[arg(long, value_enum, value_delimiter = ',')]
    only: Vec<Phase>,
    /// Model for ghnetd and the inference timing (built-in name or .safetensors).
    #[arg(long, default_value = DEFAULT_MODEL)]
    model: String,
    /// Seconds of the ROS 2 bridge's measured window (`--only ros2`).
    #[arg(long, default_value_t = 30.0)]
    ros2_seconds: f64,
    /// Sources at 10 Hz each through the ROS 2 bridge (`--only ros2`).
    #[arg(long, default_value_t = 10)]
    ros2_sources: usize,
    /// The ghnetd binary; default: `ghnetd` next to this executable.
    #[arg(long, env = "GHNETD_BIN", value_name = "PATH")]
    ghnetd: Option<PathBuf>,
}

/// The parts of the run, for `--only`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum Phase {
    /// Four latency passes: raw echo and ghnetd, iceoryx2 and Zenoh output; echo
    /// and ghnetd run side by side and take turns block by block.
    Latency,
    /// Throughput with all sources, and resident memory before and after.
    Throughput,
    /// Idle CPU and start-to-ready.
    Footprint,
    /// Allocations per sample on the daemon thread.
    Alloc,
    /// The ROS 2 bridge: added latency, CPU, memory (only when asked for: needs root,
    /// `ip`, `ghnet-ros2` and python3 with the ROS 2 wheels).
    Ros2,
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    // iceoryx2's logger would print a warning about its config file per start.
    ghnet_client::iceoryx2::prelude::set_log_level_from_env_or(
        ghnet_client::iceoryx2::prelude::LogLevel::Error,
    );
    let result = match cli.role {
        Some(Role::Echo(echo)) => echo::run(echo).map(|()| true),
        None => run(&cli.args.quick_or_full()),
    };
    match result {
        Ok(true) => ExitCode::SUCCESS,
        Ok(false) => ExitCode::from(1),
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(2)
        }
    }
}

impl Args {
    /// `--quick` applied.
    fn quick_or_full(mut self) -> Self {
        if self.quick {
            self.samples = 20_000;
            self.warmup_samples = 1_000;
            self.throughput_seconds = 3.0;
            self.idle_seconds = 5.0;
            self.ready_runs = 3;
        }
        self
    }
}

/// One row of the result table.
struct Row {
    metric: String,
    raw: String,
    ghnetd: String,
    target: String,
    pass: Option<bool>,
}

fn row(metric: &str, raw: String, ghnetd: String, target: String, pass: Option<bool>) -> Row {
    Row {
        metric: metric.to_owned(),
        raw,
        ghnetd,
        target,
        pass,
    }
}

/// A row that only informs: no target, no verdict.
fn info(metric: &str, raw: String, ghnetd: String) -> Row {
    row(metric, raw, ghnetd, "–".into(), None)
}

fn us(d: Duration) -> String {
    format!("{:.1} µs", d.as_nanos() as f64 / 1000.0)
}

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1000.0
}

fn run(args: &Args) -> anyhow::Result<bool> {
    let this_exe = std::env::current_exe().context("path of this executable")?;
    let ghnetd = match &args.ghnetd {
        Some(p) => p.clone(),
        None => ghnet_testkit::find_binary("ghnetd")?,
    };
    let env = Env {
        ghnetd: ghnetd.clone(),
        this_exe,
        model: args.model.clone(),
    };
    let started = Instant::now();
    eprintln!("perf: ghnetd = {}", ghnetd.display());

    // The targets connect to this session (so no wait for Zenoh's connect retries).
    let endpoint = format!("tcp/127.0.0.1:{}", ghnet_testkit::free_tcp_port());
    let session = zenoh::open(
        ghnet_client::peer_config(std::slice::from_ref(&endpoint), &[])
            .map_err(|e| anyhow::anyhow!("zenoh config: {e}"))?,
    )
    .wait()
    .map_err(|e| anyhow::anyhow!("zenoh session on {endpoint}: {e}"))?;

    // 1. The model alone, in this process (the latency target includes it).
    let inference = inference::time(&args.model, 20_000)?;
    eprintln!("inference: {}", inference);
    let mut rows = inference.rows();
    // The ROS 2 phase needs root and Python: only when named.
    let want = |p: Phase| (args.only.is_empty() && p != Phase::Ros2) || args.only.contains(&p);
    if want(Phase::Latency) {
        rows.extend(latency::rows(args, &env, &session, &endpoint, &inference)?);
    }
    if want(Phase::Throughput) {
        rows.extend(throughput::rows(args, &env, &session, &endpoint)?);
    }
    if want(Phase::Footprint) {
        rows.extend(footprint::rows(args, &env, &session, &endpoint)?);
    }
    if want(Phase::Alloc) {
        rows.extend(alloc::rows(args, &session, &endpoint)?);
    }
    if want(Phase::Ros2) {
        rows.extend(ros2::rows(args, &env)?);
    }
    print_report(args, &rows, started.elapsed())?;
    Ok(rows.iter().all(|r| r.pass != Some(false)))
}

fn print_report(args: &Args, rows: &[Row], took: Duration) -> anyhow::Result<()> {
    let cpuinfo = std::fs::read_to_string("/proc/cpuinfo").unwrap_or_default();
    let cpu = cpuinfo
        .lines()
        .find_map(|l| l.strip_prefix("model name"))
        .map(|v| v.trim_start_matches([' ', '\t', ':']).to_owned())
        .unwrap_or_else(|| "unknown".into());
    let cores = std::thread::available_parallelism().map_or(0, |n| n.get());
    let load = std::fs::read_to_string("/proc/loadavg").unwrap_or_default();
    let command: Vec<String> = std::env::args().collect();
    println!();
    println!("## ghnetd performance");
    println!();
    println!("- command: `{}`", command.join(" "));
    println!(
        "- machine: {cpu}, {cores} cores; load average at the end: {}",
        load.split_whitespace()
            .take(3)
            .collect::<Vec<_>>()
            .join(" ")
    );
    println!(
        "- model: `{}`; ghnetd: `{}`; run took {:.0} s",
        args.model,
        args.ghnetd
            .as_ref()
            .map_or_else(|| "next to perf".into(), |p| p.display().to_string()),
        took.as_secs_f64()
    );
    println!(
        "- latency: {} measured round trips per pass after {} warm-up, one in flight, event-driven on both sides; echo and ghnetd running side by side, taking turns in blocks of 5000 (200 more warm-up each); raw = `perf echo` (same WaitSet loop and outputs, no model)",
        args.samples, args.warmup_samples
    );
    println!(
        "- throughput: {} sources, ≤ {} unanswered each, notify per {:?}, Zenoh subscriber on `<prefix>/*/heading`; a sample is answered when its heading came back on both outputs",
        args.sources, args.in_flight, args.notify
    );
    println!();
    println!("| metric | raw transport | ghnetd | target | pass/fail |");
    println!("|---|---|---|---|---|");
    for r in rows {
        let verdict = match r.pass {
            Some(true) => "PASS",
            Some(false) => "FAIL",
            None => "–",
        };
        println!(
            "| {} | {} | {} | {} | {} |",
            r.metric, r.raw, r.ghnetd, r.target, verdict
        );
    }
    println!();
    println!(
        "Allocations: counted on the daemon thread of an in-process `ghnetd::run` (the \
         library the binary wraps), one sample in flight, housekeeping included. They are \
         the libraries': iceoryx2 0.10 allocates its shared sample state (an `Rc`) per \
         loaned sample and two short lists per WaitSet wake-up, Zenoh one reference-counted \
         buffer around each `put` payload; daemon/tests/no_alloc.rs checks that ghnetd's \
         own per-sample code adds nothing."
    );
    println!();
    Ok(())
}
