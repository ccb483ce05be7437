//! Headings over Zenoh, for consumers on other hosts or without shared memory.
//!
//! `ghnetd` publishes every [`HeadingEstimate`] it sends on iceoryx2 also on the Zenoh
//! key `<prefix>/<source>/heading` (payload: [`encode_zenoh`](crate::encode_zenoh),
//! the 64-byte table of `client/README.md`). Besides the data it declares, under
//! `<prefix>/@ghnetd/`:
//!
//! - a liveliness token `<prefix>/@ghnetd/<zid>` (the daemon session's Zenoh id) while
//!   it runs — [`IpcConfig::zenoh_presence_key`], query with
//!   `session.liveliness().get("<prefix>/@ghnetd/*")`;
//! - a queryable [`IpcConfig::zenoh_stats_key`] answering JSON counters per source;
//! - a queryable [`IpcConfig::zenoh_model_key`] answering the model metadata as JSON.
//!
//! `@ghnetd` is a Zenoh *verbatim* chunk: wildcards such as `<prefix>/**` never match
//! it, so a consumer subscribing to all headings does not receive daemon internals.
//!
//! Zenoh's defaults are not local (a peer listens on every interface and scouts by
//! multicast); [`peer_config`] builds the loopback-only configuration ghnet uses.

use std::time::Duration;

use zenoh::handlers::{FifoChannel, FifoChannelHandler};
use zenoh::pubsub::Subscriber;
use zenoh::sample::Sample;
use zenoh::{Session, Wait};

use crate::codec::{decode_zenoh, DecodeError};
use crate::names::{IpcConfig, NameError};
use crate::wire::HeadingEstimate;

/// Default TCP port of `ghnetd`'s Zenoh listener (`tcp/127.0.0.1:7447`). It is also
/// the Zenoh router's default port: a host running `zenohd` gives ghnetd another one.
pub const DEFAULT_ZENOH_PORT: u16 = 7447;

/// Headings a [`ZenohHeadingSubscriber`] buffers before Zenoh's receive thread of that
/// session waits for the reader (about 10 s at 100 Hz).
pub const ZENOH_SUBSCRIBER_BUFFER: usize = 1024;

/// Zenoh's transmit queue for every session that sends headings onward under load:
/// ghnetd's own (its default without a Zenoh config file) and a fleet's routers. 16
/// batches for data and up to 50 ms for one to free before a message is dropped, where
/// Zenoh's defaults are 2 batches and 1 ms. JSON5 values by config path, for
/// `Config::insert_json5` or a config file.
///
/// Why: headings are published with drop congestion control (the daemon's loop must
/// never stall), and every session on the way applies its *own* queue to them: a
/// router with Zenoh's defaults, on a loaded host, drops part of any burst it
/// forwards. The cost is bounded: a congested link makes a sender wait at most
/// 50 ms once, then drops without waiting (daemon/README.md, "Zenoh transmit queue").
pub const ZENOH_TX_QUEUE: [(&str, &str); 2] = [
    ("transport/link/tx/queue/size/data", "16"),
    (
        "transport/link/tx/queue/congestion_control/drop/wait_before_drop",
        "50000",
    ),
];

/// A peer-mode Zenoh config that talks to exactly the given endpoints: listens on
/// `listen`, connects to `connect`, multicast scouting and gossip off.
///
/// Why: Zenoh's defaults listen on all interfaces and announce themselves by
/// multicast; a sidecar and its local consumers must not appear on the network unless
/// someone asks for it. Consumers typically pass `listen = []` and
/// `connect = ["tcp/127.0.0.1:7447"]`; a peer that connects retries in the background,
/// so start order does not matter.
pub fn peer_config(listen: &[String], connect: &[String]) -> zenoh::Result<zenoh::Config> {
    let mut c = zenoh::Config::default();
    c.insert_json5("mode", "\"peer\"")?;
    c.insert_json5("listen/endpoints", &json_list(listen))?;
    c.insert_json5("connect/endpoints", &json_list(connect))?;
    c.insert_json5("scouting/multicast/enabled", "false")?;
    c.insert_json5("scouting/gossip/enabled", "false")?;
    Ok(c)
}

/// `["a", "b"]` with JSON string escaping.
pub(crate) fn json_list(items: &[String]) -> String {
    let quoted: Vec<String> = items
        .iter()
        .map(|s| format!("\"{}\"", s.replace('\\', "\\\\").replace('"', "\\\"")))
        .collect();
    format!("[{}]", quoted.join(","))
}

impl IpcConfig {
    /// `<prefix>/@ghnetd/<id>`: the liveliness token of a running daemon (`id` is its
    /// Zenoh session id). Consumers watch `<prefix>/@ghnetd/*` to see daemons come and go.
    pub fn zenoh_presence_key(&self, id: &str) -> String {
        format!("{}/@ghnetd/{id}", self.prefix())
    }

    /// `<prefix>/@ghnetd/stats`: queryable answering per-source counters as JSON (one
    /// reply per daemon on the prefix; query without consolidation to see them all).
    pub fn zenoh_stats_key(&self) -> String {
        format!("{}/@ghnetd/stats", self.prefix())
    }

    /// `<prefix>/@ghnetd/model`: queryable answering the model metadata as JSON.
    pub fn zenoh_model_key(&self) -> String {
        format!("{}/@ghnetd/model", self.prefix())
    }
}

/// Why [`ZenohHeadingSubscriber::new`] failed.
#[derive(Debug, thiserror::Error)]
pub enum ZenohOpenError {
    /// The source name is not a valid ghnet source.
    #[error(transparent)]
    Name(#[from] NameError),
    /// Zenoh refused the subscriber (e.g. the session is closed).
    #[error("cannot declare the Zenoh subscriber: {0}")]
    Zenoh(zenoh::Error),
}

/// Receives one source's headings from Zenoh, decoded.
///
/// Buffers up to [`ZENOH_SUBSCRIBER_BUFFER`] headings. Every heading is kept (a FIFO,
/// not a latest-value ring): consumers that log or compare need all of them. A reader
/// that stops reading stalls only its own session's receive thread; the daemon
/// publishes with congestion control *drop*, so it is never slowed down, and the
/// reader sees the loss as gaps in `seq`.
pub struct ZenohHeadingSubscriber {
    key: String,
    subscriber: Subscriber<FifoChannelHandler<Sample>>,
}

impl ZenohHeadingSubscriber {
    /// Subscribes to `<prefix>/<source>/heading` on `session`.
    pub fn new(session: &Session, ipc: &IpcConfig, source: &str) -> Result<Self, ZenohOpenError> {
        let key = ipc.zenoh_heading_key(source)?;
        let subscriber = session
            .declare_subscriber(key.clone())
            .with(FifoChannel::new(ZENOH_SUBSCRIBER_BUFFER))
            .wait()
            .map_err(ZenohOpenError::Zenoh)?;
        Ok(Self { key, subscriber })
    }

    /// The key expression subscribed to.
    pub fn key(&self) -> &str {
        &self.key
    }

    /// The next heading, waiting at most `timeout`: `Ok(None)` on timeout, an error
    /// value (never a panic) for a payload that is not a heading — anyone may publish
    /// on the key.
    pub fn recv_timeout(&self, timeout: Duration) -> Result<Option<HeadingEstimate>, DecodeError> {
        match self.subscriber.recv_timeout(timeout) {
            Ok(Some(sample)) => decode_zenoh(&sample.payload().to_bytes()).map(Some),
            // Timeout, or the channel is closed (subscriber undeclared): nothing came.
            Ok(None) | Err(_) => Ok(None),
        }
    }

    /// The next buffered heading without waiting.
    pub fn try_recv(&self) -> Result<Option<HeadingEstimate>, DecodeError> {
        match self.subscriber.try_recv() {
            Ok(Some(sample)) => decode_zenoh(&sample.payload().to_bytes()).map(Some),
            Ok(None) | Err(_) => Ok(None),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys() {
        let ipc = IpcConfig::new("site1/ghnet").unwrap();
        assert_eq!(ipc.zenoh_stats_key(), "site1/ghnet/@ghnetd/stats");
        assert_eq!(ipc.zenoh_model_key(), "site1/ghnet/@ghnetd/model");
        assert_eq!(ipc.zenoh_presence_key("ab12"), "site1/ghnet/@ghnetd/ab12");
        for k in [ipc.zenoh_stats_key(), ipc.zenoh_presence_key("ab12")] {
            assert!(zenoh::key_expr::KeyExpr::try_from(k.clone()).is_ok(), "{k}");
        }
    }

    #[test]
    fn loopback_config_has_no_multicast() {
        let c = peer_config(&["tcp/127.0.0.1:0".into()], &[]).unwrap();
        assert_eq!(c.get_json("scouting/multicast/enabled").unwrap(), "false");
        assert_eq!(c.get_json("scouting/gossip/enabled").unwrap(), "false");
        let listen = c.get_json("listen/endpoints").unwrap();
        assert!(listen.contains("tcp/127.0.0.1:0"), "{listen}");
    }
}
