//! `zenoh_subscriber`: prints the headings ghnetd publishes on Zenoh for one source.
//!
//! Run (with `ghnetd` and `publisher` in other terminals, see examples/README.md):
//!
//! ```text
//! cargo run -p ghnet-examples --bin zenoh_subscriber -- --source gnss0
//! cargo run -p ghnet-examples --bin zenoh_subscriber -- --connect tcp/127.0.0.1:7447 --count 10
//! ```
//!
//! A consumer without shared memory (another host, a container, another language)
//! reads `<prefix>/<source>/heading` from Zenoh. The payload is the 64-byte layout of
//! client/README.md, decoded by `ZenohHeadingSubscriber`; a payload that is not a
//! heading is an error value, never a panic. Same table as `subscriber`.

use std::time::Duration;

use clap::Parser;
use ghnet_client::ZenohHeadingSubscriber;
use ghnet_examples::{latency_since, table, SourceArgs, ZenohArgs};

fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    let ipc = args.source.ipc()?;
    let session = args.zenoh.open()?;
    let headings = ZenohHeadingSubscriber::new(&session, &ipc, &args.source.name)?;
    println!("listening on zenoh key {}", headings.key());
    println!("{}", table::header());
    let (mut received, mut bad) = (0u64, 0u64);
    // No iceoryx2 here, so Ctrl-C ends the process the usual way.
    while args.count == 0 || received < args.count {
        match headings.recv_timeout(Duration::from_secs(1)) {
            Ok(Some(h)) => {
                println!("{}", table::row(&h, latency_since(h.timestamp_ns)));
                received += 1;
            }
            Ok(None) => {}
            Err(e) => {
                bad += 1;
                eprintln!("skipping a payload that is not a heading: {e}");
            }
        }
    }
    println!("received {received} headings ({bad} undecodable payloads)");
    Ok(())
}

/// Prints `<prefix>/<source>/heading` from Zenoh until Ctrl-C (or `--count`).
#[derive(Parser)]
struct Args {
    #[command(flatten)]
    source: SourceArgs,
    #[command(flatten)]
    zenoh: ZenohArgs,
    /// Stop after this many headings; 0 = until Ctrl-C.
    #[arg(long, default_value_t = 0)]
    count: u64,
}
