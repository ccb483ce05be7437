//! `subscriber`: prints the headings ghnetd publishes for one source as a live table.
//!
//! Run (with `ghnetd` and `publisher` in other terminals, see examples/README.md):
//!
//! ```text
//! cargo run -p ghnet-examples --bin subscriber -- --source gnss0
//! ```
//!
//! `HeadingSubscriber::recv_timeout` sleeps on the paired event service (no busy
//! polling) and wakes at least once a second, so the loop can check
//! `termination_requested()` (iceoryx2 captures Ctrl-C). Every heading echoes its
//! sample's `seq` and `timestamp_ns` (latency = receipt − timestamp), and its `status`
//! says whether the heading may be used.

use std::time::Duration;

use clap::Parser;
use ghnet_client::{termination_requested, HeadingSubscriber, RecvError};
use ghnet_examples::{latency_since, table, SourceArgs};

fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    let ipc = args.source.ipc()?;
    let headings = HeadingSubscriber::new(&ipc, &args.source.name)?;
    println!("listening on {}", headings.service_name());
    println!("{}", table::header());

    let (mut received, mut quiet) = (0u64, false); // report a silence once
    while (args.count == 0 || received < args.count) && !termination_requested() {
        match headings.recv_timeout(Duration::from_secs(1)) {
            Ok(Some(h)) => {
                println!("{}", table::row(&h, latency_since(h.timestamp_ns)));
                (received, quiet) = (received + 1, false);
            }
            Ok(None) if !quiet => {
                eprintln!("(no heading for 1 s: is ghnetd running and a publisher sending?)");
                quiet = true;
            }
            Ok(None) => {}
            Err(RecvError::Interrupted) => break, // Ctrl-C
            Err(e) => return Err(e.into()),
        }
    }
    println!("received {received} headings");
    Ok(())
}

/// Prints `<prefix>/<source>/heading` as a table until Ctrl-C (or `--count`).
#[derive(Parser)]
struct Args {
    #[command(flatten)]
    source: SourceArgs,
    /// Stop after this many headings; 0 = until Ctrl-C.
    #[arg(long, default_value_t = 0)]
    count: u64,
}
