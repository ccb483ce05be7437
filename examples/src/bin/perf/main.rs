//! `perf`: the daemon-level benchmark of issue #6 in one run — latency, throughput,
//! footprint and allocations of the real `ghnetd`, each beside the raw transport
//! doing the same hops without a model, printed as one Markdown table.
//!
//! Teaches: how to measure an event-driven sidecar fairly. The baseline is this
//! binary re-spawned as `--role echo` (same process layout, same WaitSet wake-up,
//! same iceoryx2 + Zenoh outputs, no model), the model cost is measured in the same
//! run with `ghnet_models::Predictor`, and every target lives in a private iceoryx2
//! namespace on free Zenoh ports, so nothing else on the machine is touched.
//!
//! ```text
//! cargo build --release -p ghnetd -p ghnet-examples
//! target/release/perf            # full run, about 2-3 min
//! target/release/perf --quick    # about 1 min, fewer samples
//! ```
//!
//! `ghnetd` is taken from next to this executable (`GHNETD_BIN` or `--ghnetd`
//! override). Progress goes to stderr, the table to stdout. Exit status 0 = every
//! target met, 1 = a target missed, 2 = error.

use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::Context;
use clap::Parser;
use ghnet_client::zenoh::{self, Wait};
use ghnet_client::VelocityPublisher;
use ghnet_examples::Percentiles;
use ghnet_models::{Model, Predictor, DEFAULT_MODEL};

mod alloc;
mod echo;
mod footprint;
mod latency;
mod target;
mod throughput;

use latency::Output;
use target::{Env, Kind, Spec, Target};
use throughput::Notify;

/// Daemon latency, throughput and footprint against the raw transport, one table.
#[derive(Parser)]
struct Args {
    /// Measured round trips per latency pass (four passes: iceoryx2 and Zenoh
    /// output, raw echo and ghnetd).
    #[arg(long, default_value_t = 100_000)]
    samples: u64,
    /// Unmeasured round trips before each latency pass.
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
    /// The ghnetd binary; default: `ghnetd` next to this executable.
    #[arg(long, env = "GHNETD_BIN", value_name = "PATH")]
    ghnetd: Option<PathBuf>,

    // The echo role (spawned by perf itself).
    #[arg(long, hide = true)]
    role: Option<String>,
    #[arg(long, hide = true)]
    global_prefix: Option<String>,
    #[arg(long, hide = true)]
    root: Option<PathBuf>,
    #[arg(long, hide = true)]
    service_prefix: Option<String>,
    #[arg(long = "source", hide = true)]
    source: Vec<String>,
    #[arg(long, hide = true)]
    zenoh_listen: Option<String>,
    #[arg(long, hide = true)]
    zenoh_connect: Option<String>,
}

/// The parts of the run, for `--only`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum Phase {
    /// Four latency passes: raw echo and ghnetd, iceoryx2 and Zenoh output.
    Latency,
    /// Throughput with all sources, and resident memory before and after.
    Throughput,
    /// Idle CPU and start-to-ready.
    Footprint,
    /// Allocations per sample on the daemon thread.
    Alloc,
}

fn main() -> ExitCode {
    let mut args = Args::parse();
    if args.role.as_deref() == Some("echo") {
        // iceoryx2's logger would print a warning about its config file per start.
        ghnet_client::iceoryx2::prelude::set_log_level_from_env_or(
            ghnet_client::iceoryx2::prelude::LogLevel::Error,
        );
        let echo = echo::EchoArgs {
            global_prefix: args.global_prefix.unwrap_or_default(),
            root: args.root.unwrap_or_default(),
            service_prefix: args.service_prefix.unwrap_or_default(),
            sources: args.source,
            zenoh_listen: args.zenoh_listen,
            zenoh_connect: args.zenoh_connect,
        };
        return match echo::run(echo) {
            Ok(()) => ExitCode::SUCCESS,
            Err(e) => {
                eprintln!("echo: {e:#}");
                ExitCode::from(2)
            }
        };
    }
    if args.quick {
        args.samples = 20_000;
        args.warmup_samples = 1_000;
        args.throughput_seconds = 3.0;
        args.idle_seconds = 5.0;
        args.ready_runs = 3;
    }
    ghnet_client::iceoryx2::prelude::set_log_level_from_env_or(
        ghnet_client::iceoryx2::prelude::LogLevel::Error,
    );
    match run(&args) {
        Ok(true) => ExitCode::SUCCESS,
        Ok(false) => ExitCode::from(1),
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(2)
        }
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

fn us(d: Duration) -> String {
    format!("{:.1} µs", d.as_nanos() as f64 / 1000.0)
}

fn run(args: &Args) -> anyhow::Result<bool> {
    let this_exe = std::env::current_exe().context("path of this executable")?;
    let ghnetd = match &args.ghnetd {
        Some(p) => p.clone(),
        None => this_exe.with_file_name("ghnetd"),
    };
    anyhow::ensure!(
        ghnetd.is_file(),
        "no ghnetd at {}: build it with the same profile (`cargo build --release -p ghnetd`) or set GHNETD_BIN",
        ghnetd.display()
    );
    let env = Env {
        ghnetd: ghnetd.clone(),
        this_exe,
        model: args.model.clone(),
    };
    let started = Instant::now();
    eprintln!("perf: ghnetd = {}", ghnetd.display());

    // The targets connect to this session (so no wait for Zenoh's connect retries).
    let endpoint = format!("tcp/127.0.0.1:{}", target::free_port()?);
    let session = zenoh::open(
        ghnet_client::peer_config(std::slice::from_ref(&endpoint), &[])
            .map_err(|e| anyhow::anyhow!("zenoh config: {e}"))?,
    )
    .wait()
    .map_err(|e| anyhow::anyhow!("zenoh session on {endpoint}: {e}"))?;

    // 1. The model alone, in this process (the latency target includes it).
    let inference = inference_time(&args.model, 20_000)?;
    eprintln!("inference: {}", inference);
    let mut rows = vec![
        row(
            "model alone: `Predictor::predict_with_accuracy`, p50 (mean)",
            "–".into(),
            format!("{} ({})", us(inference.p50), us(inference.mean)),
            "–".into(),
            None,
        ),
        row(
            "model alone: `predict_batch_with_accuracy` per sample, batch 4 / 16 / 128 (p50)",
            "–".into(),
            inference
                .batch
                .iter()
                .filter(|(n, _)| [4, 16, 128].contains(n))
                .map(|(_, d)| us(*d))
                .collect::<Vec<_>>()
                .join(" / "),
            "–".into(),
            None,
        ),
    ];
    let want = |p: Phase| args.only.is_empty() || args.only.contains(&p);
    if want(Phase::Latency) {
        rows.extend(latency_rows(args, &env, &session, &endpoint, &inference)?);
    }
    if want(Phase::Throughput) {
        rows.extend(throughput_rows(args, &env, &session, &endpoint)?);
    }
    if want(Phase::Footprint) {
        rows.extend(footprint_rows(args, &env, &session, &endpoint)?);
    }
    if want(Phase::Alloc) {
        rows.extend(alloc_rows(args, &session, &endpoint)?);
    }
    print_report(args, &rows, started.elapsed())?;
    Ok(rows.iter().all(|r| r.pass != Some(false)))
}

/// Phase 2: latency, four passes (raw echo and ghnetd, each with the iceoryx2 and
/// the Zenoh output), one sample in flight.
fn latency_rows(
    args: &Args,
    env: &Env,
    session: &zenoh::Session,
    endpoint: &str,
    inference: &Inference,
) -> anyhow::Result<Vec<Row>> {
    let mut lat = Vec::new();
    let mut seq = 0;
    for kind in [Kind::Echo, Kind::Ghnetd] {
        let spec = Spec {
            kind,
            sources: vec!["lat0".into()],
            discovery: false,
            zenoh_connect: Some(endpoint.to_owned()),
        };
        let mut t = Target::spawn(env, &spec)?;
        for output in [Output::Iceoryx2, Output::Zenoh] {
            let r = latency::measure(
                &mut t,
                session,
                output,
                "lat0",
                seq,
                args.warmup_samples,
                args.samples,
            )?;
            seq += args.warmup_samples + args.samples + 10_000;
            eprintln!(
                "latency {} {output:?}: {} lost {}",
                kind.label(),
                r.percentiles,
                r.lost
            );
            lat.push(((kind, output), r));
        }
        t.stop()?;
    }
    let lat_of = |k: Kind, o: Output| {
        &lat.iter()
            .find(|((kk, oo), _)| *kk == k && *oo == o)
            .expect("measured")
            .1
    };
    let mut rows = Vec::new();
    for (output, name) in [(Output::Iceoryx2, "iceoryx2"), (Output::Zenoh, "Zenoh")] {
        let raw = &lat_of(Kind::Echo, output).percentiles;
        let d = &lat_of(Kind::Ghnetd, output).percentiles;
        let p50_limit = raw.p50 + inference.p50 + Duration::from_micros(10);
        let p99_limit = raw.p99 + Duration::from_micros(25);
        rows.push(row(
            &format!("latency p50, publisher → {{echo, ghnetd}} → {name} subscriber"),
            us(raw.p50),
            us(d.p50),
            format!("≤ raw + model + 10 µs = {}", us(p50_limit)),
            Some(d.p50 <= p50_limit),
        ));
        rows.push(row(
            &format!("latency p99 ({name})"),
            us(raw.p99),
            us(d.p99),
            format!("≤ raw + 25 µs = {}", us(p99_limit)),
            Some(d.p99 <= p99_limit),
        ));
        rows.push(row(
            &format!("latency p99.9 / max ({name})"),
            format!("{} / {}", us(raw.p999), us(raw.max)),
            format!("{} / {}", us(d.p999), us(d.max)),
            "–".into(),
            None,
        ));
        let (lr, ld) = (
            lat_of(Kind::Echo, output).lost,
            lat_of(Kind::Ghnetd, output).lost,
        );
        rows.push(row(
            &format!("latency samples lost ({name}, of {} each)", args.samples),
            lr.to_string(),
            ld.to_string(),
            "0".into(),
            Some(ld == 0),
        ));
    }
    Ok(rows)
}

/// Phase 3: throughput with all sources, raw echo then ghnetd; resident memory
/// before and after the load.
fn throughput_rows(
    args: &Args,
    env: &Env,
    session: &zenoh::Session,
    endpoint: &str,
) -> anyhow::Result<Vec<Row>> {
    let names: Vec<String> = (0..args.sources).map(|i| format!("tp{i:03}")).collect();
    let opt = throughput::Options {
        warmup: Duration::from_secs(1),
        window: Duration::from_secs_f64(args.throughput_seconds),
        in_flight: args.in_flight,
        notify: args.notify,
    };
    let mut tp = Vec::new();
    for kind in [Kind::Echo, Kind::Ghnetd] {
        let spec = Spec {
            kind,
            sources: names.clone(),
            discovery: false,
            zenoh_connect: Some(endpoint.to_owned()),
        };
        let mut t = Target::spawn(env, &spec)?;
        let r = throughput::measure(&mut t, session, &names, &opt)?;
        eprintln!(
            "throughput {}: {:.0} samples/s over {:.1?}; sent {}; iceoryx2 {:?}; zenoh {:?}; target {:.2} cores, driver {:.2} cores; RSS connected {:.1} MiB, after load {:.1} MiB (anon {} KiB, shm {} KiB, peak {} KiB)",
            kind.label(),
            r.rate,
            r.window,
            r.sent,
            r.iceoryx2,
            r.zenoh,
            r.target_cores,
            r.driver_cores,
            r.rss_connected.total_mib(),
            r.rss_after_load.total_mib(),
            r.rss_after_load.anon_kib,
            r.rss_after_load.shmem_kib,
            r.rss_after_load.peak_kib
        );
        t.stop()?;
        tp.push(r);
    }
    let (tr, td) = (&tp[0], &tp[1]);
    let mib = |kib: u64| format!("{:.1} MiB", kib as f64 / 1024.0);
    Ok(vec![
        row(
            &format!(
                "throughput, {} sources, Zenoh on, samples/s over {:.0} s",
                args.sources,
                td.window.as_secs_f64()
            ),
            format!("{:.0}", tr.rate),
            format!("{:.0}", td.rate),
            "≥ 100000".into(),
            Some(td.rate >= 100_000.0),
        ),
        row(
            "throughput: lost / duplicate / unexpected on iceoryx2 \\| over Zenoh (every seq checked on both)",
            losses(tr),
            losses(td),
            "0 / 0 / 0 \\| 0 / 0 / 0".into(),
            Some(td.iceoryx2.none() && td.zenoh.none()),
        ),
        row(
            "throughput: CPU of target / of the driving perf process (cores)",
            format!("{:.2} / {:.2}", tr.target_cores, tr.driver_cores),
            format!("{:.2} / {:.2}", td.target_cores, td.driver_cores),
            "–".into(),
            None,
        ),
        row(
            &format!(
                "VmRSS with {} sources connected (before the load)",
                args.sources
            ),
            mib(tr.rss_connected.total_kib),
            mib(td.rss_connected.total_kib),
            "< 64 MB".into(),
            Some((td.rss_connected.total_kib as f64) * 1024.0 < 64e6),
        ),
        row(
            "  anonymous / iceoryx2 shared memory of it",
            format!(
                "{} / {}",
                mib(tr.rss_connected.anon_kib),
                mib(tr.rss_connected.shmem_kib)
            ),
            format!(
                "{} / {}",
                mib(td.rss_connected.anon_kib),
                mib(td.rss_connected.shmem_kib)
            ),
            "–".into(),
            None,
        ),
        row(
            "VmRSS after the throughput load (anonymous / shared memory)",
            format!(
                "{} ({} / {})",
                mib(tr.rss_after_load.total_kib),
                mib(tr.rss_after_load.anon_kib),
                mib(tr.rss_after_load.shmem_kib)
            ),
            format!(
                "{} ({} / {})",
                mib(td.rss_after_load.total_kib),
                mib(td.rss_after_load.anon_kib),
                mib(td.rss_after_load.shmem_kib)
            ),
            "–".into(),
            None,
        ),
    ])
}

/// Phases 4 and 5: idle CPU (both targets at once, each with silent connected
/// sources; ghnetd as deployed, with discovery finding them) and start-to-ready.
fn footprint_rows(
    args: &Args,
    env: &Env,
    session: &zenoh::Session,
    endpoint: &str,
) -> anyhow::Result<Vec<Row>> {
    let idle_names: Vec<String> = (0..args.idle_sources).map(|i| format!("idle{i}")).collect();
    let mut echo_t = Target::spawn(
        env,
        &Spec {
            kind: Kind::Echo,
            sources: idle_names.clone(),
            discovery: false,
            zenoh_connect: None,
        },
    )?;
    let mut daemon_t = Target::spawn(
        env,
        &Spec {
            kind: Kind::Ghnetd,
            sources: Vec::new(),
            discovery: true,
            zenoh_connect: None,
        },
    )?;
    let publishers = [&echo_t, &daemon_t]
        .iter()
        .map(|t| {
            idle_names
                .iter()
                .map(|n| VelocityPublisher::new(&t.ipc, n))
                .collect::<Result<Vec<_>, _>>()
        })
        .collect::<Result<Vec<_>, _>>()?;
    let idle = footprint::idle_cpu(
        &mut [&mut echo_t, &mut daemon_t],
        &publishers,
        Duration::from_secs(1),
        Duration::from_secs_f64(args.idle_seconds),
    )?;
    drop(publishers);
    echo_t.stop()?;
    daemon_t.stop()?;
    eprintln!(
        "idle CPU: raw {:.3}%  ghnetd {:.3}%",
        idle[0] * 100.0,
        idle[1] * 100.0
    );

    let ready = footprint::start_to_ready(env, session, endpoint, args.ready_runs)?;
    let ready_p =
        Percentiles::of(ready.iter().map(|d| d.as_nanos() as u64).collect()).context("no start")?;
    eprintln!("start-to-ready: {ready_p}");
    Ok(vec![
        row(
            &format!(
                "idle CPU, {} silent sources, {:.0} s (share of one core)",
                args.idle_sources, args.idle_seconds
            ),
            format!("{:.3}%", idle[0] * 100.0),
            format!("{:.3}%", idle[1] * 100.0),
            "< 0.5%".into(),
            Some(idle[1] < 0.005),
        ),
        row(
            &format!(
                "start-to-ready (spawn → liveliness token + iceoryx2 services), median / max of {}",
                ready.len()
            ),
            "–".into(),
            format!("{:.1} ms / {:.1} ms", ms(ready_p.p50), ms(ready_p.max)),
            "median < 250 ms".into(),
            Some(ready_p.p50 < Duration::from_millis(250)),
        ),
    ])
}

/// Phase 6: allocations per sample on the daemon thread (in-process `ghnetd::run`).
fn alloc_rows(args: &Args, session: &zenoh::Session, endpoint: &str) -> anyhow::Result<Vec<Row>> {
    let n_alloc = (args.samples / 5).max(1_000);
    let alloc_ice = alloc::per_sample(&args.model, None, 1_000, n_alloc)?;
    let alloc_zenoh = alloc::per_sample(
        &args.model,
        Some((session, endpoint.to_owned())),
        1_000,
        n_alloc,
    )?;
    eprintln!("allocations per sample: iceoryx2 only {alloc_ice:.2}, with zenoh {alloc_zenoh:.2}");
    Ok(vec![row(
        "allocations per sample on the daemon thread: iceoryx2 only / with Zenoh",
        "–".into(),
        format!("{alloc_ice:.2} / {alloc_zenoh:.2}"),
        "– (see note)".into(),
        None,
    )])
}

/// `lost / duplicate / unexpected` on both outputs, and of how many sent.
fn losses(r: &throughput::ThroughputRun) -> String {
    let f = |l: &throughput::Losses| format!("{} / {} / {}", l.lost, l.duplicates, l.unexpected);
    format!("{} \\| {} of {}", f(&r.iceoryx2), f(&r.zenoh), r.sent)
}

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1000.0
}

/// Per-call time of the model alone.
struct Inference {
    p50: Duration,
    mean: Duration,
    /// Per-sample time of `predict_batch_with_accuracy`, by batch size.
    batch: Vec<(usize, Duration)>,
}

impl std::fmt::Display for Inference {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "one sample: p50 {} mean {}; batch, per sample:",
            us(self.p50),
            us(self.mean)
        )?;
        for (n, d) in &self.batch {
            write!(f, " {n}: {}", us(*d))?;
        }
        Ok(())
    }
}

/// Times `n` single-sample predictions (after a warm-up), each on its own: the
/// daemon answers one sample at a time when one is in flight.
fn inference_time(model: &str, n: usize) -> anyhow::Result<Inference> {
    let model = Arc::new(Model::from_name_or_path(model).map_err(|e| anyhow::anyhow!("{e}"))?);
    let mut predictor = Predictor::new(model);
    let mut times = Vec::with_capacity(n);
    for i in 0..n + 2_000 {
        let vn = 3.0 + (i % 97) as f32 * 0.01;
        let t0 = Instant::now();
        std::hint::black_box(predictor.predict_with_accuracy(
            std::hint::black_box(vn),
            std::hint::black_box(4.0),
            f32::NAN,
        ));
        let dt = t0.elapsed().as_nanos() as u64;
        if i >= 2_000 {
            times.push(dt);
        }
    }
    let mean = Duration::from_nanos(times.iter().sum::<u64>() / n as u64);
    let p = Percentiles::of(times).context("no samples")?;
    // The batch path ghnetd takes when a source has several samples buffered: the
    // median over repetitions of one call, divided by the batch size.
    let mut batch = Vec::new();
    for size in [2usize, 4, 8, 16, 64, 128] {
        let vn: Vec<f32> = (0..size).map(|i| 3.0 + (i % 97) as f32 * 0.01).collect();
        let ve = vec![4.0f32; size];
        let acc = vec![f32::NAN; size];
        let mut out = vec![predictor.predict(1.0, 1.0); size];
        let reps = (n / size).clamp(50, 2_000);
        let mut t = Vec::with_capacity(reps);
        for _ in 0..reps {
            let t0 = Instant::now();
            predictor.predict_batch_with_accuracy(&vn, &ve, &acc, &mut out);
            std::hint::black_box(&out);
            t.push(t0.elapsed().as_nanos() as u64 / size as u64);
        }
        batch.push((size, Percentiles::of(t).context("no samples")?.p50));
    }
    Ok(Inference {
        p50: p.p50,
        mean,
        batch,
    })
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
    println!("## ghnetd performance (issue #6)");
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
        "- latency: {} measured round trips per pass after {} warm-up, one in flight, event-driven on both sides; raw = `perf --role echo` (same WaitSet loop and outputs, no model)",
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
