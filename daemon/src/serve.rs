//! The event loop: one iceoryx2 node, one WaitSet, one thread.
//!
//! Each served source owns its ports (velocity subscriber + listener, and per output
//! the heading publisher + notifier), made once when the source is added. The WaitSet holds one
//! notification attachment per source listener and one interval ("housekeeping") for
//! discovery, liveness, dead-node cleanup and the stats line. Its guards borrow the
//! ports, so the set of sources can only change between attachment scopes: when
//! housekeeping finds a change, the scope ends, the change is applied, and the
//! attachments are made again (rare, and nothing is lost: pending notifications stay
//! in the listeners).
//!
//! A wait collects the sources whose listeners fired; they are then served together
//! in rounds of up to [`BATCH`] samples (`Daemon::serve_round`), so receivers on one
//! epoch share a model call and a Zenoh network batch.

use std::collections::{BTreeMap, BTreeSet};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::Context;
use ghnet_client::iceoryx2::prelude::*;
use ghnet_client::iceoryx2::service::static_config::messaging_pattern::MessagingPattern as PatternConfig;
use ghnet_client::{
    HeadingEstimate, HeadingPublisher, IpcConfig, VelocitySubscriber, SERVICE_SETTINGS,
};
use ghnet_models::{Model, Predictor};
use tracing::{debug, info, warn};

use crate::answer::{stale_message, Batch, Counters, Limits, ModelTag, Tracker};
use crate::config::Config;
use crate::output::{Burst, HeadingOutput};
use crate::remote::{LatencyRing, ZenohSide};
use crate::{ShutdownFlag, Stats};

/// Longest the loop sleeps without looking at the shutdown flag. Signals interrupt
/// the wait at once; this bounds the reaction to a flag set by another thread.
const SHUTDOWN_POLL: Duration = Duration::from_millis(100);

/// Most often the housekeeping pass looks for dead processes. Visiting every iceoryx2
/// node under the root costs tens of microseconds per node (each client port has its
/// own node), which at every 250 ms pass was most of ghnetd's idle CPU; a publisher
/// killed with -9 is still noticed within about a second.
const NODE_CLEANUP_EVERY: Duration = Duration::from_secs(1);

/// The ports of one source. Only shared borrows are needed to serve it, which is
/// what lets the WaitSet guards borrow the listeners at the same time.
struct Ports {
    name: String,
    is_static: bool,
    velocity: VelocitySubscriber,
    /// Full name of the iceoryx2 heading service, for logs.
    heading_service: String,
    /// Every destination of this source's answers; the iceoryx2 heading service
    /// first. Boxed once per source, so per sample only a virtual call.
    outputs: Vec<Box<dyn HeadingOutput>>,
}

/// Everything that changes while serving a source.
struct State {
    tracker: Tracker,
    /// The last answer and recent processing times, for the Zenoh stats queryable
    /// (`last` is also what a `Stale` message echoes).
    last: Option<HeadingEstimate>,
    latency: LatencyRing,
    /// Silence watch, kept by housekeeping only (the per-sample path stays as it
    /// is): `received` as seen at the last pass, when it last changed, and whether
    /// the current silence has had its one `Stale` message.
    seen_received: u64,
    last_activity: Instant,
    stale_sent: bool,
}

impl State {
    fn new(tracker: Tracker) -> Self {
        Self {
            seen_received: tracker.counters.received,
            tracker,
            last: None,
            latency: LatencyRing::new(),
            last_activity: Instant::now(),
            stale_sent: false,
        }
    }

    /// A source that answered something and has not had its Stale message for the
    /// current silence yet. A discovered source whose publishers are gone is kept
    /// until then, so consumers of a crashed source learn it (a source that never
    /// sent anything has nothing to be stale about).
    fn stale_pending(&self, stale_after: Option<Duration>) -> bool {
        stale_after.is_some() && self.last.is_some() && !self.stale_sent
    }
}

/// Most samples answered in one round (one model call): a full subscriber buffer,
/// so one source that fell behind is one call, and 128 receivers on one epoch too.
const BATCH: usize = SERVICE_SETTINGS.subscriber_buffer_size;

/// Fewest buffered samples that go through the batch path. One sample (the normal
/// case: one in flight per source) takes `forward_one`, the lowest latency; from
/// this many on, `predict_batch_with_accuracy` costs less in total (measured with
/// `perf`: per sample about half of `forward_one` from 4 on).
const BATCH_MIN: usize = 4;

/// Per wake-up scratch of [`Daemon::serve_round`], sized when the attachments are
/// made so that a wake-up allocates nothing.
#[derive(Default)]
struct Wake {
    /// Sources whose listener fired in this wait.
    fired: Vec<usize>,
    /// Per sample in the daemon's [`Batch`]: its source.
    owner: Vec<usize>,
    /// Fired sources with more samples than fitted in the batch.
    more: Vec<usize>,
    /// Per source: answered something in this wake-up (so flush its outputs).
    answered: Vec<bool>,
}

impl Wake {
    fn size_for(&mut self, sources: usize) {
        self.fired = Vec::with_capacity(sources);
        self.owner = Vec::with_capacity(BATCH);
        self.more = Vec::with_capacity(sources);
        self.answered = vec![false; sources];
    }
}

/// What a housekeeping pass wants changed.
#[derive(Default)]
struct Changes {
    add: Vec<String>,
    remove: Vec<usize>,
}

impl Changes {
    fn is_empty(&self) -> bool {
        self.add.is_empty() && self.remove.is_empty()
    }
}

/// Loop state that is not borrowed by the WaitSet guards.
struct Daemon {
    config: Config,
    ipc: IpcConfig,
    iox_config: ghnet_client::iceoryx2::config::Config,
    node: Node<ipc::Service>,
    predictor: Predictor,
    batch: Batch,
    wake: Wake,
    limits: Limits,
    tag: ModelTag,
    /// Counters of sources that were dropped, kept for the final stats and resumed
    /// if the source comes back.
    retired: BTreeMap<String, Counters>,
    /// Discovered names that failed to open, so a broken service is reported once,
    /// not every tick. Forgotten when the service disappears.
    rejected: BTreeSet<String>,
    /// Names over `max_sources`, reported once.
    over_limit: BTreeSet<String>,
    added: u64,
    removed: u64,
    next_stats: Option<Instant>,
    /// The Zenoh session (output, presence, queryables) when `zenoh.enabled`.
    zenoh: Option<ZenohSide>,
    /// Whether a discovery pass has anything new to list.
    services: ServiceDirWatch,
    /// When the last dead-node cleanup ran.
    cleaned_at: Option<Instant>,
}

/// Tells a discovery pass whether listing the iceoryx2 services can find anything.
///
/// Listing opens and parses the static config of every service under the root, which
/// made discovery the whole of ghnetd's idle CPU (about 3% of a core with 10 sources
/// at 4 passes a second). A new service always creates a file in the services
/// directory, which changes the directory's mtime, so a pass lists only when:
/// - the mtime changed since the last listing (a service appeared or went away);
/// - the mtime is younger than [`Self::TRUST_AFTER`]: file times are coarse (one
///   kernel tick), so a file created in the same tick just after a listing would not
///   change it;
/// - [`Self::FULL_LIST_EVERY`] passed: a publisher that comes back to a service that
///   still exists (held open by another process) creates no file.
struct ServiceDirWatch {
    dir: std::path::PathBuf,
    mtime: Option<std::time::SystemTime>,
    listed_at: Option<Instant>,
}

impl ServiceDirWatch {
    const TRUST_AFTER: Duration = Duration::from_millis(100);
    const FULL_LIST_EVERY: Duration = Duration::from_secs(5);

    fn new(iox_config: &ghnet_client::iceoryx2::config::Config) -> Self {
        Self {
            dir: iox_config.global.service_dir().to_string().into(),
            mtime: None,
            listed_at: None,
        }
    }

    /// True when a listing is due; then records the state it saw.
    fn should_list(&mut self, now: Instant) -> bool {
        let mtime = std::fs::metadata(&self.dir).and_then(|m| m.modified()).ok();
        let young = mtime
            .and_then(|m| std::time::SystemTime::now().duration_since(m).ok())
            .is_none_or(|age| age < Self::TRUST_AFTER);
        let due = self
            .listed_at
            .is_none_or(|at| now.duration_since(at) >= Self::FULL_LIST_EVERY);
        if mtime.is_none() || mtime != self.mtime || young || due {
            self.mtime = mtime;
            self.listed_at = Some(now);
            true
        } else {
            false
        }
    }
}

pub(crate) fn run(config: Config, shutdown: ShutdownFlag) -> anyhow::Result<Stats> {
    let ipc = config.ipc_config()?;
    let iox_config = ipc.iceoryx2_config();
    // The model first: a bad model file is a config error and must leave nothing
    // behind (no lock file, no iceoryx2 root).
    // Display only, not the source chain: ModelError's message already quotes its
    // cause, and `{:#}` would print it twice.
    let model = Arc::new(
        Model::from_name_or_path(&config.model.name)
            .map_err(|e| anyhow::anyhow!("model.name `{}`: {e}", config.model.name))?,
    );
    // Before anything else touches the services: a second daemon on the same prefix
    // would answer every sample twice.
    let lock = crate::lock::acquire(
        std::path::Path::new(&iox_config.global.root_path().to_string()),
        &iox_config.global.prefix.to_string(),
        &config.ipc.service_prefix,
    )?;
    let tag = ModelTag {
        id: model.id(),
        name: HeadingEstimate::encode_model_name(model.name()),
    };
    let predictor = Predictor::new(model.clone()).with_policy(config.status_policy());
    let batch = Batch::new(BATCH);
    let zenoh = if config.zenoh.enabled {
        let model_json =
            serde_json::to_string(model.meta()).context("cannot serialise the model metadata")?;
        Some(ZenohSide::open(&config.zenoh, &ipc, model_json)?)
    } else {
        info!("zenoh output disabled (zenoh.enabled = false)");
        None
    };

    // Signals belong to the embedding program (ghnetd's main registers them and sets
    // `shutdown`); iceoryx2 must not consume them.
    let node = NodeBuilder::new()
        .name(&NodeName::new("ghnetd").expect("valid node name"))
        .config(&iox_config)
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ipc::Service>()
        .context("cannot create the iceoryx2 node (check permissions of /dev/shm and the iceoryx2 root path)")?;
    restrict_global_segment(&iox_config);
    // Node creation already cleans up after dead nodes (iceoryx2 default); this
    // makes it explicit and visible after a kill -9.
    let cleanup = node.try_cleanup_dead_nodes();
    if cleanup.cleanups > 0 || cleanup.failed_cleanups > 0 {
        info!(
            cleaned = cleanup.cleanups,
            failed = cleanup.failed_cleanups,
            "removed stale iceoryx2 resources of dead processes"
        );
    }

    info!(
        prefix = %config.ipc.service_prefix,
        model = %model.name(),
        model_id = format_args!("{:#010x}", model.id()),
        sources = ?config.sources.static_sources,
        discovery = config.sources.discovery,
        discovery_interval_ms = config.sources.discovery_interval_ms,
        stale_after_ms = config.sources.stale_after_ms,
        lock = %lock.path().display(),
        "ghnetd starting"
    );

    let services = ServiceDirWatch::new(&iox_config);
    let mut d = Daemon {
        limits: Limits {
            max_speed: config.model.max_speed as f32,
        },
        next_stats: config.stats_interval().map(|i| Instant::now() + i),
        config,
        ipc,
        iox_config,
        node,
        predictor,
        batch,
        wake: Wake::default(),
        tag,
        retired: BTreeMap::new(),
        rejected: BTreeSet::new(),
        over_limit: BTreeSet::new(),
        added: 0,
        removed: 0,
        zenoh,
        services,
        cleaned_at: None,
    };

    let mut ports: Vec<Ports> = Vec::new();
    let mut states: Vec<State> = Vec::new();
    for name in d.config.sources.static_sources.clone() {
        let p = d
            .open_source(&name, true)
            .with_context(|| format!("static source `{name}`"))?;
        d.push_source(p, &mut ports, &mut states);
    }

    let waitset = WaitSetBuilder::new()
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ipc::Service>()
        .context("cannot create the iceoryx2 WaitSet")?;
    let housekeeping = d.config.discovery_interval();

    'outer: loop {
        let changes = {
            let tick = waitset
                .attach_interval(housekeeping)
                .context("cannot attach the housekeeping interval")?;
            let guards = ports
                .iter()
                .map(|p| waitset.attach_notification(p.velocity.listener()))
                .collect::<Result<Vec<_>, _>>()
                .context("cannot attach a source listener to the WaitSet")?;
            d.wake.size_for(ports.len());
            // Samples that arrived before a listener was attached (or before it
            // existed) have no pending wake-up; answer them now.
            for i in 0..ports.len() {
                d.serve_one(i, &ports, &mut states);
            }
            loop {
                let mut tick_due = false;
                let fired = &mut d.wake.fired;
                fired.clear();
                let on_event = |id: WaitSetAttachmentId<ipc::Service>| {
                    if id.has_event_from(&tick) {
                        tick_due = true;
                    } else if let Some(i) = guards.iter().position(|g| id.has_event_from(g)) {
                        fired.push(i);
                    }
                    CallbackProgression::Continue
                };
                waitset
                    .wait_and_process_once_with_timeout(on_event, SHUTDOWN_POLL)
                    .context("WaitSet failed")?;
                d.serve_fired(&ports, &mut states);
                if shutdown.is_requested() {
                    break 'outer;
                }
                if tick_due {
                    let changes = d.housekeeping(&ports, &mut states);
                    if !changes.is_empty() {
                        break changes;
                    }
                }
            }
        };
        d.apply(changes, &mut ports, &mut states);
    }

    // Answer what is already buffered, then drop ports before the node (releasing
    // the iceoryx2 resources in order).
    info!("shutdown requested: answering buffered samples");
    for i in 0..ports.len() {
        d.serve_one(i, &ports, &mut states);
    }
    let stats = d.stats(&ports, &states);
    d.log_stats(&ports, &states);
    drop(ports);
    drop(waitset);
    info!(
        sources_added = stats.sources_added,
        sources_removed = stats.sources_removed,
        received = stats.total().received,
        answered = stats.total().answered,
        "ghnetd stopped"
    );
    Ok(stats)
}

/// iceoryx2 0.10 creates its per-prefix management segment
/// (`/dev/shm/<global prefix>…global_mgmt`) with mode 0666, unaffected by the umask;
/// everything else it creates is owner-only or below the (owner-only) root path.
/// Narrow it to the owner when this process owns it; failures only cost the
/// hardening, so they are logged, not fatal.
fn restrict_global_segment(iox: &ghnet_client::iceoryx2::config::Config) {
    use std::os::unix::fs::PermissionsExt;
    let prefix = iox.global.prefix.to_string();
    let Ok(entries) = std::fs::read_dir("/dev/shm") else {
        return;
    };
    for e in entries.flatten() {
        let name = e.file_name().to_string_lossy().into_owned();
        if name.starts_with(&prefix) && name.ends_with("global_mgmt") {
            let perms = std::fs::Permissions::from_mode(0o600);
            if let Err(err) = std::fs::set_permissions(e.path(), perms) {
                debug!(file = %e.path().display(), error = %err, "cannot restrict iceoryx2 management segment");
            }
        }
    }
}

/// Ends a source's part of a wake-up: wakes its iceoryx2 listeners once for all its
/// answers (`flush`, if it answered any) and refreshes its Zenoh stats snapshot.
fn settle(ports: &Ports, state: &State, answered_any: bool, zenoh: Option<&ZenohSide>) {
    if answered_any {
        for out in &ports.outputs {
            if let Err(e) = out.flush() {
                debug!(source = %ports.name, output = out.kind(), error = %e, "flush failed");
            }
        }
    }
    if let Some(z) = zenoh {
        z.refresh(
            &ports.name,
            &state.tracker.counters,
            state.last,
            &state.latency,
        );
    }
}

/// Stamps the processing time (since `t0`) on `answer`, publishes it on every
/// output and books the result; `true` if every output took it.
fn deliver(
    ports: &Ports,
    state: &mut State,
    mut answer: HeadingEstimate,
    t0: Instant,
    burst: Burst,
) -> bool {
    answer.processing_ns = t0.elapsed().as_nanos() as u64;
    state.latency.push(answer.processing_ns);
    state.last = Some(answer);
    let mut delivered = true;
    for out in &ports.outputs {
        if let Err(e) = out.publish(&answer, burst) {
            delivered = false;
            // 1st, 2nd, 4th, 8th, ... failure: visible without flooding the log.
            let n = state.tracker.counters.send_errors + 1;
            if n.is_power_of_two() {
                warn!(source = %ports.name, output = out.kind(), error = %e, failures = n, "cannot publish heading");
            }
        }
    }
    if delivered {
        state.tracker.counters.answered += 1;
    } else {
        state.tracker.counters.send_errors += 1;
    }
    delivered
}

impl Daemon {
    /// Answers everything source `i` has buffered.
    fn serve_one(&mut self, i: usize, ports: &[Ports], states: &mut [State]) {
        self.wake.fired.clear();
        self.wake.fired.push(i);
        self.serve_fired(ports, states);
    }

    /// Answers everything the sources in `wake.fired` (those whose listeners fired
    /// in the last wait) have buffered, in rounds of up to [`BATCH`] samples.
    fn serve_fired(&mut self, ports: &[Ports], states: &mut [State]) {
        while !self.wake.fired.is_empty() {
            self.serve_round(ports, states);
            // Sources with more than fitted go again.
            std::mem::swap(&mut self.wake.fired, &mut self.wake.more);
        }
    }

    /// One round over the sources in `wake.fired`: consume their wake-up
    /// notifications first (or the WaitSet fires again at once), take their
    /// buffered samples in order, up to [`BATCH`] in all, answer them, then notify
    /// each source's listeners once. Fewer than [`BATCH_MIN`] samples (the normal
    /// case: one source, one sample in flight) take the one-sample path, the lowest
    /// latency; more go through the model in one call, whether they come from one
    /// source that fell behind or from many that woke together (receivers on one
    /// epoch), and over Zenoh as one network batch: only the round's last heading is
    /// express. Sources with more samples than fitted are left in `wake.more`.
    /// Allocates nothing.
    fn serve_round(&mut self, ports: &[Ports], states: &mut [State]) {
        let (batch, wake) = (&mut self.batch, &mut self.wake);
        batch.clear();
        wake.owner.clear();
        wake.more.clear();
        for &f in &wake.fired {
            let p = &ports[f];
            if let Err(e) = p.velocity.drain_notifications() {
                debug!(source = %p.name, error = %e, "draining notifications failed");
            }
            let mut exhausted = false;
            while batch.samples.len() < batch.capacity() {
                match p.velocity.try_recv() {
                    Ok(Some(s)) => {
                        batch.samples.push(s);
                        wake.owner.push(f);
                    }
                    Ok(None) => {
                        exhausted = true;
                        break;
                    }
                    Err(e) => {
                        warn!(source = %p.name, error = %e, "receiving failed");
                        exhausted = true;
                        break;
                    }
                }
            }
            if !exhausted {
                wake.more.push(f);
            }
        }
        let n = batch.samples.len();
        let t0 = Instant::now();
        if n < BATCH_MIN {
            for i in 0..n {
                let (t, f) = (Instant::now(), wake.owner[i]);
                let answer = states[f].tracker.answer(
                    &batch.samples[i],
                    &mut self.predictor,
                    &self.limits,
                    &self.tag,
                );
                wake.answered[f] |= deliver(&ports[f], &mut states[f], answer, t, Burst::of(i, n));
            }
        } else {
            for i in 0..n {
                batch.book(i, &mut states[wake.owner[i]].tracker, &self.limits);
            }
            batch.predict(&mut self.predictor);
            for i in 0..n {
                let f = wake.owner[i];
                let answer = batch.finish(i, &mut states[f].tracker, &self.tag);
                wake.answered[f] |= deliver(&ports[f], &mut states[f], answer, t0, Burst::of(i, n));
            }
        }
        for &f in &wake.fired {
            let answered = std::mem::take(&mut wake.answered[f]);
            settle(&ports[f], &states[f], answered, self.zenoh.as_ref());
        }
    }

    fn open_source(&self, name: &str, is_static: bool) -> anyhow::Result<Ports> {
        let velocity = VelocitySubscriber::with_node(&self.node, &self.ipc, name)?;
        let heading = HeadingPublisher::with_node(&self.node, &self.ipc, name)?;
        let heading_service = heading.service_name().to_owned();
        let mut outputs: Vec<Box<dyn HeadingOutput>> = vec![Box::new(heading)];
        if let Some(z) = &self.zenoh {
            outputs.push(Box::new(z.output(&self.ipc, name)?));
        }
        Ok(Ports {
            name: name.to_owned(),
            is_static,
            velocity,
            heading_service,
            outputs,
        })
    }

    fn push_source(&mut self, p: Ports, ports: &mut Vec<Ports>, states: &mut Vec<State>) {
        let counters = self.retired.remove(&p.name).unwrap_or_default();
        info!(
            source = %p.name,
            kind = if p.is_static { "static" } else { "discovered" },
            velocity = %p.velocity.service_name(),
            heading = %p.heading_service,
            "source added"
        );
        self.added += 1;
        ports.push(p);
        states.push(State::new(Tracker::resume(counters)));
    }

    /// Runs every `discovery_interval_ms`: cleans up after dead processes, watches
    /// for silent sources (one `Stale` message each), finds sources whose publishers
    /// are gone, discovers new ones, logs stats when due. Changes no ports; the caller
    /// applies the changes outside the WaitSet scope.
    fn housekeeping(&mut self, ports: &[Ports], states: &mut [State]) -> Changes {
        let mut changes = Changes::default();

        // A publisher killed with -9 stays registered until its node is cleaned up;
        // afterwards the publisher count drops and a new publisher can take its slot.
        // The check visits every node under the root (each client port has one), so
        // it runs at most every NODE_CLEANUP_EVERY, not on every pass.
        let now = Instant::now();
        if self
            .cleaned_at
            .is_none_or(|at| now.duration_since(at) >= NODE_CLEANUP_EVERY)
        {
            self.cleaned_at = Some(now);
            let cleanup = self.node.try_cleanup_dead_nodes();
            if cleanup.cleanups > 0 {
                info!(
                    cleaned = cleanup.cleanups,
                    "removed stale iceoryx2 resources of dead processes"
                );
            }
        }

        let stale_after = self.config.stale_after();
        for (i, (p, s)) in ports.iter().zip(states.iter_mut()).enumerate() {
            self.watch_silence(p, s, now);
            if !p.is_static && p.velocity.publisher_count() == 0 && !s.stale_pending(stale_after) {
                changes.remove.push(i);
            }
        }

        if self.config.sources.discovery && self.services.should_list(now) {
            let mut found = BTreeSet::new();
            let ipc = &self.ipc;
            let listed = ipc::Service::list(&self.iox_config, |details| {
                if let PatternConfig::PublishSubscribe(_) =
                    details.static_details.messaging_pattern()
                {
                    if let Some(src) =
                        ipc.source_of_velocity_service(details.static_details.name().as_str())
                    {
                        found.insert(src.to_owned());
                    }
                }
                CallbackProgression::Continue
            });
            if let Err(e) = listed {
                warn!(error = %e, "cannot list iceoryx2 services; discovery skipped");
            }
            self.rejected.retain(|n| found.contains(n));
            self.over_limit.retain(|n| found.contains(n));
            let served = ports.len() - changes.remove.len();
            for name in found {
                if ports.iter().any(|p| p.name == name) || self.rejected.contains(&name) {
                    continue;
                }
                if served + changes.add.len() >= self.config.sources.max_sources {
                    if self.over_limit.insert(name.clone()) {
                        warn!(source = %name, max_sources = self.config.sources.max_sources, "source ignored: sources.max_sources reached");
                    }
                    continue;
                }
                changes.add.push(name);
            }
        }

        if let Some(next) = self.next_stats {
            let now = Instant::now();
            if now >= next {
                self.log_stats(ports, states);
                self.next_stats = self.config.stats_interval().map(|i| now + i);
            }
        }
        changes
    }

    /// Notices samples since the last pass ("served again" after a Stale message), or
    /// a silence longer than `sources.stale_after_ms`: then publishes ONE `Stale`
    /// message on every output of the source, logs and counts it. The silence is
    /// measured from the pass that last saw a sample, so the message comes between
    /// `stale_after_ms` and that plus two `discovery_interval_ms` after the last sample.
    fn watch_silence(&self, p: &Ports, s: &mut State, now: Instant) {
        let received = s.tracker.counters.received;
        if received != s.seen_received {
            s.seen_received = received;
            s.last_activity = now;
            if s.stale_sent {
                s.stale_sent = false;
                info!(source = %p.name, "served again: samples arrive after the Stale message");
            }
            return;
        }
        let (Some(after), Some(last)) = (self.config.stale_after(), s.last) else {
            return;
        };
        let silent = now.duration_since(s.last_activity);
        if s.stale_sent || silent <= after {
            return;
        }
        s.stale_sent = true;
        s.tracker.counters.stale += 1;
        let msg = stale_message(&last);
        for out in &p.outputs {
            if let Err(e) = out.publish(&msg, Burst::Last).and_then(|()| out.flush()) {
                warn!(source = %p.name, output = out.kind(), error = %e, "cannot publish the Stale message");
            }
        }
        warn!(
            source = %p.name,
            last_seq = last.seq,
            silent_ms = silent.as_millis() as u64,
            publishers = p.velocity.publisher_count(),
            "source stale: no sample for longer than sources.stale_after_ms; published one Stale heading"
        );
        if let Some(z) = &self.zenoh {
            z.refresh(&p.name, &s.tracker.counters, s.last, &s.latency);
        }
    }

    fn apply(&mut self, changes: Changes, ports: &mut Vec<Ports>, states: &mut Vec<State>) {
        // Highest index first so swap_remove does not move an index still to come.
        let mut remove = changes.remove;
        remove.sort_unstable_by(|a, b| b.cmp(a));
        for i in remove {
            let p = ports.swap_remove(i);
            let s = states.swap_remove(i);
            let c = s.tracker.counters;
            info!(
                source = %p.name,
                received = c.received,
                answered = c.answered,
                invalid = c.invalid,
                stale = c.stale,
                "source removed: no publishers left"
            );
            self.retired.entry(p.name.clone()).or_default().add(&c);
            if let Some(z) = &self.zenoh {
                z.forget(&p.name);
            }
            self.removed += 1;
        }
        for name in changes.add {
            match self.open_source(&name, false) {
                // Only serve it if a publisher is really there: the service may be a
                // leftover or still being set up; the next pass looks again.
                Ok(p) if p.velocity.publisher_count() > 0 => self.push_source(p, ports, states),
                Ok(_) => {
                    debug!(source = %name, "velocity service without publishers; not served yet")
                }
                Err(e) => {
                    warn!(source = %name, error = format_args!("{e:#}"), "cannot serve discovered source");
                    self.rejected.insert(name);
                }
            }
        }
    }

    fn stats(&self, ports: &[Ports], states: &[State]) -> Stats {
        let mut sources = self.retired.clone();
        for (p, s) in ports.iter().zip(states) {
            sources
                .entry(p.name.clone())
                .or_default()
                .add(&s.tracker.counters);
        }
        Stats {
            sources,
            sources_added: self.added,
            sources_removed: self.removed,
        }
    }

    fn log_stats(&self, ports: &[Ports], states: &[State]) {
        if ports.is_empty() {
            debug!("stats: no sources served");
        }
        for (p, s) in ports.iter().zip(states) {
            let c = &s.tracker.counters;
            info!(
                source = %p.name,
                received = c.received,
                answered = c.answered,
                invalid = c.invalid,
                gaps = c.gaps,
                duplicates = c.duplicates,
                backwards = c.backwards,
                send_errors = c.send_errors,
                stale = c.stale,
                publishers = p.velocity.publisher_count(),
                "stats"
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn service_dir_watch_lists_on_change_young_mtime_and_periodically() {
        let dir = tempfile::tempdir().unwrap();
        let mut w = ServiceDirWatch {
            dir: dir.path().to_owned(),
            mtime: None,
            listed_at: None,
        };
        let t0 = Instant::now();
        assert!(w.should_list(t0), "first pass lists");
        // The directory was just created: its mtime is too young to trust.
        assert!(w.should_list(t0));
        std::thread::sleep(ServiceDirWatch::TRUST_AFTER + Duration::from_millis(50));
        // The young passes listed everything up to a time long after the mtime's
        // tick, so an old, unchanged mtime means nothing new.
        assert!(!w.should_list(t0), "nothing changed: no listing");
        std::fs::write(dir.path().join("new.service"), b"").unwrap();
        assert!(w.should_list(t0), "a new service file lists");
        std::thread::sleep(ServiceDirWatch::TRUST_AFTER + Duration::from_millis(50));
        assert!(!w.should_list(t0));
        assert!(
            w.should_list(t0 + ServiceDirWatch::FULL_LIST_EVERY),
            "a full listing every FULL_LIST_EVERY regardless"
        );
        // A missing directory (no service yet) always lists.
        let mut gone = ServiceDirWatch {
            dir: dir.path().join("missing"),
            mtime: None,
            listed_at: Some(t0),
        };
        assert!(gone.should_list(t0));
    }
}
