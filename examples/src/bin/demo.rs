//! `demo`: the one command that shows headings flowing. Starts ghnetd in-process,
//! a simulated vehicle and a live heading table, then shuts everything down in order.
//!
//! Teaches: the daemon is a library (`ghnetd::run(config, shutdown)` on its own
//! thread, stopped with a `ShutdownFlag`), and the three roles of ghnet — source,
//! daemon, consumer — are just ports on the same two services.
//!
//! ```text
//! cargo run --release -p ghnet-examples --bin demo                 # 10 s, system namespace
//! cargo run --release -p ghnet-examples --bin demo -- --isolated   # private namespace
//! ```

use std::io::IsTerminal;
use std::process::ExitCode;
use std::time::Duration;

use clap::Parser;
use ghnet_client::{testing::TestNamespace, IpcConfig, VelocityPublisher};
use ghnet_examples::{
    now_ns, pacing_node, table, wait_for_subscriber, Pacer, TablePrinter, Vehicle,
};

/// ghnetd + simulated vehicle + heading table, in one process.
#[derive(Parser)]
struct Args {
    /// Seconds to publish.
    #[arg(long, default_value_t = 10.0)]
    duration: f64,
    /// Samples per second.
    #[arg(long, default_value_t = 10.0)]
    rate: f64,
    /// Simulation seed: picks the trajectory and the receiver. The default, 10, is a
    /// good receiver (σ_v 0.03 m/s) pulling away from a stop, so the table shows
    /// `LowSpeed` turning into `Ok` as the speed grows; seed 1 is a poor receiver
    /// creeping at 0.5 m/s, where every heading is `LowSpeed` with σ near 100°.
    #[arg(long, default_value_t = 10)]
    seed: u64,
    /// Private iceoryx2 namespace (removed at exit) instead of the system one.
    #[arg(long)]
    isolated: bool,
    /// Model: built-in name or .safetensors path.
    #[arg(long, default_value = ghnet_models::DEFAULT_MODEL)]
    model: String,
}

const SOURCE: &str = "demo";

fn main() -> ExitCode {
    // Daemon log lines on stderr, the table on stdout.
    let filter = tracing_subscriber::EnvFilter::try_from_default_env();
    tracing_subscriber::fmt()
        .with_env_filter(filter.unwrap_or_else(|_| "info".into()))
        .with_writer(std::io::stderr)
        .with_ansi(std::io::stderr().is_terminal())
        .init();
    iceoryx2::prelude::set_log_level_from_env_or(iceoryx2::prelude::LogLevel::Error);
    match run(Args::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn run(args: Args) -> anyhow::Result<()> {
    // Declared first, dropped last: removes the private namespace's files.
    let ns = args.isolated.then(|| TestNamespace::new("demo"));
    let ipc = ns.as_ref().map_or_else(IpcConfig::default, |ns| ns.ipc());

    // 1. The daemon on its own thread, serving our one source from the start.
    let mut config = ghnetd::Config::default();
    config.model.name = args.model.clone();
    (config.sources.static_sources, config.sources.discovery) = (vec![SOURCE.into()], false);
    config.ipc.iceoryx2_global_prefix = ns.as_ref().map(|ns| ns.global_prefix().into());
    config.ipc.iceoryx2_root_path = ns.as_ref().map(|ns| ns.root_path().into());
    // This demo is about shared memory; `zenoh_echo` shows the Zenoh output. Off, so
    // the demo never competes with a running ghnetd for its Zenoh port.
    config.zenoh.enabled = false;
    let shutdown = ghnetd::ShutdownFlag::new();
    let daemon = std::thread::spawn({
        let shutdown = shutdown.clone();
        move || ghnetd::run(config, shutdown)
    });

    // 2. The consumer, 3. the source: publish once the daemon has subscribed.
    let printer = TablePrinter::start(&ipc, SOURCE)?;
    let node = pacing_node(&ipc, "ghnet-demo")?;
    let gnss = VelocityPublisher::with_node(&node, &ipc, SOURCE)?;
    let patience = Duration::from_secs(30);
    if let Err(e) = wait_for_subscriber(&node, &[&gnss], patience, || daemon.is_finished()) {
        // The daemon's own error (e.g. the model cannot be loaded) says more.
        let failed = daemon
            .is_finished()
            .then(|| daemon.join().expect("daemon panicked"));
        return Err(failed.and_then(Result::err).unwrap_or(e));
    }
    if gnss.subscriber_count() > 1 {
        eprintln!(
            "warning: another ghnetd serves {SOURCE}: rows may appear twice (try --isolated)"
        );
    }
    println!("{}", table::HEADER);
    let mut vehicle = Vehicle::new(args.seed, args.rate, args.duration.max(60.0));
    let (pacer, mut sent) = (Pacer::new(args.rate)?, 0);
    while pacer.elapsed().as_secs_f64() < args.duration {
        gnss.send(vehicle.next_sample(sent, now_ns()))?;
        sent += 1;
        if pacer.wait_for_slot(&node, sent).is_err() {
            break; // Ctrl-C: shut down in order below
        }
    }

    // 4. In order: let the last answers arrive and stop the table, then the daemon.
    let answered = printer.finish(sent, Duration::from_secs(1))?;
    shutdown.request();
    let stats = daemon.join().expect("daemon panicked")?.total();
    println!(
        "demo: sent {sent}, answered {answered} (ghnetd: received {}, invalid {}) in {:.1?}",
        stats.received,
        stats.invalid,
        pacer.elapsed()
    );
    Ok(())
}
