//! Sustained throughput: many sources publishing as fast as the target answers,
//! Zenoh output on (with a subscriber here, so every heading really travels), every
//! sequence number checked to be answered exactly once on iceoryx2.
//!
//! Flow control respects the bounded buffers: each source keeps at most
//! `in_flight` samples unanswered (the subscriber buffers are 128 deep, so nothing
//! is overwritten unless the target really loses samples). One thread drives all
//! sources; it sleeps on a `WaitSet` holding every heading listener and tops a
//! source up when its answers come back.

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

pub struct ThroughputRun {
    /// Answers per second over the measurement window (all sources).
    pub rate: f64,
    pub window: Duration,
    pub sent: u64,
    pub answered: u64,
    /// Sequence numbers never answered (gaps, and samples still unanswered 10 s
    /// after the publishers stopped).
    pub lost: u64,
    pub duplicates: u64,
    /// Answers to sequence numbers never sent.
    pub unexpected: u64,
    /// Headings that arrived over Zenoh, against `answered_after_zenoh_ready`.
    pub zenoh_received: u64,
    pub zenoh_expected: u64,
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

#[derive(Default, Clone, Copy)]
struct Source {
    next_send: u64,
    next_answer: u64,
    lost: u64,
    duplicates: u64,
    unexpected: u64,
    answered: u64,
}

impl Source {
    fn in_flight(&self) -> u64 {
        self.next_send - self.next_answer
    }

    fn book(&mut self, seq: u64) {
        if seq >= self.next_send {
            self.unexpected += 1;
        } else if seq >= self.next_answer {
            self.lost += seq - self.next_answer;
            self.next_answer = seq + 1;
            self.answered += 1;
        } else {
            self.duplicates += 1;
        }
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

    let zenoh_count = Arc::new(AtomicU64::new(0));
    let counter = zenoh_count.clone();
    let _zenoh_sub = session
        .declare_subscriber(format!("{}/*/heading", ipc.prefix()))
        .callback(move |s| {
            if decode_zenoh(&s.payload().to_bytes()).is_ok() {
                counter.fetch_add(1, Relaxed);
            }
        })
        .wait()
        .map_err(|e| anyhow::anyhow!("zenoh subscriber: {e}"))?;

    target.wait_until("iceoryx2 connections", Duration::from_secs(60), || {
        pubs.iter().all(|p| p.subscriber_count() > 0)
            && subs.iter().all(|s| s.publisher_count() > 0)
    })?;

    let mut state = vec![Source::default(); sources.len()];
    // Until the Zenoh subscriber's declaration has reached the target, its headings
    // go nowhere: ping source 0 until one arrives over Zenoh.
    let t0 = Instant::now();
    while zenoh_count.load(Relaxed) == 0 {
        target.check_running()?;
        anyhow::ensure!(
            t0.elapsed() < Duration::from_secs(30),
            "no heading over Zenoh"
        );
        let st = &mut state[0];
        pubs[0].send(moving_sample(st.next_send))?;
        st.next_send += 1;
        if let Some(h) = subs[0].recv_timeout(Duration::from_secs(5))? {
            st.book(h.seq);
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    std::thread::sleep(Duration::from_millis(200));
    while let Some(h) = subs[0].try_recv()? {
        state[0].book(h.seq);
    }
    let zenoh_base = zenoh_count.load(Relaxed);
    let rss_connected = Rss::of(target.pid())?;
    let answered_base: u64 = state.iter().map(|s| s.answered).sum();

    let waitset = WaitSetBuilder::new()
        .create::<ipc::Service>()
        .context("WaitSet")?;
    let guards = subs
        .iter()
        .map(|s| waitset.attach_notification(s.listener()))
        .collect::<Result<Vec<_>, _>>()
        .context("attach")?;

    let top_up = |i: usize, st: &mut Source| -> anyhow::Result<()> {
        let p = &pubs[i];
        let mut any = false;
        while st.in_flight() < opt.in_flight {
            let s = moving_sample(st.next_send);
            match opt.notify {
                Notify::Sample => p.send(s)?,
                Notify::Burst => p.publish(s)?,
            }
            st.next_send += 1;
            any = true;
        }
        if any && opt.notify == Notify::Burst {
            p.notify()?;
        }
        Ok(())
    };
    let drain = |i: usize, st: &mut Source| -> anyhow::Result<()> {
        subs[i].drain_notifications()?;
        while let Some(h) = subs[i].try_recv()? {
            if h.heading_status() != Some(HeadingStatus::Stale) {
                st.book(h.seq);
            }
        }
        Ok(())
    };

    let start = Instant::now();
    let warm_end = start + opt.warmup;
    let end = warm_end + opt.window;
    for (i, st) in state.iter_mut().enumerate() {
        top_up(i, st)?;
    }
    let answered = |state: &[Source]| state.iter().map(|s| s.answered).sum::<u64>();
    let mut window_start: Option<(Instant, u64, Duration, Duration)> = None;
    let mut window_end: Option<(Instant, u64, Duration, Duration)> = None;
    let mut fired = Vec::with_capacity(sources.len());
    let mut last_progress = Instant::now();
    loop {
        let now = Instant::now();
        let snapshot = |state: &[Source]| -> anyhow::Result<_> {
            Ok((
                Instant::now(),
                answered(state),
                cpu_time(target.pid())?,
                cpu_time(std::process::id())?,
            ))
        };
        if window_start.is_none() && now >= warm_end {
            window_start = Some(snapshot(&state)?);
        }
        if window_end.is_none() && now >= end {
            window_end = Some(snapshot(&state)?);
        }
        let outstanding: u64 = state.iter().map(Source::in_flight).sum();
        if window_end.is_some()
            && (outstanding == 0 || last_progress.elapsed() > Duration::from_secs(10))
        {
            break;
        }
        let before = answered(&state);
        waitset
            .wait_and_process_once_with_timeout(
                |id: WaitSetAttachmentId<ipc::Service>| {
                    if let Some(i) = guards.iter().position(|g| id.has_event_from(g)) {
                        fired.push(i);
                    }
                    CallbackProgression::Continue
                },
                Duration::from_millis(50),
            )
            .map_err(|e| anyhow::anyhow!("WaitSet: {e:?}"))?;
        for i in fired.drain(..) {
            drain(i, &mut state[i])?;
            if window_end.is_none() {
                top_up(i, &mut state[i])?;
            }
        }
        if answered(&state) > before {
            last_progress = Instant::now();
        } else if last_progress.elapsed() > Duration::from_secs(1) {
            // Nothing for a second: a lost wake-up or a stuck target. Look at every
            // source once (cheap) and make sure the target is alive.
            target.check_running()?;
            for (i, st) in state.iter_mut().enumerate() {
                drain(i, st)?;
                if window_end.is_none() {
                    top_up(i, st)?;
                }
            }
        }
    }
    let rss_after_load = Rss::of(target.pid())?;
    // Let the last Zenoh headings arrive.
    std::thread::sleep(Duration::from_millis(300));
    let (Some(ws), Some(we)) = (window_start, window_end) else {
        anyhow::bail!("the measurement window never started");
    };
    let window = we.0 - ws.0;
    let secs = window.as_secs_f64();
    let total = |f: fn(&Source) -> u64| state.iter().map(f).sum::<u64>();
    let outstanding = total(Source::in_flight);
    Ok(ThroughputRun {
        rate: (we.1 - ws.1) as f64 / secs,
        window,
        sent: total(|s| s.next_send),
        answered: total(|s| s.answered),
        lost: total(|s| s.lost) + outstanding,
        duplicates: total(|s| s.duplicates),
        unexpected: total(|s| s.unexpected),
        zenoh_received: zenoh_count.load(Relaxed) - zenoh_base,
        zenoh_expected: total(|s| s.answered) - answered_base,
        target_cores: (we.2 - ws.2).as_secs_f64() / secs,
        driver_cores: (we.3 - ws.3).as_secs_f64() / secs,
        rss_connected,
        rss_after_load,
    })
}
