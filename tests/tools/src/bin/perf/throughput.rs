//! Sustained throughput: many sources publishing as fast as the target answers,
//! Zenoh output on with a subscriber here, every sequence number checked to be
//! answered exactly once on iceoryx2 AND over Zenoh.
//!
//! Flow control respects the bounded buffers: each source keeps at most
//! `in_flight` samples that have not been answered on both outputs (the subscriber
//! buffers are 128 deep, so nothing is overwritten unless the target really loses
//! samples, and Zenoh is never pushed faster than this subscriber takes headings, so
//! its congestion control never has to drop). One thread drives all sources; it
//! sleeps on a `WaitSet` holding every heading listener and tops sources up when
//! answers come back; Zenoh headings are booked on Zenoh's threads.

use std::collections::HashMap;
use std::sync::atomic::{AtomicU64, Ordering::Relaxed};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::Context;
use ghnet_client::iceoryx2::prelude::*;
use ghnet_client::zenoh::{Session, Wait};
use ghnet_client::{
    decode_zenoh, wait_for_listeners, HeadingStatus, HeadingSubscriber, VelocityPublisher,
};

use crate::latency::moving_sample;
use crate::target::{cpu_time, Env, Kind, Rss, Spec, Target};
use crate::{info, row, Args, Row};

/// How the publishers wake the target.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Notify {
    /// `send` = publish + notify per sample, as a GNSS driver does.
    Sample,
    /// Publish a source's burst, then notify once.
    Burst,
}

pub struct Options {
    pub warmup: Duration,
    pub window: Duration,
    pub in_flight: u64,
    pub notify: Notify,
}

/// Losses of one output, summed over the sources.
#[derive(Debug, Default, Clone, Copy)]
pub struct Losses {
    /// Sequence numbers never answered (gaps, and samples still unanswered 10 s
    /// after the publishers stopped).
    pub lost: u64,
    pub duplicates: u64,
    /// Answers to sequence numbers never sent.
    pub unexpected: u64,
    pub answered: u64,
}

impl Losses {
    pub fn none(&self) -> bool {
        self.lost + self.duplicates + self.unexpected == 0
    }
}

pub struct ThroughputRun {
    /// Answers per second on iceoryx2 over the measurement window (all sources).
    pub rate: f64,
    pub window: Duration,
    pub sent: u64,
    pub iceoryx2: Losses,
    pub zenoh: Losses,
    /// Target CPU over the window, in cores (1.0 = one core busy).
    pub target_cores: f64,
    /// This process's CPU over the window, in cores.
    pub driver_cores: f64,
    /// Resident memory of the target with all sources connected and served once,
    /// before the load.
    pub rss_connected: Rss,
    /// The same after the load (Zenoh queues and allocator arenas have grown).
    pub rss_after_load: Rss,
}

/// One output's record of one source's answers. Written by one thread (the
/// driver for iceoryx2, Zenoh's receive task for Zenoh), read by the driver.
#[derive(Default)]
struct Book {
    next_answer: AtomicU64,
    lost: AtomicU64,
    duplicates: AtomicU64,
    unexpected: AtomicU64,
    answered: AtomicU64,
}

impl Book {
    /// Books an answer to `seq`, `sent` samples having been published.
    fn book(&self, seq: u64, sent: u64) {
        let next = self.next_answer.load(Relaxed);
        if seq >= sent {
            self.unexpected.fetch_add(1, Relaxed);
        } else if seq >= next {
            self.lost.fetch_add(seq - next, Relaxed);
            self.next_answer.store(seq + 1, Relaxed);
            self.answered.fetch_add(1, Relaxed);
        } else {
            self.duplicates.fetch_add(1, Relaxed);
        }
    }

    fn add_to(&self, l: &mut Losses, sent: u64) {
        // Whatever is still unanswered at the end is lost.
        l.lost += self.lost.load(Relaxed) + (sent - self.next_answer.load(Relaxed));
        l.duplicates += self.duplicates.load(Relaxed);
        l.unexpected += self.unexpected.load(Relaxed);
        l.answered += self.answered.load(Relaxed);
    }
}

#[derive(Default)]
struct Source {
    /// Raised before each sample is published, so an answer never outruns it.
    next_send: AtomicU64,
    iceoryx2: Book,
    zenoh: Book,
}

impl Source {
    fn sent(&self) -> u64 {
        self.next_send.load(Relaxed)
    }

    /// Samples not yet answered on both outputs.
    fn in_flight(&self) -> u64 {
        let answered = self
            .iceoryx2
            .next_answer
            .load(Relaxed)
            .min(self.zenoh.next_answer.load(Relaxed));
        self.sent() - answered
    }
}

/// Publishers and heading subscribers of every source on one node, and the books.
struct Rig<'a> {
    pubs: Vec<VelocityPublisher>,
    subs: Vec<HeadingSubscriber>,
    state: Arc<[Source]>,
    opt: &'a Options,
}

/// Answers so far and CPU times at one instant (the ends of the window).
#[derive(Clone, Copy)]
struct Snapshot {
    at: Instant,
    answered: u64,
    target_cpu: Duration,
    own_cpu: Duration,
}

pub fn measure(
    target: &Target,
    session: &Session,
    sources: &[String],
    opt: &Options,
) -> anyhow::Result<ThroughputRun> {
    let ipc = target.ipc().clone();
    let node = NodeBuilder::new()
        .config(&ipc.iceoryx2_config())
        .create::<ipc::Service>()
        .context("iceoryx2 node")?;
    let rig = Rig {
        pubs: (sources.iter())
            .map(|s| VelocityPublisher::with_node(&node, &ipc, s))
            .collect::<Result<Vec<_>, _>>()?,
        subs: (sources.iter())
            .map(|s| HeadingSubscriber::with_node(&node, &ipc, s))
            .collect::<Result<Vec<_>, _>>()?,
        state: sources.iter().map(|_| Source::default()).collect(),
        opt,
    };
    let _zenoh_sub = book_zenoh(session, &ipc, sources, rig.state.clone())?;
    target.wait_until("iceoryx2 connections", Duration::from_secs(60), || {
        rig.pubs.iter().all(|p| p.subscriber_count() > 0)
            && rig.subs.iter().all(|s| s.publisher_count() > 0)
    })?;
    rig.warm_up(target)?;
    let rss_connected = Rss::of(target.pid())?;
    let (start, end) = rig.drive(target)?;
    let rss_after_load = Rss::of(target.pid())?;
    Ok(rig.result(start, end, rss_connected, rss_after_load))
}

/// A callback subscriber on `<prefix>/*/heading` booking every Zenoh heading.
fn book_zenoh(
    session: &Session,
    ipc: &ghnet_client::IpcConfig,
    sources: &[String],
    state: Arc<[Source]>,
) -> anyhow::Result<ghnet_client::zenoh::pubsub::Subscriber<()>> {
    let index: HashMap<String, usize> = (sources.iter().enumerate())
        .map(|(i, s)| Ok((ipc.zenoh_heading_key(s)?, i)))
        .collect::<anyhow::Result<_>>()?;
    session
        .declare_subscriber(format!("{}/*/heading", ipc.prefix()))
        .callback(move |s| {
            let (Some(&i), Ok(h)) = (
                index.get(s.key_expr().as_str()),
                decode_zenoh(&s.payload().to_bytes()),
            ) else {
                return;
            };
            if h.heading_status() != Some(HeadingStatus::Stale) {
                let src = &state[i];
                src.zenoh.book(h.seq, src.sent());
            }
        })
        .wait()
        .map_err(|e| anyhow::anyhow!("zenoh subscriber: {e}"))
}

impl Rig<'_> {
    fn send(&self, i: usize, notify: bool) -> anyhow::Result<()> {
        let seq = self.state[i].next_send.fetch_add(1, Relaxed);
        let s = moving_sample(seq);
        if notify {
            self.pubs[i].send(s)?;
        } else {
            self.pubs[i].publish(s)?;
        }
        Ok(())
    }

    fn drain(&self, i: usize) -> anyhow::Result<()> {
        self.subs[i].drain_notifications()?;
        while let Some(h) = self.subs[i].try_recv()? {
            if h.heading_status() != Some(HeadingStatus::Stale) {
                self.state[i].iceoryx2.book(h.seq, self.state[i].sent());
            }
        }
        Ok(())
    }

    /// Tops source `i` up to `in_flight` unanswered samples.
    fn top_up(&self, i: usize) -> anyhow::Result<()> {
        let mut any = false;
        while self.state[i].in_flight() < self.opt.in_flight {
            self.send(i, self.opt.notify == Notify::Sample)?;
            any = true;
        }
        if any && self.opt.notify == Notify::Burst {
            self.pubs[i].notify()?;
        }
        Ok(())
    }

    fn answered(&self) -> u64 {
        (self.state.iter())
            .map(|s| s.iceoryx2.answered.load(Relaxed))
            .sum()
    }

    fn snapshot(&self, target: &Target) -> anyhow::Result<Snapshot> {
        Ok(Snapshot {
            at: Instant::now(),
            answered: self.answered(),
            target_cpu: cpu_time(target.pid())?,
            own_cpu: cpu_time(std::process::id())?,
        })
    }

    /// Until the Zenoh subscriber's declaration has reached the target, its headings
    /// go nowhere: pings source 0 until one arrives over Zenoh.
    fn warm_up(&self, target: &Target) -> anyhow::Result<()> {
        let t0 = Instant::now();
        while self.state[0].zenoh.answered.load(Relaxed) == 0 {
            target.check_running()?;
            anyhow::ensure!(
                t0.elapsed() < Duration::from_secs(30),
                "no heading over Zenoh"
            );
            self.send(0, true)?;
            if let Some(h) = self.subs[0].recv_timeout(Duration::from_secs(5))? {
                self.state[0].iceoryx2.book(h.seq, self.state[0].sent());
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        std::thread::sleep(Duration::from_millis(200));
        self.drain(0)?;
        // The pings answered before the subscription reached the target had nowhere
        // to go over Zenoh; they are not losses.
        self.state[0].zenoh.lost.store(0, Relaxed);
        Ok(())
    }

    /// The load: warm-up, then the measurement window, then until every sample is
    /// answered (or nothing moved for 10 s). Returns the window's two ends.
    fn drive(&self, target: &Target) -> anyhow::Result<(Snapshot, Snapshot)> {
        let waitset = WaitSetBuilder::new()
            .create::<ipc::Service>()
            .context("WaitSet")?;
        let guards = (self.subs.iter())
            .map(|s| waitset.attach_notification(s.listener()))
            .collect::<Result<Vec<_>, _>>()
            .context("attach")?;
        let warm_end = Instant::now() + self.opt.warmup;
        let end = warm_end + self.opt.window;
        let (mut window_start, mut window_end) = (None, None);
        let mut fired = Vec::with_capacity(self.subs.len());
        let mut progress = Progress::new();
        loop {
            let now = Instant::now();
            if window_start.is_none() && now >= warm_end {
                window_start = Some(self.snapshot(target)?);
            }
            if window_end.is_none() && now >= end {
                window_end = Some(self.snapshot(target)?);
            }
            if window_end.is_some() && (self.outstanding() == 0 || progress.stalled_for(10)) {
                break;
            }
            // Zenoh answers come on Zenoh's threads and wake nobody here: the short
            // timeout tops up a source held back by its Zenoh answers soon after they
            // arrive, even when no iceoryx2 answer does.
            wait_for_listeners(&waitset, &guards, Duration::from_millis(1), &mut fired)
                .map_err(|e| anyhow::anyhow!("WaitSet: {e:?}"))?;
            for i in fired.drain(..) {
                self.drain(i)?;
            }
            if window_end.is_none() {
                (0..self.state.len()).try_for_each(|i| self.top_up(i))?;
            }
            if progress.update(self.answered(), self.zenoh_answered()) {
                // Nothing for a second: a lost wake-up or a stuck target. Look at every
                // source once (cheap) and make sure the target is alive.
                target.check_running()?;
                (0..self.state.len()).try_for_each(|i| self.drain(i))?;
            }
        }
        match (window_start, window_end) {
            (Some(s), Some(e)) => Ok((s, e)),
            _ => anyhow::bail!("the measurement window never started"),
        }
    }

    fn zenoh_answered(&self) -> u64 {
        (self.state.iter())
            .map(|s| s.zenoh.answered.load(Relaxed))
            .sum()
    }

    fn outstanding(&self) -> u64 {
        self.state.iter().map(Source::in_flight).sum()
    }

    fn result(&self, ws: Snapshot, we: Snapshot, connected: Rss, after: Rss) -> ThroughputRun {
        let window = we.at - ws.at;
        let secs = window.as_secs_f64();
        let (mut iceoryx2, mut zenoh) = (Losses::default(), Losses::default());
        for s in self.state.iter() {
            s.iceoryx2.add_to(&mut iceoryx2, s.sent());
            s.zenoh.add_to(&mut zenoh, s.sent());
        }
        ThroughputRun {
            rate: (we.answered - ws.answered) as f64 / secs,
            window,
            sent: self.state.iter().map(Source::sent).sum(),
            iceoryx2,
            zenoh,
            target_cores: (we.target_cpu - ws.target_cpu).as_secs_f64() / secs,
            driver_cores: (we.own_cpu - ws.own_cpu).as_secs_f64() / secs,
            rss_connected: connected,
            rss_after_load: after,
        }
    }
}

/// When the answers last moved.
struct Progress {
    seen: (u64, u64),
    at: Instant,
}

impl Progress {
    fn new() -> Self {
        Self {
            seen: (0, 0),
            at: Instant::now(),
        }
    }

    /// Records the answers on both outputs; `true` when nothing moved for a second.
    fn update(&mut self, iceoryx2: u64, zenoh: u64) -> bool {
        if (iceoryx2, zenoh) != self.seen {
            (self.seen, self.at) = ((iceoryx2, zenoh), Instant::now());
            return false;
        }
        self.stalled_for(1)
    }

    fn stalled_for(&self, seconds: u64) -> bool {
        self.at.elapsed() > Duration::from_secs(seconds)
    }
}

/// Phase 3: throughput with all sources, raw echo then ghnetd; resident memory
/// before and after the load.
pub fn rows(args: &Args, env: &Env, session: &Session, endpoint: &str) -> anyhow::Result<Vec<Row>> {
    let names: Vec<String> = (0..args.sources).map(|i| format!("tp{i:03}")).collect();
    let opt = Options {
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
        let t = Target::spawn(env, &spec)?;
        let r = measure(&t, session, &names, &opt)?;
        eprintln!("throughput {}: {r}", kind.label());
        t.stop()?;
        tp.push(r);
    }
    let (tr, td) = (&tp[0], &tp[1]);
    let mut rows = rate_rows(args, tr, td);
    rows.extend(memory_rows(args, tr, td));
    Ok(rows)
}

impl std::fmt::Display for ThroughputRun {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let (c, a) = (&self.rss_connected, &self.rss_after_load);
        write!(
            f,
            "{:.0} samples/s over {:.1?}; sent {}; iceoryx2 {:?}; zenoh {:?}; target {:.2} cores, driver {:.2} cores; RSS connected {:.1} MiB, after load {:.1} MiB (anon {} KiB, shm {} KiB, peak {} KiB)",
            self.rate,
            self.window,
            self.sent,
            self.iceoryx2,
            self.zenoh,
            self.target_cores,
            self.driver_cores,
            c.total_mib(),
            a.total_mib(),
            a.anon_kib,
            a.shmem_kib,
            a.peak_kib
        )
    }
}

/// The share of the raw echo's throughput ghnetd must keep with the default model in
/// the same run: the model may cost, but not most of the daemon's capacity.
/// The echo itself spreads by ±10% between runs on a 2-core VM, so one run can land
/// on either side; quote several.
const THROUGHPUT_RATIO: f64 = 0.6;

/// Rate, losses and CPU of the raw echo (`tr`) and ghnetd (`td`).
fn rate_rows(args: &Args, tr: &ThroughputRun, td: &ThroughputRun) -> Vec<Row> {
    vec![
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
            "throughput: ghnetd / raw echo in this run",
            "1".into(),
            format!("{:.2}", td.rate / tr.rate),
            format!("≥ {THROUGHPUT_RATIO}"),
            Some(td.rate >= THROUGHPUT_RATIO * tr.rate),
        ),
        row(
            "throughput: lost / duplicate / unexpected on iceoryx2 \\| over Zenoh (every seq checked on both)",
            losses(tr),
            losses(td),
            "0 / 0 / 0 \\| 0 / 0 / 0".into(),
            Some(td.iceoryx2.none() && td.zenoh.none()),
        ),
        info(
            "throughput: CPU of target / of the driving perf process (cores)",
            format!("{:.2} / {:.2}", tr.target_cores, tr.driver_cores),
            format!("{:.2} / {:.2}", td.target_cores, td.driver_cores),
        ),
    ]
}

/// Resident memory with every source connected, and after the load.
fn memory_rows(args: &Args, tr: &ThroughputRun, td: &ThroughputRun) -> Vec<Row> {
    let mib = |kib: u64| format!("{:.1} MiB", kib as f64 / 1024.0);
    let parts = |r: &Rss| format!("{} / {}", mib(r.anon_kib), mib(r.shmem_kib));
    let after = |r: &Rss| format!("{} ({})", mib(r.total_kib), parts(r));
    vec![
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
        info(
            "  anonymous / iceoryx2 shared memory of it",
            parts(&tr.rss_connected),
            parts(&td.rss_connected),
        ),
        info(
            "VmRSS after the throughput load (anonymous / shared memory)",
            after(&tr.rss_after_load),
            after(&td.rss_after_load),
        ),
    ]
}

/// `lost / duplicate / unexpected` on both outputs, and of how many sent.
fn losses(r: &ThroughputRun) -> String {
    let f = |l: &Losses| format!("{} / {} / {}", l.lost, l.duplicates, l.unexpected);
    format!("{} \\| {} of {}", f(&r.iceoryx2), f(&r.zenoh), r.sent)
}
