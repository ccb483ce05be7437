//! One served source: its ports ([`Source`], made once, when the source is added) and
//! the state that changes while serving it ([`State`]), two values.
//!
//! The event loop's WaitSet guards borrow every source's listener for as long as the
//! set of sources stays the same, so the ports are only ever borrowed shared, while
//! the states, kept apart beside them ([`Sources`]), are borrowed mutably: no cell.

use std::time::{Duration, Instant};

use ghnet_client::iceoryx2::prelude::*;
use ghnet_client::{HeadingEstimate, HeadingPublisher, IpcConfig, VelocitySubscriber};
use ghnet_inference::SourceStream;
use tracing::{debug, info, warn};

use crate::answer::{stale_message, Batch, Counters, Tracker};
use crate::latency::LatencyRing;
use crate::output::{Burst, HeadingOutput};
use crate::remote::{SourceView, ZenohSide};

/// How a source came to be served.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Kind {
    /// From `sources.static`: served from the start, never dropped.
    Static,
    /// Found by discovery: dropped when its publishers are gone.
    Discovered,
}

impl Kind {
    fn as_str(self) -> &'static str {
        match self {
            Kind::Static => "static",
            Kind::Discovered => "discovered",
        }
    }
}

/// A served source.
pub(crate) struct Source {
    pub(crate) name: String,
    pub(crate) kind: Kind,
    pub(crate) velocity: VelocitySubscriber,
    /// Full name of the iceoryx2 heading service, for logs.
    heading_service: String,
    /// Every destination of this source's answers; the iceoryx2 heading service
    /// first. Boxed once per source, so per sample only a virtual call.
    outputs: Vec<Box<dyn HeadingOutput>>,
}

/// The served sources: ports and states side by side, the same index in both.
#[derive(Default)]
pub(crate) struct Sources {
    /// Borrowed by the WaitSet guards while the set stays the same.
    pub(crate) ports: Vec<Source>,
    /// Changed by every sample and housekeeping pass.
    pub(crate) states: Vec<State>,
}

impl Sources {
    /// Adds a source.
    pub(crate) fn push(&mut self, (source, state): (Source, State)) {
        self.ports.push(source);
        self.states.push(state);
    }

    /// Removes the source at `i`, the last taking its place.
    pub(crate) fn swap_remove(&mut self, i: usize) -> (Source, State) {
        (self.ports.swap_remove(i), self.states.swap_remove(i))
    }
}

/// Everything that changes while serving a source.
pub(crate) struct State {
    /// The source's rules, history and counters; made when the source is opened, so
    /// a source that comes back starts afresh (its counters continue).
    pub(crate) tracker: Tracker,
    /// The last answer and recent processing times, for the Zenoh stats queryable
    /// (`last` is also what a `Stale` message echoes).
    pub(crate) last: Option<HeadingEstimate>,
    pub(crate) latency: LatencyRing,
    silence: Silence,
    /// The stats snapshot missed this state's last change (a query held it): the
    /// next housekeeping pass refreshes it, since the source may send nothing more.
    snapshot_behind: bool,
}

impl State {
    /// Drops what the model knows of this source because its publishers are gone:
    /// the vehicle may move before one comes back. Counted in `resets_restart` when
    /// the history had something in it.
    pub(crate) fn forget_history(&mut self) {
        self.tracker.stream.restart();
    }

    /// The counters so far.
    pub(crate) fn counters(&self) -> Counters {
        self.tracker.counters()
    }

    /// What the stats snapshot takes of this state.
    pub(crate) fn view(&self) -> SourceView<'_> {
        SourceView {
            counters: self.tracker.counters(),
            last: self.last,
            latency: &self.latency,
        }
    }
}

/// Silence watch, kept by housekeeping only (the per-sample path does not touch it).
struct Silence {
    /// `received` as seen at the last pass, and when it last changed.
    seen_received: u64,
    last_activity: Instant,
    /// Whether the current silence has had its one `Stale` message.
    stale_sent: bool,
}

impl Source {
    /// Opens the ports of `name` on `node`: the velocity subscriber, the iceoryx2
    /// heading publisher and, with Zenoh on, the Zenoh heading publishers. The
    /// counters continue `counters` (a source that comes back keeps its totals); its
    /// `stream` is new (sequence tracking and history start afresh), since a new
    /// publisher may restart its sequence numbers and its vehicle may have moved.
    pub(crate) fn open(
        node: &Node<ipc::Service>,
        ipc: &IpcConfig,
        zenoh: Option<&ZenohSide>,
        name: &str,
        kind: Kind,
        counters: Counters,
        stream: SourceStream,
    ) -> anyhow::Result<(Self, State)> {
        let velocity = VelocitySubscriber::with_node(node, ipc, name)?;
        let heading = HeadingPublisher::with_node(node, ipc, name)?;
        let heading_service = heading.service_name().to_owned();
        let mut outputs: Vec<Box<dyn HeadingOutput>> = vec![Box::new(heading)];
        if let Some(z) = zenoh {
            outputs.push(Box::new(z.output(ipc, name)?));
        }
        let tracker = Tracker::resume(stream, counters);
        let state = State {
            silence: Silence {
                seen_received: tracker.counters().received,
                last_activity: Instant::now(),
                stale_sent: false,
            },
            tracker,
            last: None,
            latency: LatencyRing::new(),
            snapshot_behind: false,
        };
        let ports = Self {
            name: name.to_owned(),
            kind,
            velocity,
            heading_service,
            outputs,
        };
        Ok((ports, state))
    }

    pub(crate) fn log_added(&self) {
        info!(
            source = %self.name,
            kind = self.kind.as_str(),
            velocity = %self.velocity.service_name(),
            heading = %self.heading_service,
            "source added"
        );
    }

    /// Logs the counters in `state` with `what` as the message (the periodic `stats`
    /// line, and `source removed`).
    pub(crate) fn log_counters(&self, state: &State, what: &str) {
        let c = state.counters();
        info!(
            source = %self.name,
            received = c.received,
            answered = c.answered,
            invalid = c.invalid,
            gaps = c.gaps,
            duplicates = c.duplicates,
            backwards = c.backwards,
            send_errors = c.send_errors,
            stale = c.stale,
            resets_gap = c.resets_gap,
            resets_backwards = c.resets_backwards,
            resets_restart = c.resets_restart,
            publishers = self.velocity.publisher_count(),
            "{what}"
        );
    }

    /// Takes up to `share` of this source's buffered samples into `batch` (`owner`
    /// records `me` per sample), fewer if the batch fills. With `drain` (once per
    /// wake-up: draining costs atomic swaps on a bitset the publishers write to)
    /// consumes the pending wake-up notifications first, or the WaitSet fires again
    /// at once. `true` when the buffer was emptied, `false` when samples are left for
    /// another round.
    pub(crate) fn take_samples(
        &self,
        batch: &mut Batch,
        owner: &mut Vec<usize>,
        me: usize,
        share: usize,
        drain: bool,
    ) -> bool {
        if drain {
            if let Err(e) = self.velocity.drain_notifications() {
                debug!(source = %self.name, error = %e, "draining notifications failed");
            }
        }
        let end = batch.capacity().min(batch.samples.len() + share);
        while batch.samples.len() < end {
            match self.velocity.try_recv() {
                Ok(Some(s)) => {
                    batch.samples.push(s);
                    owner.push(me);
                }
                Ok(None) => return true,
                Err(e) => {
                    warn!(source = %self.name, error = %e, "receiving failed");
                    return true;
                }
            }
        }
        false
    }

    /// Stamps the processing time (since `t0`) on `answer`, publishes it on every
    /// output and books the result; `true` if every output took it.
    pub(crate) fn deliver(
        &self,
        state: &mut State,
        mut answer: HeadingEstimate,
        t0: Instant,
        burst: Burst,
    ) -> bool {
        answer.processing_ns = t0.elapsed().as_nanos() as u64;
        state.latency.push(answer.processing_ns);
        state.last = Some(answer);
        let mut delivered = true;
        for out in &self.outputs {
            if let Err(e) = out.publish(&answer, burst) {
                delivered = false;
                // 1st, 2nd, 4th, 8th, ... failure: visible without flooding the log.
                let n = state.tracker.delivery.send_errors + 1;
                if n.is_power_of_two() {
                    warn!(source = %self.name, output = out.kind(), error = %e, failures = n, "cannot publish heading");
                }
            }
        }
        let c = &mut state.tracker.delivery;
        if delivered {
            c.answered += 1;
        } else {
            c.send_errors += 1;
        }
        delivered
    }

    /// Ends this source's part of a wake-up: wakes its iceoryx2 listeners once for
    /// all its answers (`flush`, if it answered any) and refreshes its Zenoh stats
    /// snapshot.
    pub(crate) fn settle(&self, state: &mut State, answered_any: bool, zenoh: Option<&ZenohSide>) {
        if answered_any {
            for out in &self.outputs {
                if let Err(e) = out.flush() {
                    debug!(source = %self.name, output = out.kind(), error = %e, "flush failed");
                }
            }
        }
        if let Some(z) = zenoh {
            state.snapshot_behind = !z.refresh(&self.name, &state.view());
        }
    }

    /// Housekeeping: refreshes the stats snapshot if a query kept the last refresh
    /// out, so a source that went quiet right after is not reported stale forever.
    pub(crate) fn catch_up_snapshot(&self, state: &mut State, zenoh: Option<&ZenohSide>) {
        if let (Some(z), true) = (zenoh, state.snapshot_behind) {
            state.snapshot_behind = !z.refresh(&self.name, &state.view());
        }
    }

    /// A discovered source whose publishers are all gone, and that has had its
    /// `Stale` message if one is due: housekeeping drops it. A source that answered
    /// something is kept until its Stale message, so consumers of a crashed source
    /// learn it (one that never sent anything has nothing to be stale about).
    pub(crate) fn is_gone(&self, state: &State, stale_after: Option<Duration>) -> bool {
        let stale_pending =
            stale_after.is_some() && state.last.is_some() && !state.silence.stale_sent;
        self.kind == Kind::Discovered && self.velocity.publisher_count() == 0 && !stale_pending
    }

    /// Notices samples since the last pass ("served again" after a Stale message), or
    /// a silence longer than `stale_after`: then publishes ONE `Stale` message on
    /// every output, logs and counts it. The silence is measured from the pass that
    /// last saw a sample, so the message comes between `stale_after` and that plus
    /// two housekeeping intervals after the last sample.
    pub(crate) fn watch_silence(
        &self,
        state: &mut State,
        now: Instant,
        stale_after: Option<Duration>,
        zenoh: Option<&ZenohSide>,
    ) {
        let State {
            tracker,
            last,
            silence,
            ..
        } = state;
        let received = tracker.stream.counts().received;
        if received != silence.seen_received {
            silence.seen_received = received;
            silence.last_activity = now;
            if silence.stale_sent {
                silence.stale_sent = false;
                info!(source = %self.name, "served again: samples arrive after the Stale message");
            }
            return;
        }
        let (Some(after), Some(last)) = (stale_after, *last) else {
            return;
        };
        let silent = now.duration_since(silence.last_activity);
        if silence.stale_sent || silent <= after {
            return;
        }
        silence.stale_sent = true;
        tracker.delivery.stale += 1;
        self.publish_stale(&last, silent);
        if let Some(z) = zenoh {
            state.snapshot_behind = !z.refresh(&self.name, &state.view());
        }
    }

    fn publish_stale(&self, last: &HeadingEstimate, silent: Duration) {
        let msg = stale_message(last);
        for out in &self.outputs {
            if let Err(e) = out.publish(&msg, Burst::Last).and_then(|()| out.flush()) {
                warn!(source = %self.name, output = out.kind(), error = %e, "cannot publish the Stale message");
            }
        }
        warn!(
            source = %self.name,
            last_seq = last.seq,
            silent_ms = silent.as_millis() as u64,
            publishers = self.velocity.publisher_count(),
            "source stale: no sample for longer than sources.stale_after_ms; published one Stale heading"
        );
    }
}
