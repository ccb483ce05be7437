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
use ghnet_client::{decode_zenoh, HeadingStatus, HeadingSubscriber, VelocityPublisher};

use crate::latency::moving_sample;
use crate::target::{cpu_time, Rss, Target};

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

pub fn measure(
    target: &mut Target,
    session: &Session,
    sources: &[String],
    opt: &Options,
) -> anyhow::Result<ThroughputRun> {
    let ipc = target.ipc.clone();
    let node = NodeBuilder::new()
        .config(&ipc.iceoryx2_config())
        .create::<ipc::Service>()
        .context("iceoryx2 node")?;
    let pubs = sources
        .iter()
        .map(|s| VelocityPublisher::with_node(&node, &ipc, s))
        .collect::<Result<Vec<_>, _>>()?;
    let subs = sources
        .iter()
        .map(|s| HeadingSubscriber::with_node(&node, &ipc, s))
        .collect::<Result<Vec<_>, _>>()?;

    let state: Arc<[Source]> = sources.iter().map(|_| Source::default()).collect();
    let index: HashMap<String, usize> = sources
        .iter()
        .enumerate()
        .map(|(i, s)| Ok((ipc.zenoh_heading_key(s)?, i)))
        .collect::<anyhow::Result<_>>()?;
    let zenoh_state = state.clone();
    let _zenoh_sub = session
        .declare_subscriber(format!("{}/*/heading", ipc.prefix()))
        .callback(move |s| {
            let (Some(&i), Ok(h)) = (
                index.get(s.key_expr().as_str()),
                decode_zenoh(&s.payload().to_bytes()),
            ) else {
                return;
            };
            if h.heading_status() != Some(HeadingStatus::Stale) {
                let src = &zenoh_state[i];
                src.zenoh.book(h.seq, src.sent());
            }
        })
        .wait()
        .map_err(|e| anyhow::anyhow!("zenoh subscriber: {e}"))?;

    target.wait_until("iceoryx2 connections", Duration::from_secs(60), || {
        pubs.iter().all(|p| p.subscriber_count() > 0)
            && subs.iter().all(|s| s.publisher_count() > 0)
    })?;

    let send = |i: usize, notify: bool| -> anyhow::Result<()> {
        let seq = state[i].next_send.fetch_add(1, Relaxed);
        let s = moving_sample(seq);
        if notify {
            pubs[i].send(s)?;
        } else {
            pubs[i].publish(s)?;
        }
        Ok(())
    };
    let drain = |i: usize| -> anyhow::Result<()> {
        subs[i].drain_notifications()?;
        while let Some(h) = subs[i].try_recv()? {
            if h.heading_status() != Some(HeadingStatus::Stale) {
                state[i].iceoryx2.book(h.seq, state[i].sent());
            }
        }
        Ok(())
    };

    // Until the Zenoh subscriber's declaration has reached the target, its headings
    // go nowhere: ping source 0 until one arrives over Zenoh.
    let t0 = Instant::now();
    while state[0].zenoh.answered.load(Relaxed) == 0 {
        target.check_running()?;
        anyhow::ensure!(
            t0.elapsed() < Duration::from_secs(30),
            "no heading over Zenoh"
        );
        send(0, true)?;
        if let Some(h) = subs[0].recv_timeout(Duration::from_secs(5))? {
            state[0].iceoryx2.book(h.seq, state[0].sent());
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    std::thread::sleep(Duration::from_millis(200));
    drain(0)?;
    // The pings answered before the subscription reached the target had nowhere to
    // go over Zenoh; they are not losses.
    state[0].zenoh.lost.store(0, Relaxed);
    let rss_connected = Rss::of(target.pid())?;

    let waitset = WaitSetBuilder::new()
        .create::<ipc::Service>()
        .context("WaitSet")?;
    let guards = subs
        .iter()
        .map(|s| waitset.attach_notification(s.listener()))
        .collect::<Result<Vec<_>, _>>()
        .context("attach")?;

    let top_up = |i: usize| -> anyhow::Result<()> {
        let mut any = false;
        while state[i].in_flight() < opt.in_flight {
            send(i, opt.notify == Notify::Sample)?;
            any = true;
        }
        if any && opt.notify == Notify::Burst {
            pubs[i].notify()?;
        }
        Ok(())
    };
    let answered = || {
        state
            .iter()
            .map(|s| s.iceoryx2.answered.load(Relaxed))
            .sum::<u64>()
    };
    let outstanding = || state.iter().map(Source::in_flight).sum::<u64>();

    let start = Instant::now();
    let warm_end = start + opt.warmup;
    let end = warm_end + opt.window;
    let mut window_start: Option<(Instant, u64, Duration, Duration)> = None;
    let mut window_end: Option<(Instant, u64, Duration, Duration)> = None;
    let mut fired = Vec::with_capacity(sources.len());
    let mut last_progress = Instant::now();
    let mut progress_seen = (0, 0);
    loop {
        let now = Instant::now();
        let snapshot = || -> anyhow::Result<_> {
            Ok((
                Instant::now(),
                answered(),
                cpu_time(target.pid())?,
                cpu_time(std::process::id())?,
            ))
        };
        if window_start.is_none() && now >= warm_end {
            window_start = Some(snapshot()?);
        }
        if window_end.is_none() && now >= end {
            window_end = Some(snapshot()?);
        }
        if window_end.is_some()
            && (outstanding() == 0 || last_progress.elapsed() > Duration::from_secs(10))
        {
            break;
        }
        // Zenoh answers come on Zenoh's threads and wake nobody here: the short
        // timeout tops up a source held back by its Zenoh answers soon after they
        // arrive, even when no iceoryx2 answer does.
        waitset
            .wait_and_process_once_with_timeout(
                |id: WaitSetAttachmentId<ipc::Service>| {
                    if let Some(i) = guards.iter().position(|g| id.has_event_from(g)) {
                        fired.push(i);
                    }
                    CallbackProgression::Continue
                },
                Duration::from_millis(1),
            )
            .map_err(|e| anyhow::anyhow!("WaitSet: {e:?}"))?;
        for i in fired.drain(..) {
            drain(i)?;
        }
        if window_end.is_none() {
            for i in 0..state.len() {
                top_up(i)?;
            }
        }
        let zenoh_answered: u64 = state.iter().map(|s| s.zenoh.answered.load(Relaxed)).sum();
        let seen = (answered(), zenoh_answered);
        if seen != progress_seen {
            progress_seen = seen;
            last_progress = Instant::now();
        } else if last_progress.elapsed() > Duration::from_secs(1) {
            // Nothing for a second: a lost wake-up or a stuck target. Look at every
            // source once (cheap) and make sure the target is alive.
            target.check_running()?;
            for i in 0..state.len() {
                drain(i)?;
            }
        }
    }
    let rss_after_load = Rss::of(target.pid())?;
    let (Some(ws), Some(we)) = (window_start, window_end) else {
        anyhow::bail!("the measurement window never started");
    };
    let window = we.0 - ws.0;
    let secs = window.as_secs_f64();
    let (mut iceoryx2, mut zenoh) = (Losses::default(), Losses::default());
    for s in state.iter() {
        s.iceoryx2.add_to(&mut iceoryx2, s.sent());
        s.zenoh.add_to(&mut zenoh, s.sent());
    }
    Ok(ThroughputRun {
        rate: (we.1 - ws.1) as f64 / secs,
        window,
        sent: state.iter().map(Source::sent).sum(),
        iceoryx2,
        zenoh,
        target_cores: (we.2 - ws.2).as_secs_f64() / secs,
        driver_cores: (we.3 - ws.3).as_secs_f64() / secs,
        rss_connected,
        rss_after_load,
    })
}
