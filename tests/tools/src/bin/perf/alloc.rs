//! Allocations per sample on the daemon's thread. A counting global allocator in
//! this binary counts only on threads that ask for it; `ghnetd::run` (the same
//! library the `ghnetd` binary is a shell around) runs in-process on such a thread,
//! and the count over a window of answered samples, divided by the samples, is the
//! figure. Everything on that thread counts: receive, model, both outputs and
//! housekeeping; Zenoh's own runtime threads do not.

use std::time::Duration;

use ghnet_client::zenoh::{Session, Wait};
use ghnet_client::{HeadingSubscriber, VelocityPublisher};

use ghnet_testkit::TestNamespace;

use crate::latency::moving_sample;
use crate::{row, Args, Row};

use ghnet_client::testing::alloc::{allocations, count_this_thread, CountingAllocator};

#[global_allocator]
static GLOBAL: CountingAllocator = CountingAllocator;

/// Allocations per answered sample on the daemon thread, one sample in flight,
/// with the Zenoh output on (and a subscriber on `session`) or off.
fn per_sample(
    model: &str,
    zenoh: Option<(&Session, String)>,
    warmup: u64,
    n: u64,
) -> anyhow::Result<f64> {
    let ns = TestNamespace::new("perfalloc");
    let mut config = ghnetd::Config::default();
    config.ipc.iceoryx2_global_prefix = Some(ns.global_prefix().to_owned());
    config.ipc.iceoryx2_root_path = Some(ns.root_path().to_owned());
    config.sources.static_sources = vec!["alloc0".into()];
    config.sources.discovery = false;
    config.model.name = model.to_owned();
    config.stats.interval_s = 0;
    config.zenoh.enabled = zenoh.is_some();
    config.zenoh.listen = vec![format!("tcp/127.0.0.1:{}", ghnet_testkit::free_tcp_port())];
    if let Some((_, endpoint)) = &zenoh {
        config.zenoh.connect = vec![endpoint.clone()];
    }
    let ipc = ns.ipc();
    let shutdown = ghnetd::ShutdownFlag::new();
    let stop = shutdown.clone();
    let daemon = std::thread::spawn(move || {
        count_this_thread();
        ghnetd::run(config, stop)
    });
    let result = (|| -> anyhow::Result<f64> {
        let gnss = VelocityPublisher::new(&ipc, "alloc0")?;
        let headings = HeadingSubscriber::new(&ipc, "alloc0")?;
        let _zenoh_sub = match &zenoh {
            Some((session, _)) => Some(
                session
                    .declare_subscriber(ipc.zenoh_heading_key("alloc0")?)
                    .callback(|_| {})
                    .wait()
                    .map_err(|e| anyhow::anyhow!("zenoh subscriber: {e}"))?,
            ),
            None => None,
        };
        let t0 = std::time::Instant::now();
        while gnss.subscriber_count() == 0 || headings.publisher_count() == 0 {
            anyhow::ensure!(!daemon.is_finished(), "in-process ghnetd ended early");
            anyhow::ensure!(t0.elapsed() < Duration::from_secs(30), "ghnetd not serving");
            std::thread::sleep(Duration::from_millis(1));
        }
        let round = |seq: u64| -> anyhow::Result<()> {
            gnss.send(moving_sample(seq))?;
            loop {
                match headings.recv_timeout(Duration::from_secs(5))? {
                    Some(h) if h.seq == seq => return Ok(()),
                    Some(_) => {}
                    None => anyhow::bail!("no answer to {seq}"),
                }
            }
        };
        for seq in 0..warmup {
            round(seq)?;
        }
        let before = allocations();
        for seq in warmup..warmup + n {
            round(seq)?;
        }
        Ok((allocations() - before) as f64 / n as f64)
    })();
    shutdown.request();
    let stats = daemon
        .join()
        .map_err(|_| anyhow::anyhow!("in-process ghnetd panicked"))?;
    let per_sample = result?;
    stats?;
    Ok(per_sample)
}

/// Phase 6: allocations per sample on the daemon thread (in-process `ghnetd::run`).
pub fn rows(args: &Args, session: &Session, endpoint: &str) -> anyhow::Result<Vec<Row>> {
    let n_alloc = (args.samples / 5).max(1_000);
    let alloc_ice = per_sample(&args.model, None, 1_000, n_alloc)?;
    let alloc_zenoh = per_sample(
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
