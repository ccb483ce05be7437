//! `demo`: ghnetd on the embedded default model, a simulated vehicle and a live table
//! of headings, in one process. The daemon is a library (`ghnetd::run(config,
//! shutdown)` on a thread); source, daemon and consumer are ports on two services.
//!
//! ```text
//! cargo run --release -p ghnet-examples --bin demo                 # 10 s, system namespace
//! cargo run --release -p ghnet-examples --bin demo -- --isolated   # private namespace
//! ```

use std::time::Duration;

use clap::Parser;
use ghnet_client::{testing::TestNamespace, IpcConfig, VelocityPublisher};
use ghnet_examples::{log_to_stderr, now_ns, pacing_node, wait_for_subscriber};
use ghnet_examples::{table, Pacer, TablePrinter, Vehicle};

const SOURCE: &str = "demo";
fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    log_to_stderr(); // the daemon's log lines; the table goes to stdout
    let ns = args.isolated.then(|| TestNamespace::new("demo")); // removed at exit
    let ipc = ns
        .as_ref()
        .map_or_else(IpcConfig::default, TestNamespace::ipc);

    // 1. The daemon on its own thread, serving our one source from the start. No
    // Zenoh, so the demo never competes with a running ghnetd for its port.
    let mut config = ghnetd::Config::default();
    (config.model.name, config.zenoh.enabled) = (args.model.clone(), false);
    (config.sources.static_sources, config.sources.discovery) = (vec![SOURCE.into()], false);
    config.ipc.iceoryx2_global_prefix = ns.as_ref().map(|ns| ns.global_prefix().into());
    config.ipc.iceoryx2_root_path = ns.as_ref().map(|ns| ns.root_path().into());
    let shutdown = ghnetd::ShutdownFlag::new();
    let stop = shutdown.clone();
    let daemon = std::thread::spawn(move || ghnetd::run(config, stop));

    // 2. The consumer, 3. the source: publish once the daemon has subscribed.
    let printer = TablePrinter::start(&ipc, SOURCE)?;
    let node = pacing_node(&ipc, "ghnet-demo")?;
    let gnss = VelocityPublisher::with_node(&node, &ipc, SOURCE)?;
    let patience = Duration::from_secs(30);
    if let Err(e) = wait_for_subscriber(&node, &[&gnss], patience, || daemon.is_finished()) {
        // The daemon's own error (e.g. the model cannot be loaded) says more.
        let failed = daemon
            .is_finished()
            .then(|| daemon.join().expect("no panic"));
        return Err(failed.and_then(Result::err).unwrap_or(e));
    }
    println!("{}", table::header());
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
    let stats = daemon.join().expect("no panic")?.total();
    let (received, invalid, took) = (stats.received, stats.invalid, pacer.elapsed());
    println!("demo: sent {sent}, answered {answered} (ghnetd: received {received}, invalid {invalid}) in {took:.1?}");
    Ok(())
}

/// ghnetd + simulated vehicle + heading table, in one process.
#[derive(Parser)]
struct Args {
    /// Seconds to publish.
    #[arg(long, default_value_t = 10.0)]
    duration: f64,
    /// Samples per second.
    #[arg(long, default_value_t = 10.0)]
    rate: f64,
    /// Simulation seed: 10, a good receiver pulling away (`LowSpeed` turning `Ok`); 1, a
    /// poor one creeping at 0.5 m/s.
    #[arg(long, default_value_t = 10)]
    seed: u64,
    /// Private iceoryx2 namespace (removed at exit) instead of the system one.
    #[arg(long)]
    isolated: bool,
    /// Model: built-in name or .safetensors path.
    #[arg(long, default_value = ghnet_models::DEFAULT_MODEL)]
    model: String,
}
