//! The loop: one thread waits on the heading services of every source (an iceoryx2
//! `WaitSet`, no polling), turns each answer into an Imu and hands it to the
//! [`Output`]; once a second it looks for new sources (when none were given) and
//! publishes `/diagnostics`.
//!
//! ghnetd is never slowed: the bridge is one more subscriber of a service with safe
//! overflow, so a bridge that falls behind loses its own oldest answers (counted as
//! `missed`), and a ROS side that refuses a message costs a count (`send_failures`).
//! ghnetd restarting, or not running yet, needs nothing: the bridge keeps the services
//! open (`open_or_create`) and a new publisher on them is seen at the next receive.

use std::collections::BTreeSet;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use anyhow::Context as _;
use ghnet_client::iceoryx2::prelude::*;
use ghnet_client::iceoryx2::service::static_config::messaging_pattern::MessagingPattern;
use ghnet_client::names::HEADING_SUFFIX;
use ghnet_client::{attach_listeners, wait_for_listeners, HeadingSubscriber, IpcConfig};

use crate::msg::{DiagnosticArray, Header, Time};
use crate::names::TopicMap;
use crate::output::{Output, TopicId};
use crate::relay::SourceState;
use crate::Config;

/// How often `/diagnostics` is published and new sources are looked for.
pub const TICK: Duration = Duration::from_secs(1);

/// Longest a wait lasts, so a stop request is seen within it.
const STOP_CHECK: Duration = Duration::from_millis(100);

/// One source being relayed.
struct Relayed {
    name: String,
    topic: String,
    id: TopicId,
    state: SourceState,
    /// `send_failures` at the last tick, to log increases once a second.
    failures_logged: u64,
    /// When ghnetd's last message for the source came.
    last_message: Option<Instant>,
}

/// The sources of the bridge: receivers apart from the rest, because a `WaitSet`'s
/// guards borrow the receivers while the states change.
#[derive(Default)]
pub(crate) struct Sources {
    receivers: Vec<HeadingSubscriber>,
    relayed: Vec<Relayed>,
    topics: TopicMap,
    /// Discovered names that cannot be relayed (a topic collision): logged once.
    refused: BTreeSet<String>,
}

impl Sources {
    /// Opens `name`'s heading service and declares its topic. An error if its topic
    /// is taken by another source or a service or publisher cannot be made.
    pub(crate) fn add(
        &mut self,
        name: &str,
        ipc: &IpcConfig,
        out: &mut dyn Output,
    ) -> anyhow::Result<()> {
        let topic = self.topics.insert(name)?;
        let receiver = HeadingSubscriber::new(ipc, name)
            .with_context(|| format!("source `{name}`: opening its heading service"))?;
        let id = out.add_heading_topic(&topic)?;
        tracing::info!(source = name, topic = %topic, "relaying");
        self.receivers.push(receiver);
        self.relayed.push(Relayed {
            name: name.to_owned(),
            topic,
            id,
            state: SourceState::default(),
            failures_logged: 0,
            last_message: None,
        });
        Ok(())
    }

    fn contains(&self, name: &str) -> bool {
        self.relayed.iter().any(|r| r.name == name) || self.refused.contains(name)
    }

    /// Adds every discovered source not yet known; `true` if any was added.
    fn add_discovered(
        &mut self,
        found: BTreeSet<String>,
        cfg: &Config,
        out: &mut dyn Output,
    ) -> bool {
        let mut added = false;
        for name in found {
            if self.contains(&name) {
                continue;
            }
            match self.add(&name, &cfg.ipc, out) {
                Ok(()) => added = true,
                Err(e) => {
                    tracing::error!("discovered source not relayed: {e:#}");
                    self.refused.insert(name);
                }
            }
        }
        added
    }
}

/// Relays everything waiting on `rx` as `r`'s topic.
fn relay(
    rx: &HeadingSubscriber,
    r: &mut Relayed,
    frame_id: &str,
    out: &mut dyn Output,
) -> anyhow::Result<()> {
    rx.drain_notifications()?;
    while let Some(h) = rx.try_recv()? {
        r.last_message = Some(Instant::now());
        let imu = r.state.to_imu(&h, frame_id);
        if let Err(e) = out.publish_imu(r.id, imu) {
            r.state.counters.send_failures += 1;
            if r.state.counters.send_failures == 1 {
                tracing::warn!(source = %r.name, "{e}");
            }
        }
    }
    r.state.counters.missed = rx.missed();
    Ok(())
}

/// The `DiagnosticArray` of all sources, stamped `now`; logs send failures that grew
/// since the last call.
fn diagnostics(
    receivers: &[HeadingSubscriber],
    relayed: &mut [Relayed],
    now: Time,
) -> DiagnosticArray {
    let mut status = Vec::with_capacity(relayed.len());
    for (rx, r) in receivers.iter().zip(relayed) {
        let failures = r.state.counters.send_failures;
        if failures > r.failures_logged {
            let new = failures - r.failures_logged;
            tracing::warn!(source = %r.name, new, total = failures, "messages not sent to ROS");
            r.failures_logged = failures;
        }
        let silent = r.last_message.map(|t| t.elapsed());
        let publishers = rx.publisher_count();
        status.push(r.state.diagnostic(&r.name, &r.topic, publishers, silent));
    }
    DiagnosticArray {
        header: Header {
            stamp: now,
            frame_id: String::new(),
        },
        status,
    }
}

/// The sources ghnetd serves under `ipc`'s prefix: every publish-subscribe service
/// named `<prefix>/<source>/heading` with a valid source name.
pub fn heading_sources(ipc: &IpcConfig) -> anyhow::Result<BTreeSet<String>> {
    let mut found = BTreeSet::new();
    let prefix = format!("{}/", ipc.prefix());
    let suffix = format!("/{HEADING_SUFFIX}");
    ipc::Service::list(&ipc.iceoryx2_config(), |details| {
        if let MessagingPattern::PublishSubscribe(_) = details.static_details.messaging_pattern() {
            let name = details.static_details.name().as_str();
            let source = name
                .strip_prefix(&prefix)
                .and_then(|r| r.strip_suffix(&suffix));
            if let Some(s) = source.filter(|s| ghnet_client::validate_source_name(s).is_ok()) {
                found.insert(s.to_owned());
            }
        }
        CallbackProgression::Continue
    })
    .map_err(|e| anyhow::anyhow!("cannot list iceoryx2 services: {e:?}"))?;
    Ok(found)
}

fn now() -> Time {
    let ns = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as u64);
    Time::from_unix_ns(ns)
}

/// Runs until `stop` returns true. Returns the sources' counters at the end.
pub(crate) fn serve(
    cfg: &Config,
    mut sources: Sources,
    out: &mut dyn Output,
    stop: &dyn Fn() -> bool,
) -> anyhow::Result<Vec<(String, crate::relay::Counters)>> {
    // Signals belong to the binary (it turns them into `stop`), not to iceoryx2.
    let waitset = WaitSetBuilder::new()
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ipc::Service>()
        .map_err(|e| anyhow::anyhow!("cannot create an iceoryx2 WaitSet: {e:?}"))?;
    let mut fired = Vec::new();
    let mut next_tick = Instant::now();
    while !stop() {
        let guards = attach_listeners(&waitset, sources.receivers.iter())
            .map_err(|e| anyhow::anyhow!("cannot wait on the heading services: {e:?}"))?;
        let receivers = &sources.receivers;
        // A wake-up sent before the attachment is not lost: look at every source once.
        let mut pending: Vec<usize> = (0..receivers.len()).collect();
        let mut changed = false;
        while !stop() && !changed {
            for i in pending.drain(..) {
                relay(&receivers[i], &mut sources.relayed[i], &cfg.frame_id, out)?;
            }
            let now_i = Instant::now();
            if now_i >= next_tick {
                next_tick = now_i + TICK;
                if out
                    .publish_diagnostics(diagnostics(receivers, &mut sources.relayed, now()))
                    .is_err()
                {
                    tracing::debug!("diagnostics not sent");
                }
                if cfg.sources.is_empty() {
                    // A listing that fails (a service half made or removed while
                    // read) is tried again at the next tick.
                    let found = heading_sources(&cfg.ipc).unwrap_or_else(|e| {
                        tracing::warn!("{e:#}");
                        BTreeSet::new()
                    });
                    changed = found.iter().any(|n| !sources.contains(n));
                    if changed {
                        drop(guards);
                        sources.add_discovered(found, cfg, out);
                        break;
                    }
                }
            }
            let timeout = next_tick
                .saturating_duration_since(Instant::now())
                .min(STOP_CHECK);
            if guards.is_empty() {
                // Nothing to wait on yet (no source found): a WaitSet refuses that.
                std::thread::sleep(timeout);
                continue;
            }
            fired.clear();
            wait_for_listeners(&waitset, &guards, timeout, &mut fired)
                .map_err(|e| anyhow::anyhow!("waiting on the heading services: {e:?}"))?;
            pending.append(&mut fired);
        }
    }
    Ok(sources
        .relayed
        .iter()
        .map(|r| (r.name.clone(), r.state.counters))
        .collect())
}
