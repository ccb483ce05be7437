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
//! (visible as gaps in `seq`) instead.
//!
//! Each source has two publishers on its heading key, the same but for `express`: the
//! answers of one round (the samples of the sources that woke together) but the last
//! are put on the batching ones (Zenoh appends them to its current batch, whatever the
//! key), the last on its source's express one, which sends that batch at once.
//! So a lone heading (one sample in flight, the normal case) leaves at once, and a
//! round of 64 costs one TCP send and one wake-up of Zenoh's transmit thread instead
//! of 64. With every heading express, that per-message cost (in ghnetd and in every
//! subscriber) held 100 sources to about 50,000 headings/s on 2 cores; see the
//! README's Performance section.

use std::collections::BTreeMap;
use std::sync::{Arc, Mutex};
use std::time::{SystemTime, UNIX_EPOCH};

use anyhow::Context;
use ghnet_client::zenoh::{self, Wait};
use ghnet_client::{encode_zenoh, HeadingEstimate, IpcConfig};
use serde::Serialize;
use tracing::info;

use crate::answer::Counters;
use crate::config::ZenohSection;
use crate::output::{Burst, HeadingOutput, OutputError};

/// Processing times kept per source for the stats percentiles (the most recent ones).
pub(crate) const LATENCY_WINDOW: usize = 1024;

/// Recent processing times of one source, a ring owned by the loop (allocated once
/// per source; writing into it allocates nothing).
pub(crate) struct LatencyRing {
    ns: Box<[u64; LATENCY_WINDOW]>,
    len: usize,
    next: usize,
}

impl LatencyRing {
    pub(crate) fn new() -> Self {
        Self {
            ns: Box::new([0; LATENCY_WINDOW]),
            len: 0,
            next: 0,
        }
    }

    pub(crate) fn push(&mut self, ns: u64) {
        self.ns[self.next] = ns;
        self.next = (self.next + 1) % LATENCY_WINDOW;
        self.len = (self.len + 1).min(LATENCY_WINDOW);
    }
}

/// What the loop last published about one source.
#[derive(Clone)]
struct SourceSnapshot {
    counters: Counters,
    last: Option<HeadingEstimate>,
    latencies: Box<[u64; LATENCY_WINDOW]>,
    latency_len: usize,
}

/// State shared between the loop (writer) and the queryables (readers).
#[derive(Default)]
pub(crate) struct Shared {
    sources: BTreeMap<String, SourceSnapshot>,
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

#[derive(Serialize)]
struct SourceStats<'a> {
    #[serde(flatten)]
    counters: &'a Counters,
    last_seq: Option<u64>,
    last_timestamp_ns: Option<u64>,
    last_heading_deg: Option<f32>,
    last_status: Option<u32>,
    processing: Option<Latency>,
}

#[derive(Serialize)]
struct StatsReply<'a> {
    daemon: &'a DaemonId,
    sources: BTreeMap<&'a str, SourceStats<'a>>,
}

/// Who answers: several daemons may share a prefix.
#[derive(Serialize, Clone)]
struct DaemonId {
    zid: String,
    pid: u32,
    started_unix_s: u64,
}

impl Shared {
    fn to_json(&self, id: &DaemonId) -> String {
        let sources = self
            .sources
            .iter()
            .map(|(name, s)| {
                let mut lat: Vec<u64> = s.latencies[..s.latency_len].to_vec();
                lat.sort_unstable();
                let pct = |p: f64| lat[((lat.len() - 1) as f64 * p).round() as usize];
                let processing = (!lat.is_empty()).then(|| Latency {
                    window: lat.len(),
                    p50_ns: pct(0.5),
                    p90_ns: pct(0.9),
                    p99_ns: pct(0.99),
                    max_ns: lat[lat.len() - 1],
                });
                let last = s.last.as_ref();
                let stats = SourceStats {
                    counters: &s.counters,
                    last_seq: last.map(|h| h.seq),
                    last_timestamp_ns: last.map(|h| h.timestamp_ns),
                    // NaN is not JSON: an invalid last answer has no heading.
                    last_heading_deg: last.map(|h| h.heading_deg).filter(|v| v.is_finite()),
                    last_status: last.map(|h| h.status),
                    processing,
                };
                (name.as_str(), stats)
            })
            .collect();
        serde_json::to_string(&StatsReply {
            daemon: id,
            sources,
        })
        .expect("stats always serialise")
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
        model_json: String,
    ) -> anyhow::Result<Self> {
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
        let zid = session.zid().to_string();
        info!(
            zid = %zid,
            mode = %section.mode,
            listening = ?section.listen,
            connect = ?section.connect,
            multicast_scouting = section.multicast_scouting,
            gossip = section.gossip,
            config_file = ?section.config_file,
            "zenoh session open"
        );

        let token = session
            .liveliness()
            .declare_token(ipc.zenoh_presence_key(&zid))
            .wait()
            .map_err(|e| anyhow::anyhow!("cannot declare the Zenoh liveliness token: {e}"))?;

        let shared = Arc::new(Mutex::new(Shared::default()));
        let id = DaemonId {
            zid: zid.clone(),
            pid: std::process::id(),
            started_unix_s: SystemTime::now()
                .duration_since(UNIX_EPOCH)
                .map(|d| d.as_secs())
                .unwrap_or(0),
        };
        let reader = shared.clone();
        let stats = session
            .declare_queryable(ipc.zenoh_stats_key())
            .callback(move |query| {
                // Serialise under the lock (microseconds), reply outside it.
                let json = {
                    let s = reader.lock().unwrap_or_else(|e| e.into_inner());
                    s.to_json(&id)
                };
                let _ = query
                    .reply(query.key_expr().clone(), json)
                    .encoding(zenoh::bytes::Encoding::APPLICATION_JSON)
                    .wait();
            })
            .wait()
            .map_err(|e| anyhow::anyhow!("cannot declare the Zenoh stats queryable: {e}"))?;
        let model = session
            .declare_queryable(ipc.zenoh_model_key())
            .callback(move |query| {
                let _ = query
                    .reply(query.key_expr().clone(), model_json.clone())
                    .encoding(zenoh::bytes::Encoding::APPLICATION_JSON)
                    .wait();
            })
            .wait()
            .map_err(|e| anyhow::anyhow!("cannot declare the Zenoh model queryable: {e}"))?;
        info!(
            presence = %ipc.zenoh_presence_key(&zid),
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

    /// Refreshes the snapshot of `source` unless a query is reading it right now.
    pub(crate) fn refresh(
        &self,
        source: &str,
        counters: &Counters,
        last: Option<HeadingEstimate>,
        ring: &LatencyRing,
    ) {
        let Ok(mut shared) = self.shared.try_lock() else {
            return;
        };
        match shared.sources.get_mut(source) {
            Some(s) => {
                s.counters = *counters;
                s.last = last;
                s.latencies.copy_from_slice(&ring.ns[..]);
                s.latency_len = ring.len;
            }
            None => {
                shared.sources.insert(
                    source.to_owned(),
                    SourceSnapshot {
                        counters: *counters,
                        last,
                        latencies: ring.ns.clone(),
                        latency_len: ring.len,
                    },
                );
            }
        }
    }

    /// Forgets a source that is no longer served (its counters stay in the log).
    pub(crate) fn forget(&self, source: &str) {
        let mut shared = self.shared.lock().unwrap_or_else(|e| e.into_inner());
        shared.sources.remove(source);
    }
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
