//! The Zenoh side of the daemon: one session, a heading publisher per source (a
//! [`HeadingOutput`]), a liveliness token, and the `stats` and `model` queryables.
//!
//! Threads: Zenoh runs its own runtime threads; the iceoryx2 loop stays on its one
//! thread and only calls the synchronous `.wait()` API. The queryables answer on
//! Zenoh's threads from [`Shared`], a snapshot the loop refreshes once per wake-up of
//! a source with `try_lock`: if a query holds the lock at that moment, the loop skips
//! the refresh (the next wake-up does it) rather than wait. So a query can never stall
//! the iceoryx2 loop, and the loop never waits for the network.
//!
//! Congestion control of the heading publisher is **Drop**: with `Block`, one slow or
//! stuck consumer (a full TCP window) would block `put` and with it the whole iceoryx2
//! loop, i.e. every local consumer of every source. Headings are a stream where the
//! next one supersedes the last, so a remote consumer that cannot keep up loses some
//! (visible as gaps in `seq`) instead. How long Zenoh holds a heading before dropping
//! it: daemon/README.md, "Zenoh transmit queue".
//!
//! Each source has two publishers on its heading key, the same but for `express`: the
//! answers of one round (the samples of the sources that woke together) but the last
//! are put on the batching ones (Zenoh appends them to its current batch, whatever the
//! key), the last on its source's express one, which sends that batch at once.
//! So a lone heading (one sample in flight, the normal case) leaves at once, and a
//! round of 64 costs one TCP send and one wake-up of Zenoh's transmit thread instead
//! of 64: that per-message cost, paid in ghnetd and in every subscriber, is what
//! limits throughput with many sources.

use std::collections::BTreeMap;
use std::sync::{Arc, Mutex};
use std::time::{SystemTime, UNIX_EPOCH};

use anyhow::Context;
use ghnet_client::zenoh::{self, Wait};
use ghnet_client::{encode_zenoh, HeadingEstimate, IpcConfig};
use ghnet_inference::{Model, ModelMeta};
use serde::Serialize;
use tracing::info;

use crate::answer::Counters;
use crate::config::ZenohSection;
use crate::latency::{LatencyRing, LATENCY_WINDOW};
use crate::output::{Burst, HeadingOutput, OutputError};

/// What the stats snapshot takes of a source's state: its counters, last answer and
/// recent processing times (the source builds it; this module never sees its state).
pub(crate) struct SourceView<'a> {
    pub(crate) counters: Counters,
    pub(crate) last: Option<HeadingEstimate>,
    pub(crate) latency: &'a LatencyRing,
}

/// What the loop last published about one source.
struct SourceSnapshot {
    counters: Counters,
    served: bool,
    last: Option<HeadingEstimate>,
    latencies: Box<[u64; LATENCY_WINDOW]>,
    latency_len: usize,
    /// The ring's push count when `latencies` was last brought up to date.
    latency_seen: u64,
}

/// State shared between the loop (writer) and the queryables (readers). A source
/// stays in `sources` after it is dropped (`served: false`), with the counters it
/// had, so what happened to it (e.g. its `stale` count) does not vanish with it.
#[derive(Default)]
pub(crate) struct Shared {
    sources: BTreeMap<String, SourceSnapshot>,
    /// Name → (reason, retries).
    unserved: BTreeMap<String, (String, u64)>,
    sources_added: u64,
    sources_removed: u64,
}

/// Percentiles of the processing time, ns.
#[derive(Serialize)]
struct Latency {
    window: usize,
    p50_ns: u64,
    p90_ns: u64,
    p99_ns: u64,
    max_ns: u64,
}

impl Latency {
    fn of(window: &[u64]) -> Option<Self> {
        let mut lat = window.to_vec();
        lat.sort_unstable();
        let pct = |p: f64| lat[((lat.len() - 1) as f64 * p).round() as usize];
        (!lat.is_empty()).then(|| Latency {
            window: lat.len(),
            p50_ns: pct(0.5),
            p90_ns: pct(0.9),
            p99_ns: pct(0.99),
            max_ns: lat[lat.len() - 1],
        })
    }
}

#[derive(Serialize)]
struct SourceStats<'a> {
    #[serde(flatten)]
    counters: &'a Counters,
    served: bool,
    last_seq: Option<u64>,
    last_timestamp_ns: Option<u64>,
    last_heading_deg: Option<f32>,
    last_status: Option<u32>,
    processing: Option<Latency>,
}

#[derive(Serialize)]
struct UnservedStats<'a> {
    reason: &'a str,
    /// Times opening it was tried again after the first failure.
    retries: u64,
}

/// The `@ghnetd/stats` answer; daemon/README.md documents every field.
#[derive(Serialize)]
struct StatsReply<'a> {
    daemon: &'a DaemonId,
    sources_added: u64,
    sources_removed: u64,
    sources: BTreeMap<&'a str, SourceStats<'a>>,
    unserved: BTreeMap<&'a str, UnservedStats<'a>>,
}

/// The `@ghnetd/model` answer: the model metadata, its id, and who answers.
#[derive(Serialize)]
struct ModelReply<'a> {
    #[serde(flatten)]
    meta: &'a ModelMeta,
    /// The `model_id` every heading of this model carries.
    model_id: u32,
    daemon: &'a DaemonId,
}

/// Who answers: several daemons may share a Zenoh network, and a query without
/// consolidation gets one answer from each.
#[derive(Serialize, Clone)]
struct DaemonId {
    zid: String,
    prefix: String,
    pid: u32,
    started_unix_s: u64,
}

impl Shared {
    fn to_json(&self, id: &DaemonId) -> String {
        let sources = self
            .sources
            .iter()
            .map(|(name, s)| {
                let last = s.last.as_ref();
                let stats = SourceStats {
                    counters: &s.counters,
                    served: s.served,
                    last_seq: last.map(|h| h.seq),
                    last_timestamp_ns: last.map(|h| h.timestamp_ns),
                    // NaN is not JSON: an invalid last answer has no heading.
                    last_heading_deg: last.map(|h| h.heading_deg).filter(|v| v.is_finite()),
                    last_status: last.map(|h| h.status),
                    processing: Latency::of(&s.latencies[..s.latency_len]),
                };
                (name.as_str(), stats)
            })
            .collect();
        let unserved = self
            .unserved
            .iter()
            .map(|(name, (reason, retries))| {
                let retries = *retries;
                (name.as_str(), UnservedStats { reason, retries })
            })
            .collect();
        serde_json::to_string(&StatsReply {
            daemon: id,
            sources_added: self.sources_added,
            sources_removed: self.sources_removed,
            sources,
            unserved,
        })
        .expect("stats always serialise")
    }

    fn write(&mut self, source: &str, state: &SourceView, served: bool) {
        let ring = state.latency;
        match self.sources.get_mut(source) {
            Some(s) => {
                s.counters = state.counters;
                s.served = served;
                s.last = state.last;
                s.latency_seen = ring.update(&mut s.latencies, s.latency_seen);
                s.latency_len = ring.len();
            }
            None => {
                let snapshot = SourceSnapshot {
                    counters: state.counters,
                    served,
                    last: state.last,
                    latencies: ring.copy(),
                    latency_len: ring.len(),
                    latency_seen: ring.pushed(),
                };
                self.sources.insert(source.to_owned(), snapshot);
            }
        }
    }
}

/// The daemon's Zenoh session and everything declared on it. Dropping it undeclares
/// the token and queryables and closes the session.
pub(crate) struct ZenohSide {
    // Declaration order is drop order: undeclare, then close the session.
    _token: zenoh::liveliness::LivelinessToken,
    _stats: zenoh::query::Queryable<()>,
    _model: zenoh::query::Queryable<()>,
    shared: Arc<Mutex<Shared>>,
    session: zenoh::Session,
}

impl ZenohSide {
    /// Opens the session from `section`, declares presence and the queryables, and
    /// logs the endpoints in use.
    pub(crate) fn open(
        section: &ZenohSection,
        ipc: &IpcConfig,
        model: &Model,
    ) -> anyhow::Result<Self> {
        let session = open_session(section)?;
        let id = DaemonId {
            zid: session.zid().to_string(),
            prefix: ipc.prefix().to_owned(),
            pid: std::process::id(),
            started_unix_s: SystemTime::now()
                .duration_since(UNIX_EPOCH)
                .map(|d| d.as_secs())
                .unwrap_or(0),
        };
        let token = session
            .liveliness()
            .declare_token(ipc.zenoh_presence_key(&id.zid))
            .wait()
            .map_err(|e| anyhow::anyhow!("cannot declare the Zenoh liveliness token: {e}"))?;
        let shared = Arc::new(Mutex::new(Shared::default()));
        let reader = shared.clone();
        let stats_id = id.clone();
        let stats = answer_queries(&session, ipc.zenoh_stats_key(), move || {
            // Serialise under the lock (microseconds), reply outside it.
            let s = reader.lock().unwrap_or_else(|e| e.into_inner());
            s.to_json(&stats_id)
        })?;
        let model_json = serde_json::to_string(&ModelReply {
            meta: model.meta(),
            model_id: model.id(),
            daemon: &id,
        })
        .context("cannot serialise the model metadata")?;
        let model = answer_queries(&session, ipc.zenoh_model_key(), move || model_json.clone())?;
        info!(
            presence = %ipc.zenoh_presence_key(&id.zid),
            stats = %ipc.zenoh_stats_key(),
            model = %ipc.zenoh_model_key(),
            "zenoh presence and queryables declared"
        );
        Ok(Self {
            session,
            shared,
            _token: token,
            _stats: stats,
            _model: model,
        })
    }

    /// A heading publisher for `source`, declared once per source.
    pub(crate) fn output(&self, ipc: &IpcConfig, source: &str) -> anyhow::Result<ZenohOutput> {
        let key = ipc.zenoh_heading_key(source)?;
        // Same key, same priority (so one transmit queue, in order), drop.
        let declare = |express: bool| {
            self.session
                .declare_publisher(key.clone())
                .congestion_control(zenoh::qos::CongestionControl::Drop)
                .priority(zenoh::qos::Priority::DataHigh)
                .express(express)
                .wait()
                .map_err(|e| anyhow::anyhow!("cannot declare Zenoh publisher {key}: {e}"))
                .context("zenoh")
        };
        Ok(ZenohOutput {
            batched: declare(false)?,
            express: declare(true)?,
        })
    }

    /// Refreshes the snapshot of a served `source` unless a query is reading it right
    /// now (the loop never waits for a query); `false` then, and the caller tries
    /// again later (`Source::catch_up_snapshot`).
    pub(crate) fn refresh(&self, source: &str, state: &SourceView) -> bool {
        match self.shared.try_lock() {
            Ok(mut shared) => {
                shared.write(source, state, true);
                true
            }
            Err(_) => false,
        }
    }

    /// Records a change of the set of sources: `source` is served from now on (or no
    /// longer, `served: false`), with `state` as it is, and the add/remove totals that
    /// include this change, under one lock so that no query sees one without the other.
    /// Waits for the lock: a change is rare, and must not be lost.
    pub(crate) fn set_served(
        &self,
        source: &str,
        state: &SourceView,
        served: bool,
        totals: (u64, u64),
    ) {
        let mut shared = self.shared.lock().unwrap_or_else(|e| e.into_inner());
        shared.write(source, state, served);
        (shared.sources_added, shared.sources_removed) = totals;
    }

    /// Records the sources that cannot be served (name → reason, retries) and the
    /// add/remove totals.
    pub(crate) fn set_roster(
        &self,
        unserved: &BTreeMap<String, (String, u64)>,
        added: u64,
        removed: u64,
    ) {
        let mut shared = self.shared.lock().unwrap_or_else(|e| e.into_inner());
        shared.unserved.clone_from(unserved);
        (shared.sources_added, shared.sources_removed) = (added, removed);
    }
}

/// Opens the Zenoh session of `section` and logs what it listens on.
fn open_session(section: &ZenohSection) -> anyhow::Result<zenoh::Session> {
    let mut section = section.clone();
    section.listen = section
        .listen
        .iter()
        .map(|e| resolve_port_zero(e))
        .collect::<anyhow::Result<_>>()?;
    let config = section.zenoh_config()?;
    let session = zenoh::open(config).wait().map_err(|e| {
        anyhow::anyhow!(
            "zenoh.listen {:?}: cannot open the Zenoh session: {e}",
            section.listen
        )
    })?;
    info!(
        zid = %session.zid(),
        mode = %section.mode,
        listening = ?section.listen,
        connect = ?section.connect,
        multicast_scouting = section.multicast_scouting,
        gossip = section.gossip,
        config_file = ?section.config_file,
        "zenoh session open"
    );
    Ok(session)
}

/// A queryable on `key` that answers every query with `answer()` as JSON, on Zenoh's
/// threads.
fn answer_queries(
    session: &zenoh::Session,
    key: String,
    answer: impl Fn() -> String + Send + Sync + 'static,
) -> anyhow::Result<zenoh::query::Queryable<()>> {
    session
        .declare_queryable(key.clone())
        .callback(move |query| {
            let _ = query
                .reply(query.key_expr().clone(), answer())
                .encoding(zenoh::bytes::Encoding::APPLICATION_JSON)
                .wait();
        })
        .wait()
        .map_err(|e| anyhow::anyhow!("cannot declare the Zenoh queryable {key}: {e}"))
}

/// `tcp/<ip>:0` → `tcp/<ip>:<a free port>`, so the log (and whoever reads it, e.g.
/// the tests) names the real port. Zenoh's API for the bound locators is unstable,
/// and asking the kernel first costs one bind; the port is free again for Zenoh's
/// bind a moment later (only another process binding in that instant could take it,
/// and then the session fails to open with a clear error). Other endpoints unchanged.
fn resolve_port_zero(endpoint: &str) -> anyhow::Result<String> {
    let Some(addr) = endpoint.strip_prefix("tcp/") else {
        return Ok(endpoint.to_owned());
    };
    // Keep any `?`/`#` metadata and config suffix of the endpoint as it is.
    let end = addr.find(['?', '#']).unwrap_or(addr.len());
    let (host_port, rest) = addr.split_at(end);
    let Ok(sock) = host_port.parse::<std::net::SocketAddr>() else {
        return Ok(endpoint.to_owned());
    };
    if sock.port() != 0 {
        return Ok(endpoint.to_owned());
    }
    let port = std::net::TcpListener::bind(sock)
        .and_then(|l| l.local_addr())
        .with_context(|| format!("zenoh.listen {endpoint}: cannot bind"))?
        .port();
    let mut resolved = sock;
    resolved.set_port(port);
    Ok(format!("tcp/{resolved}{rest}"))
}

/// One source's Zenoh heading publisher.
pub(crate) struct ZenohOutput {
    /// For answers followed by more of the same round: appended to Zenoh's batch.
    batched: zenoh::pubsub::Publisher<'static>,
    /// For the last answer of a round: sends the batch, this answer included, now.
    express: zenoh::pubsub::Publisher<'static>,
}

impl HeadingOutput for ZenohOutput {
    fn kind(&self) -> &'static str {
        "zenoh"
    }

    /// The payload is a 64-byte array Zenoh takes by value: one allocation per put,
    /// Zenoh's reference-counted buffer around it (no `Vec` of ours besides).
    fn publish(&self, answer: &HeadingEstimate, burst: Burst) -> Result<(), OutputError> {
        let publisher = match burst {
            Burst::More => &self.batched,
            Burst::Last => &self.express,
        };
        publisher
            .put(encode_zenoh(answer))
            .wait()
            .map_err(|e| OutputError(e.to_string().into()))
    }

    fn flush(&self) -> Result<(), OutputError> {
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn port_zero_is_resolved_and_others_are_kept() {
        let r = super::resolve_port_zero("tcp/127.0.0.1:0").unwrap();
        assert!(r.starts_with("tcp/127.0.0.1:") && !r.ends_with(":0"), "{r}");
        for keep in [
            "tcp/127.0.0.1:7447",
            "unixsock-stream//tmp/x.sock",
            "tcp/localhost:0",
        ] {
            assert_eq!(super::resolve_port_zero(keep).unwrap(), keep);
        }
    }
}
