//! What the in-process tests share: `ghnetd::run` on a thread of its own, in a
//! private iceoryx2 namespace, with a Zenoh endpoint of the test's own (a unix
//! socket in a temporary directory, so parallel tests never meet on a port).

// Each test file uses a different part of this module.
#![allow(dead_code)]

use std::path::PathBuf;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use ghnet_client::testing::TestNamespace;
use ghnet_client::zenoh::{self, Wait};
use ghnet_client::{
    HeadingEstimate, HeadingStatus, HeadingSubscriber, IpcConfig, VelocityPublisher,
};
use ghnetd::{Config, ShutdownFlag, Stats};

/// Longest any wait in these tests may take; a guard against hangs, never a
/// performance limit.
pub const WATCHDOG: Duration = Duration::from_secs(60);

/// Polls `cond` every 5 ms until it holds; panics with `what` after [`WATCHDOG`].
pub fn wait_until(what: &str, mut cond: impl FnMut() -> bool) {
    let t0 = Instant::now();
    while !cond() {
        assert!(t0.elapsed() < WATCHDOG, "watchdog: waiting for {what}");
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// An in-process ghnetd; stopped (and its thread joined) by [`stop`](Self::stop).
pub struct InProcess {
    shutdown: ShutdownFlag,
    thread: Option<JoinHandle<anyhow::Result<Stats>>>,
    /// The Zenoh endpoint ghnetd listens on.
    pub endpoint: String,
    pub ns: TestNamespace,
    _dir: tempfile::TempDir,
}

impl InProcess {
    /// Starts ghnetd with the test defaults (model `paper-s1`, discovery every
    /// 50 ms, no stats lines, Zenoh on the test's own unix socket), changed by
    /// `edit`.
    pub fn start(tag: &str, edit: impl FnOnce(&mut Config)) -> Self {
        Self::start_on(tag, edit, || {})
    }

    /// [`start`](Self::start), calling `on_thread` first on ghnetd's thread (e.g. to
    /// count that thread's allocations).
    pub fn start_on(tag: &str, edit: impl FnOnce(&mut Config), on_thread: fn()) -> Self {
        let ns = TestNamespace::new(tag);
        let dir = tempfile::tempdir().unwrap();
        let endpoint = unix_endpoint(dir.path().join("zenoh.sock"));
        let mut config = Config::default();
        config.model.name = "paper-s1".into();
        config.ipc.iceoryx2_global_prefix = Some(ns.global_prefix().into());
        config.ipc.iceoryx2_root_path = Some(ns.root_path().into());
        config.sources.discovery_interval_ms = 50;
        config.stats.interval_s = 0;
        config.zenoh.listen = vec![endpoint.clone()];
        edit(&mut config);
        let shutdown = ShutdownFlag::new();
        // iceoryx2 ports are !Send: run() makes its own on the thread it runs on.
        let thread = std::thread::spawn({
            let shutdown = shutdown.clone();
            move || {
                on_thread();
                ghnetd::run(config, shutdown)
            }
        });
        Self {
            shutdown,
            thread: Some(thread),
            endpoint,
            ns,
            _dir: dir,
        }
    }

    pub fn ipc(&self) -> IpcConfig {
        self.ns.ipc()
    }

    /// Panics with ghnetd's error if it has stopped already.
    pub fn assert_running(&mut self) {
        if self.thread.as_ref().is_some_and(|t| t.is_finished()) {
            let result = self.thread.take().unwrap().join().unwrap();
            panic!("ghnetd stopped early: {result:?}");
        }
    }

    /// Waits until ghnetd has subscribed to `gnss`'s velocity service.
    pub fn wait_serving(&mut self, gnss: &VelocityPublisher) {
        let t0 = Instant::now();
        while gnss.subscriber_count() == 0 {
            self.assert_running();
            assert!(t0.elapsed() < WATCHDOG, "watchdog: ghnetd never subscribed");
            std::thread::sleep(Duration::from_millis(5));
        }
    }

    /// Requests the stop and returns what `run` returned. The namespace stays until
    /// `self` is dropped, so the test's own ports (declared later, dropped earlier)
    /// close cleanly.
    pub fn stop(&mut self) -> Stats {
        self.shutdown.request();
        self.thread
            .take()
            .expect("running")
            .join()
            .expect("ghnetd's thread panicked")
            .expect("ghnetd::run failed")
    }

    /// A Zenoh session connected to this ghnetd.
    pub fn zenoh(&self) -> zenoh::Session {
        let cfg = ghnet_client::peer_config(&[], std::slice::from_ref(&self.endpoint)).unwrap();
        let session = zenoh::open(cfg).wait().unwrap();
        wait_until("a Zenoh connection to ghnetd", || {
            session.info().peers_zid().wait().next().is_some()
        });
        session
    }
}

impl Drop for InProcess {
    fn drop(&mut self) {
        // A failed test must not leave ghnetd running on a namespace being deleted.
        self.shutdown.request();
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// `unixsock-stream/<path>`.
pub fn unix_endpoint(path: PathBuf) -> String {
    format!("unixsock-stream/{}", path.display())
}

/// The JSON answer of the queryable `key` (one daemon answers).
pub fn query_json(session: &zenoh::Session, key: &str) -> serde_json::Value {
    let replies = session.get(key).wait().unwrap();
    let reply = replies
        .recv_timeout(WATCHDOG)
        .unwrap()
        .unwrap_or_else(|| panic!("no answer on {key}"));
    let bytes = reply.result().expect("an ok reply").payload().to_bytes();
    serde_json::from_slice(&bytes).unwrap()
}

/// Polls `<prefix>/@ghnetd/stats` until `cond` holds for it; returns it.
pub fn stats_when(
    session: &zenoh::Session,
    ipc: &IpcConfig,
    what: &str,
    cond: impl Fn(&serde_json::Value) -> bool,
) -> serde_json::Value {
    let t0 = Instant::now();
    loop {
        let stats = query_json(session, &ipc.zenoh_stats_key());
        if cond(&stats) {
            return stats;
        }
        assert!(
            t0.elapsed() < WATCHDOG,
            "watchdog: stats never showed {what}: {stats}"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// The next answer on `headings` that is not a `Stale` message.
pub fn next_answer(headings: &HeadingSubscriber) -> HeadingEstimate {
    loop {
        let h = headings
            .recv_timeout(WATCHDOG)
            .unwrap()
            .expect("watchdog: an answer");
        if h.heading_status() != Some(HeadingStatus::Stale) {
            return h;
        }
    }
}
