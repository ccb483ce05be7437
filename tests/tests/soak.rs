//! The CI soak: 100 sources × 10 Hz × 60 s against a real ghnetd; every
//! sequence number gets exactly one heading on iceoryx2 and on Zenoh (same bytes on
//! both), and ghnetd's resident memory grows by less than 1 MB after the warm-up.
//!
//! Runs `ghnet_tools::soak::run`, the logic of the `soak` tool, in this process; the
//! daemon is the real binary. `GHNET_SOAK_SECONDS` runs it longer (or shorter, while
//! iterating; under ~15 s the memory check has too few samples and fails).

use std::time::Duration;

use ghnet_testkit::{TestNamespace, WATCHDOG};
use ghnet_tools::soak::{self, Options};

#[test]
fn hundred_sources_exactly_once_on_iceoryx2_and_zenoh_with_flat_memory() {
    let seconds: u64 = std::env::var("GHNET_SOAK_SECONDS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(60);
    let ns = TestNamespace::new("soak");
    let mut opts = Options::new(ns.ipc(), "soak");
    opts.duration = Duration::from_secs(seconds);
    // Bounds against hangs on a loaded machine, not performance limits.
    (opts.patience, opts.drain_timeout) = (WATCHDOG, WATCHDOG);
    // ghnetd's default Zenoh transmit queue (daemon/src/config.rs) is what this test
    // proves: Zenoh's own default lost 18% of the headings here.
    let daemon = opts.daemon(&ns).start();
    opts.zenoh_connect = Some(daemon.zenoh_endpoint().to_owned());
    opts.daemon_pid = Some(daemon.pid());

    let report = soak::run(&opts)
        .unwrap_or_else(|e| panic!("soak did not run: {e:#}\nghnetd {}", daemon.log_tail(40)));
    println!("{report}");
    daemon.assert_running();
    assert!(!report.interrupted);
    assert_eq!(report.sent, opts.samples_per_source());
    let failures = report.failures();
    assert!(
        failures.is_empty(),
        "{failures:#?}\n{report}\nghnetd {}",
        daemon.log_tail(40)
    );
    // The daemon's own counters agree: it received every sample of a source.
    let first = &opts.source_names()[0];
    daemon.wait_for_counters(first, |c| c["received"] == report.sent);
    daemon.stop();
}
