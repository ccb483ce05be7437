//! `publisher`: one simulated vehicle sending `VelocitySample`s to ghnetd.
//!
//! Run (with `ghnetd` and `subscriber` in other terminals, see examples/README.md):
//!
//! ```text
//! cargo run -p ghnet-examples --bin publisher -- --source gnss0 --rate 10 --duration 60
//! ```
//!
//! `VelocityPublisher::send` is loan → write → send → notify, straight into shared
//! memory. Timestamps are real, sequence numbers increase, `node.wait` paces the loop
//! (and ends it on Ctrl-C), and the first sample waits for the daemon: ghnet services
//! keep no history, so a sample sent before ghnetd subscribed is never answered.

use std::time::Duration;

use clap::Parser;
use ghnet_client::VelocityPublisher;
use ghnet_examples::{now_ns, pacing_node, wait_for_subscriber, Interrupted, SourceArgs};
use ghnet_examples::{Pacer, Vehicle};

fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    let ipc = args.source.ipc()?;
    let node = pacing_node(&ipc, "ghnet-example-publisher")?;
    let gnss = VelocityPublisher::with_node(&node, &ipc, &args.source.name)?;
    let mut vehicle = Vehicle::new(args.seed, args.rate, args.duration.max(60.0));

    let patience = Duration::from_secs_f64(args.wait);
    if let Err(e) = wait_for_subscriber(&node, &[&gnss], patience, || false) {
        if e.is::<Interrupted>() {
            return Ok(());
        }
        eprintln!("warning: {e:#}; sending anyway");
    }

    println!("publishing on {} at {} Hz", gnss.service_name(), args.rate);
    let total = (args.duration * args.rate).round() as u64; // 0 = until Ctrl-C
    let pacer = Pacer::new(args.rate)?;
    let mut seq = 0;
    while total == 0 || seq < total {
        gnss.send(vehicle.next_sample(seq, now_ns()))?;
        seq += 1;
        if pacer.wait_for_slot(&node, seq).is_err() {
            break; // Ctrl-C / SIGTERM: ports are dropped cleanly on return
        }
    }
    println!("sent {seq} samples (seq 0..{seq})");
    Ok(())
}

/// Sends a simulated vehicle's GNSS velocities on `<prefix>/<source>/velocity`.
#[derive(Parser)]
struct Args {
    #[command(flatten)]
    source: SourceArgs,
    /// Samples per second.
    #[arg(long, default_value_t = 10.0)]
    rate: f64,
    /// Seconds to publish; 0 = until Ctrl-C.
    #[arg(long, default_value_t = 60.0)]
    duration: f64,
    /// Seconds to wait for a subscriber (ghnetd) before sending anyway.
    #[arg(long, default_value_t = 5.0)]
    wait: f64,
    /// Simulation seed: picks the trajectory and the receiver.
    #[arg(long, default_value_t = 1)]
    seed: u64,
}
