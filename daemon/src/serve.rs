//! The event loop: one iceoryx2 node, one WaitSet, one thread. [`run`] reads as
//! start, serve, shutdown.
//!
//! Each served [`Source`] owns its ports (velocity subscriber + listener, and per
//! output the heading publisher + notifier), made once when the source is added; its
//! [`State`] sits beside it in [`Sources`]. The
//! WaitSet holds one notification attachment per source listener and one interval
//! ("housekeeping") for discovery, liveness, dead-node cleanup and the stats line.
//! Its guards borrow the ports (the states stay free to change), so the set of
//! sources can only change between
//! attachment scopes: when housekeeping finds a change, the scope ends
//! ([`Daemon::serve`] returns the [`Changes`]), the change is applied, and the
//! attachments are made again (rare, and nothing is lost: pending notifications stay
//! in the listeners).
//!
//! A wait collects the sources whose listeners fired; they are then served together
//! in rounds of up to [`BATCH`] samples ([`Daemon::serve_round`]), so receivers on
//! one epoch share a model call and a Zenoh network batch.

use std::collections::BTreeMap;
use std::collections::BTreeSet;
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::Context;
use ghnet_client::iceoryx2::config::Config as IoxConfig;
use ghnet_client::iceoryx2::prelude::*;
use ghnet_client::iceoryx2::waitset::WaitSetGuard;
use ghnet_client::{HeadingEstimate, IpcConfig, SERVICE_SETTINGS};
use ghnet_inference::{Model, Runner, Staged};
use tracing::{debug, info, warn};

use crate::answer::{estimate, sample, Batch, Counters, ModelTag};
use crate::config::Config;
use crate::discovery::{velocity_sources, BadNames, ServiceDirWatch};
use crate::lock::InstanceLock;
use crate::node::open_node;
use crate::output::Burst;
use crate::pressure::Budget;
use crate::remote::ZenohSide;
use crate::roster::{Changes, Roster};
use crate::source::{Kind, Source, Sources, State};
use crate::{ShutdownFlag, Stats};

/// Longest the loop sleeps without looking at the shutdown flag. Signals interrupt
/// the wait at once; this bounds the reaction to a flag set by another thread.
const SHUTDOWN_POLL: Duration = Duration::from_millis(100);

/// Most often the housekeeping pass looks for dead processes. Visiting every iceoryx2
/// node under the root costs tens of microseconds per node (each client port has its
/// own node), too much for every pass; a publisher killed with -9 is still noticed
/// within about a second.
const NODE_CLEANUP_EVERY: Duration = Duration::from_secs(1);

/// Most samples answered in one round (one model call): a full subscriber buffer,
/// so one source that fell behind is one call, and 128 receivers on one epoch too.
const BATCH: usize = SERVICE_SETTINGS.subscriber_buffer_size;

/// Fewest buffered samples that go through the batch path. One sample (the normal
/// case: one in flight per source) takes `forward_one`, the lowest latency; from
/// this many on, `predict_batch_with_accuracy` costs less in total (per sample about
/// half of `forward_one`).
const BATCH_MIN: usize = 4;

pub(crate) fn run(config: Config, shutdown: ShutdownFlag) -> anyhow::Result<Stats> {
    let (mut daemon, mut sources) = Daemon::start(config)?;
    // Signals belong to the embedding program (ghnetd's main registers them and sets
    // `shutdown`); iceoryx2 must not consume them.
    let waitset = WaitSetBuilder::new()
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ipc::Service>()
        .context("cannot create the iceoryx2 WaitSet")?;
    while let Some(changes) = daemon.serve(&waitset, &mut sources, &shutdown)? {
        daemon.apply(changes, &mut sources);
    }
    Ok(daemon.shutdown(sources, waitset))
}

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
    /// The sources that fired, as they were before the rounds: settled once each at
    /// the end of the wake-up.
    woken: Vec<usize>,
    /// Per sample of a round: how many of its source's samples precede it in the round
    /// (its staged pass).
    pass: Vec<usize>,
    /// One staged pass: `(sample, column)`.
    staged: Vec<(usize, usize)>,
    /// Per source: its samples counted so far in the round (all zero between rounds).
    taken: Vec<usize>,
}

impl Wake {
    fn size_for(&mut self, sources: usize) {
        self.fired = Vec::with_capacity(sources);
        self.owner = Vec::with_capacity(BATCH);
        self.more = Vec::with_capacity(sources);
        self.answered = vec![false; sources];
        self.woken = Vec::with_capacity(sources);
        self.pass = Vec::with_capacity(BATCH);
        self.staged = Vec::with_capacity(BATCH);
        self.taken = vec![0; sources];
    }
}

/// How a round is answered ([`Daemon::path`]).
enum Path {
    /// Each sample alone, in order.
    OneByOne,
    /// A per-epoch model, every sample in one call.
    Batched,
    /// A temporal model in staged passes.
    Passes,
}

/// Loop state that is not borrowed by the WaitSet guards.
struct Daemon {
    config: Config,
    ipc: IpcConfig,
    iox_config: IoxConfig,
    /// The model: per-epoch (batched when samples pile up) or stateful (one sample
    /// at a time against each source's history).
    runner: Runner,
    batch: Batch,
    wake: Wake,
    tag: ModelTag,
    /// Counters of sources that were dropped, kept for the stats and resumed if the
    /// source comes back.
    retired: BTreeMap<String, Counters>,
    /// Sources found but not served, why, and when to try again.
    roster: Roster,
    /// What a source costs in descriptors and shared memory, checked before opening one.
    budget: Budget,
    added: u64,
    removed: u64,
    next_stats: Option<Instant>,
    /// Whether a discovery pass has anything new to list.
    services: ServiceDirWatch,
    /// Velocity services whose source name breaks the rules, logged once each.
    bad_names: BadNames,
    /// When the last dead-node cleanup ran.
    cleaned_at: Option<Instant>,
    // Drop order: Zenoh (output, presence, queryables, when `zenoh.enabled`), then
    // the node, then the lock, so that a second daemon can only start once this one
    // has let go of everything.
    zenoh: Option<ZenohSide>,
    node: Node<ipc::Service>,
    _lock: InstanceLock,
}

impl Daemon {
    /// Loads the model, takes the instance lock, opens Zenoh and the iceoryx2 node,
    /// and opens the static sources.
    fn start(config: Config) -> anyhow::Result<(Self, Sources)> {
        let ipc = config.ipc_config()?;
        let iox_config = ipc.iceoryx2_config();
        // The model first: a bad model file is a config error and must leave nothing
        // behind (no lock file, no iceoryx2 root).
        let model = load_model(&config.model.name)?;
        // Before anything else touches the services: a second daemon on the same
        // prefix would answer every sample twice.
        let lock = crate::lock::acquire(
            std::path::Path::new(&iox_config.global.root_path().to_string()),
            &iox_config.global.prefix.to_string(),
            &config.ipc.service_prefix,
        )?;
        let zenoh = match config.zenoh.enabled {
            true => Some(ZenohSide::open(&config.zenoh, &ipc, &model)?),
            false => {
                info!("zenoh output disabled (zenoh.enabled = false)");
                None
            }
        };
        let node = open_node(&iox_config)?;
        let budget = Budget::measure(&config, &ipc);
        let runner = Runner::new(
            model.clone(),
            config.status_policy(),
            config.history.max_gap_s,
        );
        info!(
            prefix = %config.ipc.service_prefix,
            model = %model.name(),
            model_id = format_args!("{:#010x}", model.id()),
            sources = ?config.sources.static_sources,
            discovery = config.sources.discovery,
            discovery_interval_ms = config.sources.discovery_interval_ms,
            stale_after_ms = config.sources.stale_after_ms,
            stateful = model.is_stateful(),
            history_max_gap_s = ?runner.max_gap_s(),
            platform = %config.model.platform.unwrap_or(model.meta().kind.default_platform()),
            lock = %lock.path().display(),
            "ghnetd starting"
        );
        let mut daemon = Daemon {
            tag: ModelTag {
                id: model.id(),
                name: HeadingEstimate::encode_model_name(model.name()),
            },
            runner,
            batch: Batch::new(BATCH),
            wake: Wake::default(),
            next_stats: config.stats_interval().map(|i| Instant::now() + i),
            services: ServiceDirWatch::new(&iox_config),
            bad_names: BadNames::default(),
            config,
            ipc,
            iox_config,
            retired: BTreeMap::new(),
            roster: Roster::default(),
            budget,
            added: 0,
            removed: 0,
            cleaned_at: None,
            zenoh,
            node,
            _lock: lock,
        };
        // A static source that cannot be opened is that source's problem (e.g. a
        // consumer created its heading service with smaller limits): it is reported
        // and retried like a discovered one, and the others are served meanwhile.
        let mut sources = Sources::default();
        let add = Changes {
            add: daemon.config.sources.static_sources.clone(),
            remove: Vec::new(),
        };
        daemon.apply(add, &mut sources);
        Ok((daemon, sources))
    }

    /// Serves `sources` until housekeeping wants them changed (`Some`) or a stop is
    /// requested (`None`).
    fn serve(
        &mut self,
        waitset: &WaitSet<ipc::Service>,
        sources: &mut Sources,
        shutdown: &ShutdownFlag,
    ) -> anyhow::Result<Option<Changes>> {
        let Sources { ports, states } = sources;
        let tick = waitset
            .attach_interval(self.config.discovery_interval())
            .context("cannot attach the housekeeping interval")?;
        let guards = ghnet_client::attach_listeners(waitset, ports.iter().map(|s| &s.velocity))
            .context("cannot attach a source listener to the WaitSet")?;
        self.wake.size_for(ports.len());
        // Samples that arrived before a listener was attached (or before it existed)
        // have no pending wake-up; answer them now.
        self.serve_all(ports, states);
        loop {
            let tick_due = self.wait(waitset, &tick, &guards)?;
            self.serve_fired(ports, states);
            if shutdown.is_requested() {
                return Ok(None);
            }
            if tick_due {
                let changes = self.housekeeping(ports, states);
                if !changes.is_empty() {
                    return Ok(Some(changes));
                }
            }
        }
    }

    /// Answers what is already buffered, releases the ports before the WaitSet and
    /// the node, and returns the final counters.
    fn shutdown(mut self, mut sources: Sources, waitset: WaitSet<ipc::Service>) -> Stats {
        info!("shutdown requested: answering buffered samples");
        self.serve_all(&sources.ports, &mut sources.states);
        let stats = self.stats(&sources);
        self.log_stats(&sources.ports, &sources.states);
        drop(sources);
        drop(waitset);
        let total = stats.total();
        info!(
            sources_added = stats.sources_added,
            sources_removed = stats.sources_removed,
            received = total.received,
            answered = total.answered,
            "ghnetd stopped"
        );
        stats
    }

    /// Waits for a notification, the housekeeping tick or [`SHUTDOWN_POLL`]; records
    /// the sources that fired in `wake.fired`. `true` if the tick is due.
    fn wait(
        &mut self,
        waitset: &WaitSet<ipc::Service>,
        tick: &WaitSetGuard<ipc::Service>,
        guards: &[WaitSetGuard<ipc::Service>],
    ) -> anyhow::Result<bool> {
        let mut tick_due = false;
        let fired = &mut self.wake.fired;
        fired.clear();
        let on_event = |id: WaitSetAttachmentId<ipc::Service>| {
            if id.has_event_from(tick) {
                tick_due = true;
            } else if let Some(i) = guards.iter().position(|g| id.has_event_from(g)) {
                fired.push(i);
            }
            CallbackProgression::Continue
        };
        waitset
            .wait_and_process_once_with_timeout(on_event, SHUTDOWN_POLL)
            .context("WaitSet failed")?;
        Ok(tick_due)
    }

    /// Answers everything every source has buffered.
    fn serve_all(&mut self, ports: &[Source], states: &mut [State]) {
        self.wake.fired.clear();
        self.wake.fired.extend(0..ports.len());
        self.serve_fired(ports, states);
    }

    /// Answers everything the sources in `wake.fired` have buffered, in rounds of up
    /// to [`BATCH`] samples, each source taking an equal share of a round; then
    /// settles each woken source once (one wake-up of its listeners for all its
    /// answers, however many rounds they took).
    fn serve_fired(&mut self, ports: &[Source], states: &mut [State]) {
        let wake = &mut self.wake;
        wake.woken.clear();
        wake.woken.extend_from_slice(&wake.fired);
        // Every woken source meets the first round (a full batch only shortens its
        // share to nothing), so draining there drains each once per wake-up.
        let mut first = true;
        while !self.wake.fired.is_empty() {
            self.serve_round(ports, states, std::mem::take(&mut first));
            // Sources with more than fitted go again.
            std::mem::swap(&mut self.wake.fired, &mut self.wake.more);
        }
        let wake = &mut self.wake;
        for &f in &wake.woken {
            let answered = std::mem::take(&mut wake.answered[f]);
            ports[f].settle(&mut states[f], answered, self.zenoh.as_ref());
        }
    }

    /// One round over the sources in `wake.fired`: take a share of each one's
    /// buffered samples in order, up to [`BATCH`] in all, and answer them. Fewer than
    /// [`BATCH_MIN`] samples (the normal case: one source, one sample in flight) take
    /// the one-sample path, the lowest latency; more go through the model together,
    /// whether they come from one source that fell behind or from many that woke
    /// together: a per-epoch model in one batched call, a temporal model in staged
    /// passes (chosen by [`path`](Self::path)); over Zenoh as one network batch,
    /// only the round's last heading express. Sources with more samples than fitted
    /// are left in `wake.more`. Allocates nothing.
    fn serve_round(&mut self, ports: &[Source], states: &mut [State], drain: bool) {
        let (batch, wake) = (&mut self.batch, &mut self.wake);
        batch.clear();
        wake.owner.clear();
        wake.more.clear();
        // A share per source: many sources that woke together each put about one
        // sample in a round (so a temporal model's pass has one per source), one
        // source that fell behind fills the round.
        let share = (BATCH / wake.fired.len().max(1)).max(1);
        for &f in &wake.fired {
            if !ports[f].take_samples(batch, &mut wake.owner, f, share, drain) {
                wake.more.push(f);
            }
        }
        match self.path() {
            Path::OneByOne => self.serve_one_by_one(ports, states),
            Path::Batched => self.serve_batched(ports, states),
            Path::Passes => self.serve_passes(ports, states),
        }
    }

    /// How the round in the batch is answered, decided here only. From [`BATCH_MIN`]
    /// samples on, a per-epoch model batches and a temporal one stages passes; `kf`
    /// (and any round under [`BATCH_MIN`]) takes every sample alone, in order, against
    /// its source's history.
    fn path(&mut self) -> Path {
        if self.batch.samples.len() < BATCH_MIN {
            Path::OneByOne
        } else if self.runner.stages() {
            Path::Passes
        } else if self.runner.batched().is_some() {
            Path::Batched
        } else {
            Path::OneByOne
        }
    }

    /// A round one sample at a time (the lowest latency).
    fn serve_one_by_one(&mut self, ports: &[Source], states: &mut [State]) {
        let (batch, wake) = (&self.batch, &mut self.wake);
        let n = batch.samples.len();
        for i in 0..n {
            let (t0, f) = (Instant::now(), wake.owner[i]);
            let s = &batch.samples[i];
            let answer = states[f].tracker.answer(s, &mut self.runner, &self.tag);
            wake.answered[f] |= ports[f].deliver(&mut states[f], answer, t0, Burst::of(i, n));
        }
    }

    /// A round through a per-epoch model in one batched call.
    fn serve_batched(&mut self, ports: &[Source], states: &mut [State]) {
        let (batch, wake) = (&mut self.batch, &mut self.wake);
        let (t0, n) = (Instant::now(), batch.samples.len());
        for i in 0..n {
            batch.book(i, &mut states[wake.owner[i]].tracker.stream);
        }
        batch.predict(self.runner.batched().expect("per-epoch model"));
        for i in 0..n {
            let f = wake.owner[i];
            let answer = batch.finish(i, &mut states[f].tracker.stream, &self.tag);
            wake.answered[f] |= ports[f].deliver(&mut states[f], answer, t0, Burst::of(i, n));
        }
    }

    /// A round through a temporal model in staged passes: pass `k` holds the `k`-th
    /// sample of every source in the round, their convolutions run together (the
    /// weights read once for all of them), then each is answered in its source's
    /// order. Answers are bit for bit those of one sample at a time.
    fn serve_passes(&mut self, ports: &[Source], states: &mut [State]) {
        let (batch, wake, runner) = (&self.batch, &mut self.wake, &mut self.runner);
        let n = batch.samples.len();
        // Each source's samples are in the round in arrival order.
        wake.pass.clear();
        for &f in &wake.owner {
            wake.pass.push(wake.taken[f]);
            wake.taken[f] += 1;
        }
        for &f in &wake.owner {
            wake.taken[f] = 0;
        }
        let passes = wake.pass.iter().max().map_or(0, |k| k + 1);
        let mut done = 0;
        for k in 0..passes {
            let t0 = Instant::now();
            runner.clear_staged();
            wake.staged.clear();
            for i in (0..n).filter(|&i| wake.pass[i] == k) {
                let f = wake.owner[i];
                let s = &batch.samples[i];
                match runner.stage(&mut states[f].tracker.stream, &sample(s)) {
                    Staged::Waiting(column) => wake.staged.push((i, column)),
                    Staged::Answered(p) => {
                        let answer = estimate(s, &p, &self.tag);
                        let burst = Burst::of(done, n);
                        wake.answered[f] |= ports[f].deliver(&mut states[f], answer, t0, burst);
                        done += 1;
                    }
                }
            }
            runner.run_staged();
            for &(i, column) in &wake.staged {
                let f = wake.owner[i];
                let s = &batch.samples[i];
                let p = runner.complete(&mut states[f].tracker.stream, &sample(s), column);
                let answer = estimate(s, &p, &self.tag);
                let burst = Burst::of(done, n);
                wake.answered[f] |= ports[f].deliver(&mut states[f], answer, t0, burst);
                done += 1;
            }
        }
    }

    /// Runs every `discovery_interval_ms`: cleans up after dead processes, watches
    /// for silent sources (one `Stale` message each), finds sources whose publishers
    /// are gone, discovers new ones, logs stats when due. Changes no ports; the caller
    /// applies the changes outside the WaitSet scope.
    fn housekeeping(&mut self, ports: &[Source], states: &mut [State]) -> Changes {
        let now = Instant::now();
        self.cleanup_dead_nodes(now);
        let stale_after = self.config.stale_after();
        let mut changes = Changes::default();
        for (i, (s, state)) in ports.iter().zip(states.iter_mut()).enumerate() {
            s.watch_silence(state, now, stale_after, self.zenoh.as_ref());
            s.catch_up_snapshot(state, self.zenoh.as_ref());
            if s.is_gone(state, stale_after) {
                changes.remove.push(i);
            }
        }
        if self.config.sources.discovery && self.services.due(now) {
            match velocity_sources(&self.iox_config, &self.ipc, &mut self.bad_names) {
                Ok(found) => self.discover(found, ports, &mut changes),
                // Never fatal: the next pass lists again.
                Err(e) => warn!(
                    error = format_args!("{e:#}"),
                    short = %self.budget.shortage().unwrap_or_default(),
                    "discovery skipped"
                ),
            }
        }
        self.roster.retries_due(
            now,
            ports.len(),
            self.config.sources.max_sources,
            &mut changes,
        );
        if self.next_stats.is_some_and(|next| now >= next) {
            self.log_stats(ports, states);
            self.next_stats = self.config.stats_interval().map(|i| now + i);
        }
        changes
    }

    /// A publisher killed with -9 stays registered until its node is cleaned up;
    /// afterwards the publisher count drops and a new publisher can take its slot.
    /// The check visits every node under the root, so it runs at most every
    /// [`NODE_CLEANUP_EVERY`].
    fn cleanup_dead_nodes(&mut self, now: Instant) {
        if self
            .cleaned_at
            .is_some_and(|at| now.duration_since(at) < NODE_CLEANUP_EVERY)
        {
            return;
        }
        self.cleaned_at = Some(now);
        let cleanup = self.node.try_cleanup_dead_nodes();
        if cleanup.cleanups > 0 {
            info!(
                cleaned = cleanup.cleanups,
                "removed stale iceoryx2 resources of dead processes"
            );
        }
    }

    /// Adds to `changes` the `found` velocity services that are not served yet, up to
    /// `sources.max_sources` (see [`Roster::discover`]).
    fn discover(&mut self, found: BTreeSet<String>, sources: &[Source], changes: &mut Changes) {
        let (statics, max) = (
            &self.config.sources.static_sources,
            self.config.sources.max_sources,
        );
        let served = |name: &str| sources.iter().any(|s| s.name == name);
        let served_after = sources.len() - changes.remove.len();
        if self
            .roster
            .discover(found, statics, served, served_after, max, changes)
        {
            self.publish_roster();
        }
    }

    /// Applies what housekeeping found: drops the sources that are gone (their
    /// counters kept for the stats and for their return), opens the new ones.
    fn apply(&mut self, changes: Changes, sources: &mut Sources) {
        // Highest index first so swap_remove does not move an index still to come.
        let mut remove = changes.remove;
        remove.sort_unstable_by(|a, b| b.cmp(a));
        for i in remove {
            let (s, mut state) = sources.swap_remove(i);
            state.forget_history();
            s.log_counters(&state, "source removed: no publishers left");
            self.retired
                .entry(s.name.clone())
                .or_default()
                .add(&state.counters());
            self.removed += 1;
            if let Some(z) = &self.zenoh {
                z.set_served(&s.name, &state.view(), false, (self.added, self.removed));
            }
        }
        for name in changes.add {
            let kind = match self.config.sources.static_sources.contains(&name) {
                true => Kind::Static,
                false => Kind::Discovered,
            };
            // Resources first: opening a source without the shared memory it needs
            // ends in SIGBUS, and without descriptors in an opaque iceoryx2 error.
            let before = self.budget.usage();
            let opened = match self.budget.check() {
                Ok(()) => self
                    .open_source(&name, kind)
                    .map_err(|e| self.budget.explain(e)),
                Err(short) => Err(short),
            };
            match opened {
                // A discovered source is only served if a publisher is really there:
                // the service may be a leftover or still being set up; the next pass
                // looks again.
                Ok(s) if kind == Kind::Static || s.0.velocity.publisher_count() > 0 => {
                    self.budget.learn(before);
                    self.add(s, sources)
                }
                Ok(_) => {
                    debug!(source = %name, "velocity service without publishers; not served yet")
                }
                Err(reason) => self.roster.failed(name, kind, reason),
            }
        }
        self.publish_roster();
    }

    /// Opens `name`'s ports; its counters continue where they stopped if it was
    /// served before.
    fn open_source(&self, name: &str, kind: Kind) -> anyhow::Result<(Source, State)> {
        let counters = self.retired.get(name).copied().unwrap_or_default();
        Source::open(
            &self.node,
            &self.ipc,
            self.zenoh.as_ref(),
            name,
            kind,
            counters,
            self.runner.stream(self.config.model.platform_of(name)),
        )
    }

    fn add(&mut self, (source, state): (Source, State), sources: &mut Sources) {
        source.log_added();
        // Its counters live on in the source now.
        self.retired.remove(&source.name);
        self.roster.served(&source.name);
        self.added += 1;
        if let Some(z) = &self.zenoh {
            z.set_served(
                &source.name,
                &state.view(),
                true,
                (self.added, self.removed),
            );
        }
        sources.push((source, state));
    }

    /// Hands the unserved sources and the add/remove totals to the stats queryable.
    fn publish_roster(&self) {
        if let Some(z) = &self.zenoh {
            let unserved = self.roster.listing(self.config.sources.max_sources);
            z.set_roster(&unserved, self.added, self.removed);
        }
    }

    fn stats(&self, sources: &Sources) -> Stats {
        let mut counters = self.retired.clone();
        for (s, state) in sources.ports.iter().zip(&sources.states) {
            counters
                .entry(s.name.clone())
                .or_default()
                .add(&state.counters());
        }
        let listing = self.roster.listing(self.config.sources.max_sources);
        Stats {
            sources: counters,
            sources_added: self.added,
            sources_removed: self.removed,
            unserved_retries: (listing.iter())
                .map(|(name, (_, retries))| (name.clone(), *retries))
                .collect(),
            unserved: (listing.into_iter())
                .map(|(name, (reason, _))| (name, reason))
                .collect(),
        }
    }

    fn log_stats(&self, ports: &[Source], states: &[State]) {
        if ports.is_empty() {
            debug!("stats: no sources served");
        }
        for (s, state) in ports.iter().zip(states) {
            s.log_counters(state, "stats");
        }
    }
}

/// The model named by `model.name` (a built-in name or a file).
fn load_model(name: &str) -> anyhow::Result<Arc<Model>> {
    // Display only, not the source chain: ModelError's message already quotes its
    // cause, and `{:#}` would print it twice.
    let model =
        Model::from_name_or_path(name).map_err(|e| anyhow::anyhow!("model.name `{name}`: {e}"))?;
    Ok(Arc::new(model))
}
