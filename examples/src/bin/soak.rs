//! `soak`: N sources at a fixed rate against ghnetd; checks that every sample got
//! exactly one heading and prints latency percentiles (sample timestamp → receipt).
//!
//! Teaches: the exactly-once contract (`seq` is echoed), one collector thread per
//! heading subscriber (iceoryx2 ports are `!Send`), all publishers on one pacing
//! node. Exit status 0 = every sample answered once, 1 = loss or duplicate, 2 = error.
//!
//! ```text
//! cargo run --release -p ghnet-examples --bin soak -- --sources 4 --rate 100 --duration 30
//! # or with a ghnetd of its own (static sources, stopped with SIGTERM at the end):
//! cargo build --release -p ghnetd
//! cargo run --release -p ghnet-examples --bin soak -- --spawn-daemon target/release/ghnetd
//! ```

use std::process::ExitCode;
use std::time::Duration;

use clap::Parser;
use ghnet_client::{VelocityPublisher, VelocitySample};
use ghnet_examples::{now_ns, pacing_node, wait_for_subscriber, Collector, CommonArgs};
use ghnet_examples::{Pacer, Percentiles, SpawnedDaemon, Tally};

/// Load test: every sample must be answered exactly once.
#[derive(Parser)]
struct Args {
    #[command(flatten)]
    common: CommonArgs,
    /// Number of sources, named `soak<pid>-<i>`.
    #[arg(long, default_value_t = 4)]
    sources: usize,
    /// Samples per second per source.
    #[arg(long, default_value_t = 100.0)]
    rate: f64,
    /// Seconds to publish.
    #[arg(long, default_value_t = 10.0)]
    duration: f64,
    /// Start this ghnetd binary instead of using a running one.
    #[arg(long, value_name = "PATH")]
    spawn_daemon: Option<std::path::PathBuf>,
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
    let ipc = args.common.ipc()?;
    let pid = std::process::id();
    let names: Vec<String> = (0..args.sources)
        .map(|i| format!("soak{pid}-{i}"))
        .collect();
    let total = (args.duration * args.rate).round() as u64;
    let mut daemon = match &args.spawn_daemon {
        Some(bin) => Some(SpawnedDaemon::ghnetd(bin, &args.common.prefix, &names)?),
        None => None,
    };

    // Collectors first, so no heading is published before someone listens.
    let (startup, idle) = (Duration::from_secs(20), Duration::from_secs(2));
    let collectors: Vec<Collector> = (names.iter())
        .map(|n| Collector::start(&ipc, n, total, startup, idle))
        .collect::<anyhow::Result<_>>()?;
    let node = pacing_node(&ipc, "ghnet-example-soak")?;
    let pubs: Vec<VelocityPublisher> = (names.iter())
        .map(|n| VelocityPublisher::with_node(&node, &ipc, n))
        .collect::<Result<_, _>>()?;
    let patience = Duration::from_secs(10);
    wait_for_subscriber(&node, &pubs.iter().collect::<Vec<_>>(), patience, || {
        daemon.as_mut().is_some_and(|d| d.has_exited())
    })?;

    println!(
        "soak: {} sources × {total} samples at {} Hz",
        names.len(),
        args.rate
    );
    let pacer = Pacer::new(args.rate)?;
    for seq in 0..total {
        for p in &pubs {
            p.send(VelocitySample::new(now_ns(), seq, 3.0, 4.0, 0.0))?;
        }
        pacer.wait_for_slot(&node, seq + 1)?;
    }

    let (mut ok, mut latencies) = (true, Vec::new());
    for (name, collector) in names.iter().zip(collectors) {
        let got = collector.join()?;
        let tally = Tally::of(total, got.iter().map(|a| a.seq));
        println!("{name}: sent {total}  answered {}  {tally}", got.len());
        ok &= tally.is_exactly_once();
        latencies.extend(got.iter().map(|a| a.latency_ns));
    }
    if let Some(p) = Percentiles::of(latencies) {
        println!("latency {p}");
    }
    if let Some(d) = daemon {
        println!("ghnetd exited: {}", d.stop(Duration::from_secs(10))?);
    }
    let verdict = if ok {
        "PASS: every sample answered exactly once"
    } else {
        "FAIL"
    };
    println!("{verdict}");
    Ok(ok)
}
