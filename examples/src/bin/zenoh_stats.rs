//! `zenoh_stats`: asks running ghnetd daemons for their counters and model.
//!
//! Run (with `ghnetd` running, see examples/README.md):
//!
//! ```text
//! cargo run -p ghnet-examples --bin zenoh_stats
//! ```
//!
//! ghnetd announces itself with a liveliness token `<prefix>/@ghnetd/<zid>` and
//! answers Zenoh queries on `<prefix>/@ghnetd/stats` (per-source counters, last
//! sequence number and heading, processing-time percentiles) and
//! `<prefix>/@ghnetd/model` (the model metadata). Queries are made without
//! consolidation, so every daemon on the prefix answers.

use std::time::Duration;

use clap::Parser;
use ghnet_client::zenoh::query::ConsolidationMode;
use ghnet_client::zenoh::Wait;
use ghnet_examples::{CommonArgs, ZenohArgs};

fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    let ipc = args.common.ipc()?;
    let session = args.zenoh.open()?;
    let timeout = Duration::from_millis(args.timeout_ms);
    // A peer connects in the background; give it the timeout to get there.
    let t0 = std::time::Instant::now();
    while session.info().peers_zid().wait().next().is_none() && t0.elapsed() < timeout {
        std::thread::sleep(Duration::from_millis(10));
    }
    let err = |e| anyhow::anyhow!("zenoh: {e}");

    let presence = ipc.zenoh_presence_key("*");
    let tokens = (session.liveliness().get(presence.as_str()))
        .timeout(timeout)
        .wait()
        .map_err(err)?;
    while let Ok(Ok(sample)) = tokens.recv().map(|r| r.into_result()) {
        println!("daemon alive: {}", sample.key_expr());
    }
    let mut answers = 0;
    for key in [ipc.zenoh_stats_key(), ipc.zenoh_model_key()] {
        let replies = (session.get(key.as_str()))
            .consolidation(ConsolidationMode::None)
            .timeout(timeout)
            .wait()
            .map_err(err)?;
        while let Ok(reply) = replies.recv() {
            let Ok(sample) = reply.result() else { continue };
            let json: serde_json::Value = serde_json::from_slice(&sample.payload().to_bytes())?;
            println!("{key}:\n{}", serde_json::to_string_pretty(&json)?);
            answers += 1;
        }
    }
    let prefix = ipc.prefix();
    anyhow::ensure!(answers > 0, "no ghnetd answered on prefix {prefix} (is it running with zenoh.enabled, and --connect its zenoh.listen?)");
    Ok(())
}

/// Prints every daemon's presence token, stats and model metadata on `--prefix`.
#[derive(Parser)]
struct Args {
    #[command(flatten)]
    common: CommonArgs,
    #[command(flatten)]
    zenoh: ZenohArgs,
    /// How long to wait for answers, ms (the session connects first).
    #[arg(long, default_value_t = 2000)]
    timeout_ms: u64,
}
