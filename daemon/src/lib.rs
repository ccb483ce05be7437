//! `ghnetd`: the ghnet heading sidecar as a library, so tests and other programs can
//! run it in-process; the `ghnetd` binary is a thin shell around [`run`].
//!
//! # Layout
//!
//! - `config` (private) — [`Config`] (TOML sections `ipc`, `sources`, `model`,
//!   `history`, `stats`, `zenoh`): each key's type, doc, flag and default on one field,
//!   read by serde from the file and by clap from the flags; validation with one-line
//!   errors that name the key. `layering` (private): TOML parse errors and flags laid
//!   over the file; `host` (private): the host checks validation makes (root
//!   directory ownership, `/dev/shm` size).
//! - `answer` (private) — the wire side of a source's samples: [`Counters`], the
//!   conversion to the sample rules of `ghnet_inference::source` (sequence, time,
//!   validity, resets, repeats: the same in ghnetd and `ghnet infer`), the per-epoch
//!   batch path, the `Stale` message. The model runs through `ghnet_inference::Runner`.
//! - `lock` (private) — one ghnetd per service prefix and iceoryx2 namespace: an
//!   exclusive lock file holding the pid, released by the kernel when its holder
//!   dies (so `kill -9` leaves nothing to clean up).
//! - `source` (private) — `Source`, one served source's ports and outputs, and beside
//!   it its `State` (rules and history, last answer, latencies, silence watch).
//! - `output` (private) — `HeadingOutput`, one destination of a source's answers:
//!   the iceoryx2 heading service, and the Zenoh publisher.
//! - `remote` (private) — the Zenoh session: heading publishers (congestion control
//!   *drop*, so a slow remote consumer never stalls the loop), the liveliness token
//!   `<prefix>/@ghnetd/<zid>`, and the `<prefix>/@ghnetd/stats` and `.../model`
//!   queryables, answered on Zenoh's threads from a snapshot the loop refreshes with
//!   `try_lock` (never waiting).
//! - `latency` (private) — the ring of recent processing times behind the stats
//!   percentiles.
//! - `roster` (private) — sources found but not served, why, and the retry backoff.
//! - `node` (private) — the iceoryx2 node and the hardening of its /dev/shm segment.
//! - `discovery` (private) — which velocity services exist, and whether a pass needs
//!   to look (the services directory changed).
//! - `serve` (private) — the event loop (start, serve, shutdown): one iceoryx2 node,
//!   one `WaitSet` with a notification per source listener and one housekeeping
//!   interval (discovery, publisher liveness, dead-node cleanup, stats line).
//!
//! # Behaviour
//!
//! Every [`VelocitySample`](ghnet_client::VelocitySample) taken from
//! `<prefix>/<source>/velocity` is answered with exactly one
//! [`HeadingEstimate`](ghnet_client::HeadingEstimate) on `<prefix>/<source>/heading`,
//! invalid ones with status `InvalidInput` (never dropped silently). Sources come from
//! `sources.static` and, with discovery on, from any velocity service that gets a
//! publisher; a discovered source whose publishers are all gone is dropped. A source
//! silent for longer than `sources.stale_after_ms` (default 2500) gets ONE extra
//! message with status `Stale` (the last sample's sequence number and timestamp,
//! heading NaN), which is not an answer to a sample; when samples come again it is
//! served as before. A source ghnetd finds but cannot serve (its services cannot be
//! opened, or `sources.max_sources` is reached) is logged once and listed in
//! [`Stats::unserved`] and the stats queryable, with the reason. Counters belong to
//! the source name for the daemon's lifetime: a source that is dropped and comes back
//! continues them, while its sequence tracking starts afresh (a new publisher may
//! restart at 0). A second ghnetd for the same service prefix in the same
//! iceoryx2 namespace exits with an error naming the first one's pid. The
//! per-sample path allocates nothing of its own: ports and model scratch are made
//! once per source / once per daemon. The libraries allocate on it: iceoryx2 0.10
//! one small object per loaned sample and two short lists per WaitSet wake-up,
//! Zenoh its payload buffer per `put`; none grows with load.
//! `tests/no_alloc.rs` counts the allocations of the real serve path and of a loop
//! making only the library calls, and requires the same count per sample.
//!
//! # Signals and shutdown
//!
//! The *embedding program* owns SIGINT/SIGTERM. `run` creates its iceoryx2 node and
//! WaitSet with `SignalHandlingMode::Disabled`, so iceoryx2 never consumes a signal
//! meant for the host program, and stops when the [`ShutdownFlag`] is set: within
//! about 100 ms, after answering every sample already buffered, releasing all ports
//! and the node. The `ghnetd` binary registers SIGINT/SIGTERM handlers (through
//! iceoryx2's own signal module, so iceoryx2 cannot later overwrite them) that set the
//! flag.
//!
//! ```no_run
//! let config = ghnetd::Config::default(); // embedded ghnet-full model, discovery on
//! let shutdown = ghnetd::ShutdownFlag::new();
//! let stopper = shutdown.clone();
//! std::thread::spawn(move || {
//!     std::thread::sleep(std::time::Duration::from_secs(5));
//!     stopper.request();
//! });
//! let stats = ghnetd::run(config, shutdown)?;
//! println!("answered {}", stats.total().answered);
//! # Ok::<(), anyhow::Error>(())
//! ```

#![warn(missing_docs)]

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use serde::Serialize;

mod answer;
mod config;
mod discovery;
mod host;
mod latency;
mod layering;
mod lock;
mod node;
mod output;
mod pressure;
mod remote;
mod roster;
mod serve;
mod source;
#[cfg(test)]
mod test_model;

pub use answer::Counters;
pub use config::{
    Config, HistorySection, IpcSection, ModelSection, Platforms, SourcesSection, StatsSection,
    ZenohSection,
};

/// Set once to stop [`run`]. Cheap to clone; setting it is async-signal-safe (a
/// single atomic store), so a signal handler may call [`request`](Self::request).
#[derive(Debug, Clone, Default)]
pub struct ShutdownFlag(Arc<AtomicBool>);

impl ShutdownFlag {
    /// A flag that is not set.
    pub fn new() -> Self {
        Self::default()
    }

    /// Asks [`run`] to stop.
    pub fn request(&self) {
        self.0.store(true, Ordering::Release);
    }

    /// Whether a stop was requested.
    pub fn is_requested(&self) -> bool {
        self.0.load(Ordering::Acquire)
    }
}

/// What [`run`] did, per source (including sources that were dropped on the way).
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize)]
pub struct Stats {
    /// Counters by source name.
    pub sources: BTreeMap<String, Counters>,
    /// Times a source was added (static at start, or discovered).
    pub sources_added: u64,
    /// Times a discovered source was dropped because its publishers were gone.
    pub sources_removed: u64,
    /// Sources with a velocity service that are not served, with the reason: their
    /// services could not be opened (e.g. created by another process with other
    /// limits), or `sources.max_sources` was reached.
    pub unserved: BTreeMap<String, String>,
    /// For each of [`unserved`](Self::unserved): how often opening it was tried
    /// again (with backoff, 0.1 s doubling to 5 s) after the first failure; 0 for a
    /// source over `sources.max_sources`.
    pub unserved_retries: BTreeMap<String, u64>,
}

impl Stats {
    /// Sum over all sources.
    pub fn total(&self) -> Counters {
        let mut t = Counters::default();
        for c in self.sources.values() {
            t.add(c);
        }
        t
    }
}

/// Serves sources until `shutdown` is set; returns the counters.
///
/// Must run on one thread for its whole life (iceoryx2 `ipc::Service` ports are
/// `!Send`). Errors: invalid config, model that cannot be loaded, iceoryx2 node or a
/// static source's services that cannot be opened (e.g. created by a client with
/// smaller limits, or another iceoryx2 version), or another ghnetd already serving
/// the same service prefix (the message names its pid). A discovered source that
/// cannot be opened (e.g. all its subscriber slots in use) is logged and listed in
/// [`Stats::unserved`] instead.
pub fn run(config: Config, shutdown: ShutdownFlag) -> anyhow::Result<Stats> {
    config.validate()?;
    serve::run(config, shutdown)
}
