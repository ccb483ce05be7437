//! The test kit of ghnet: what every cross-process test, the soak and the perf tool
//! need to run real `ghnetd` processes against real iceoryx2 shared memory and real
//! Zenoh, each in a namespace of its own.
//!
//! # Layout
//!
//! - [`TestNamespace`] — the one namespace type (re-exported from
//!   `ghnet_client::testing`): a private iceoryx2 global prefix and root path per test,
//!   scratch directories beside them, removed on drop; the first one of a process
//!   sweeps the leftovers of crashed runs.
//! - [`ghnetd`] — [`Ghnetd`], a running daemon: spawned with a [`GhnetdBuilder`],
//!   ready when its iceoryx2 node is alive and its model query answers, Zenoh on an
//!   endpoint the kit chooses ([`Listen`]: a unix socket in a scratch directory by
//!   default), counters read from `<prefix>/@ghnetd/stats`, SIGTERM, `kill -9`, reaped
//!   on drop, its log in a file for failure messages. [`run_ghnetd`] runs one to its
//!   (start-up failure) exit; [`OneSource`] is the setup most tests start from (a
//!   daemon serving one static source, and that source's publisher and subscriber).
//! - [`child`] — [`ChildPublisher`] and [`ChildSubscriber`], a GNSS source and a
//!   heading consumer in processes of their own (the kit's bins
//!   `ghnet-test-publisher`, `ghnet-test-subscriber`) that a test can `kill -9`;
//!   [`ChildRouter`], a Zenoh router process (`ghnet-test-router`) for the fleet.
//! - [`netns`] — [`NetNamespace`], a network namespace as another "host" (unique
//!   names, deleted on drop, leftovers of killed runs swept), veth pairs between
//!   them; needs root and `ip`.
//! - [`wait_until`], [`WATCHDOG`] — bounded waits: a hang becomes a failure, no
//!   duration is ever asserted.
//! - [`recv_answer`] — the next heading that answers a sample (skipping `Stale`);
//!   [`assert_silent`] — no extra heading; [`zenoh_barrier`] — returns once a daemon
//!   knows a session's subscribers.
//! - [`assert_success`] (re-exported) — a child command succeeded, or its stderr in
//!   the failure.
//! - [`list_nodes`] — a namespace's iceoryx2 nodes, alive and dead.
//! - [`test_model`] — the model the daemons run, loaded in-process for comparisons.
//!
//! # Binaries
//!
//! `ghnetd` and the kit's bins are found next to the running executable
//! (`target/<profile>/`, see [`find_binary`]). `cargo test --workspace` builds them;
//! for one test crate alone, `cargo build -p ghnetd -p ghnet-testkit` first.
//! `GHNETD_BIN` points at another daemon build.
//!
//! # Rules every test follows
//!
//! - Its own [`TestNamespace`], declared first so that it is dropped last, after every
//!   process using it has been reaped (the handles reap on drop).
//! - Children get `PR_SET_PDEATHSIG(SIGKILL)`: if the test process dies, its daemons
//!   and publishers die with it. Linux sends it when the *thread* that spawned the
//!   child ends, so spawn children on the test's own thread.

#![warn(missing_docs)]

pub mod child;
pub mod ghnetd;
pub mod netns;

use std::path::PathBuf;
use std::sync::{Arc, OnceLock};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

pub use child::{ChildPublisher, ChildRouter, ChildSubscriber, Heading};
pub use ghnet_client::testing::{assert_success, foreign_service, TestNamespace};
use ghnet_client::zenoh::{self, Wait};
use ghnet_client::{
    HeadingEstimate, HeadingStatus, HeadingSubscriber, IpcConfig, VelocityPublisher, VelocitySample,
};
use ghnet_inference::Model;
pub use ghnetd::{run_ghnetd, Counters, Ghnetd, GhnetdBuilder, Listen, OneSource};
pub use netns::NetNamespace;

/// Upper bound of every wait. Generous on purpose: tests run in parallel on small
/// machines; this only turns a hang into a failure, it is not a performance limit.
pub const WATCHDOG: Duration = Duration::from_secs(60);

/// Polls `cond` every 5 ms until it holds; panics naming `what` after [`WATCHDOG`].
pub fn wait_until(what: &str, cond: impl FnMut() -> bool) {
    if let Err(e) = poll_until(what, WATCHDOG, Duration::from_millis(5), cond) {
        panic!("watchdog: {e}");
    }
}

/// Polls `cond` every `poll` until it holds; an error naming `what` after `timeout`.
/// The fallible form of [`wait_until`], for tools.
pub fn poll_until(
    what: &str,
    timeout: Duration,
    poll: Duration,
    mut cond: impl FnMut() -> bool,
) -> anyhow::Result<()> {
    let t0 = Instant::now();
    while !cond() {
        anyhow::ensure!(t0.elapsed() < timeout, "no {what} after {timeout:?}");
        std::thread::sleep(poll);
    }
    Ok(())
}

/// Nanoseconds since the Unix epoch, for sample timestamps.
pub fn now_ns() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .expect("clock after 1970")
        .as_nanos() as u64
}

/// The next heading that answers a sample, skipping `Stale` messages (ghnetd sends
/// one when a source is silent for `sources.stale_after_ms`; it repeats the last
/// sequence number and is not an answer). `None` after `timeout` without an answer.
/// Exactly-once checks use this, so a slow test machine cannot turn a pause into a
/// spurious extra message.
pub fn recv_answer(headings: &HeadingSubscriber, timeout: Duration) -> Option<HeadingEstimate> {
    let deadline = Instant::now() + timeout;
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        let h = headings.recv_timeout(left).expect("receive")?;
        if h.heading_status() != Some(HeadingStatus::Stale) {
            return Some(h);
        }
    }
}

/// A moving sample (3 m/s north, 4 m/s east) with sequence number `seq`, stamped now:
/// the plain input of tests about delivery rather than heading.
pub fn moving_sample(seq: u64) -> VelocitySample {
    VelocitySample::new(now_ns(), seq, 3.0, 4.0, 0.0)
}

/// Sends [`moving_sample`]`(seq)` on `gnss` and checks that the next answer on
/// `headings` (skipping `Stale`) is exactly that sample's.
pub fn round_trip(gnss: &VelocityPublisher, headings: &HeadingSubscriber, seq: u64) {
    gnss.send(moving_sample(seq)).unwrap();
    let h = recv_answer(headings, WATCHDOG)
        .unwrap_or_else(|| panic!("{}: no answer to {seq}", headings.service_name()));
    assert_eq!(h.seq, seq, "{}", headings.service_name());
}

/// Asserts that nothing more arrives on `headings` within `quiet` (after the answers a
/// test expected: exactly one answer per sample, no late duplicate).
pub fn assert_silent(headings: &HeadingSubscriber, quiet: Duration) {
    let extra = headings.recv_timeout(quiet).expect("receive");
    assert!(
        extra.is_none(),
        "{}: unexpected {extra:?}",
        headings.service_name()
    );
}

/// Returns once the daemon that `session` is connected to answers its model query.
/// The query travels after every declaration made before it on the same link, so
/// afterwards the daemon knows this session's subscribers and no heading is missed.
pub fn zenoh_barrier(session: &zenoh::Session, ipc: &IpcConfig) {
    let key = ipc.zenoh_model_key();
    wait_until(&format!("an answer on {key}"), || {
        model_answers(session, ipc)
    });
}

/// Whether a daemon on `session` answers a model query on `ipc`'s prefix (within a
/// second): it is up, and it has seen every declaration the session made before.
pub fn model_answers(session: &zenoh::Session, ipc: &IpcConfig) -> bool {
    let Ok(replies) = session
        .get(ipc.zenoh_model_key())
        .timeout(Duration::from_secs(1))
        .wait()
    else {
        return false;
    };
    matches!(replies.recv(), Ok(r) if r.result().is_ok())
}

/// The Zenoh config of a router listening on `endpoints`: ghnet's peer config (scouting
/// off) in router mode, as `zenohd` runs it, with the transmit queue a router of
/// headings needs ([`ghnet_client::ZENOH_TX_QUEUE`]). One definition for the fleet
/// tests' router, whether it runs in the test or as the `ghnet-test-router` process.
pub fn router_config(endpoints: &[String]) -> zenoh::Config {
    let mut c = ghnet_client::peer_config(endpoints, &[]).expect("zenoh config");
    c.insert_json5("mode", "\"router\"").expect("router mode");
    for (key, value) in ghnet_client::ZENOH_TX_QUEUE {
        c.insert_json5(key, value).expect("transmit queue");
    }
    c
}

/// A free TCP port on loopback, for a Zenoh endpoint a test chooses (the kernel picks
/// it; it is free again a moment later for whoever binds it next).
pub fn free_tcp_port() -> u16 {
    let listener = std::net::TcpListener::bind("127.0.0.1:0").expect("bind 127.0.0.1:0");
    listener.local_addr().expect("bound address").port()
}

/// The executable `name` next to the running one: in its directory or up to two levels
/// above (`target/<profile>/deps/cross_process-…` → `target/<profile>/<name>`), where
/// cargo puts the binaries of the workspace.
///
/// A test crate cannot use `env!("CARGO_BIN_EXE_…")` for another package's binary, so
/// `cargo test -p <one crate>` does not build it: `cargo test --workspace` does, or
/// `cargo build -p ghnetd -p ghnet-testkit` first.
pub fn find_binary(name: &str) -> anyhow::Result<PathBuf> {
    let exe = std::env::current_exe()?;
    let file = format!("{name}{}", std::env::consts::EXE_SUFFIX);
    exe.ancestors()
        .skip(1)
        .take(3)
        .map(|dir| dir.join(&file))
        .find(|p| p.is_file())
        .ok_or_else(|| {
            anyhow::anyhow!(
                "cannot find `{name}` near {}: build it with the same profile and target \
                 dir (`cargo build -p ghnetd -p ghnet-testkit`, or `cargo test --workspace`, \
                 which builds every binary)",
                exe.display()
            )
        })
}

/// The iceoryx2 nodes of `ns` by state: `(alive, dead)`, each as the `Debug` text of
/// the node id plus the node name. A dead node is a process that died without
/// releasing its resources; the next node created in the namespace (or ghnetd's
/// housekeeping) removes them.
pub fn list_nodes(ns: &TestNamespace) -> (Vec<String>, Vec<String>) {
    use iceoryx2::node::{NodeDetails, NodeView};
    use iceoryx2::prelude::*;
    let (mut alive, mut dead) = (Vec::new(), Vec::new());
    let describe = |id: &dyn std::fmt::Debug, details: &Option<NodeDetails>| {
        let name = details.as_ref().map(|d| d.name().to_string());
        format!("{id:?} {}", name.unwrap_or_default())
    };
    Node::<ipc::Service>::list(&ns.ipc().iceoryx2_config(), |state| {
        match state {
            NodeState::Alive(v) => alive.push(describe(v.id(), v.details())),
            NodeState::Dead(v) => dead.push(describe(v.id(), v.details())),
            NodeState::Inaccessible(id) | NodeState::Undefined(id) => {
                dead.push(format!("{id:?} (inaccessible or undefined)"))
            }
        }
        CallbackProgression::Continue
    })
    .expect("list iceoryx2 nodes");
    (alive, dead)
}

/// The model under test, and how the daemon is told to use it.
#[derive(Debug)]
pub struct TestModel {
    /// The model, loaded like the daemon loads it (`Model::from_name_or_path`).
    pub model: Arc<Model>,
    /// The built-in name to pass as `--model`; `None` when it is the daemon's
    /// default (then no `--model` flag is passed at all).
    pub flag: Option<&'static str>,
}

/// The model every daemon of the kit runs unless told otherwise, loaded the way the
/// daemon loads it.
///
/// Normally the default built-in model (`ghnet_inference::DEFAULT_MODEL`), so the tests
/// exercise what ships without a `--model` flag. While its embedded weights fail to
/// load (e.g. a placeholder during retraining), the first other built-in model that
/// loads is used and passed as `--model <name>`, so the IPC tests still run; a note
/// says so. Panics if no built-in model loads.
pub fn test_model() -> &'static TestModel {
    static MODEL: OnceLock<TestModel> = OnceLock::new();
    MODEL.get_or_init(|| {
        let default = ghnet_inference::DEFAULT_MODEL;
        let others = ghnet_inference::model::BUILTIN.iter().map(|(name, _)| *name);
        let mut errors = Vec::new();
        for name in std::iter::once(default).chain(others.filter(|n| *n != default)) {
            match Model::from_name_or_path(name) {
                Ok(m) => {
                    if name != default {
                        eprintln!(
                            "note: the default model does not load ({}); ghnetd runs `--model {name}` in these tests",
                            errors.join("; ")
                        );
                    }
                    let flag = (name != default).then_some(name);
                    return TestModel {
                        model: Arc::new(m),
                        flag,
                    };
                }
                Err(e) => errors.push(e.to_string()),
            }
        }
        panic!("no built-in model loads: {}", errors.join("; "));
    })
}
