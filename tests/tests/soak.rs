//! The CI soak (issue #5): 100 sources × 10 Hz × 60 s against a real ghnetd; every
//! sequence number gets exactly one heading on iceoryx2 and on Zenoh (same bytes on
//! both), and ghnetd's resident memory grows by less than 1 MB after the warm-up.
//!
//! Runs `ghnet_examples::soak::run`, the logic of the `soak` example, in this process;
//! the daemon is the real binary. `GHNET_SOAK_SECONDS` runs it longer (or shorter,
//! while iterating; under ~15 s the memory check has too few samples and fails).

use std::time::Duration;

use ghnet_examples::soak::{self, Options};
use ghnet_tests::{unique_prefix, Daemon, Namespace, WATCHDOG};

#[test]
fn hundred_sources_exactly_once_on_iceoryx2_and_zenoh_with_flat_memory() {
    let seconds: u64 = std::env::var("GHNET_SOAK_SECONDS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(60);
    let ns = Namespace::new();
    let prefix = unique_prefix("soak");
    let mut opts = Options::new(ns.ipc().with_prefix(&prefix).unwrap(), &prefix);
    opts.sources = 100;
    opts.rate_hz = 10.0;
    opts.duration = Duration::from_secs(seconds);
    // Bounds against hangs on a loaded machine, not performance limits.
    (opts.patience, opts.drain_timeout) = (WATCHDOG, WATCHDOG);

    let names = opts.daemon_sources();
    let max = names.len().to_string();
    let mut args = vec!["--service-prefix", &prefix, "--discovery", "false"];
    // ghnetd's default Zenoh transmit queue (daemon/src/config.rs) is what this test
    // proves: Zenoh's own default lost 18% of the headings here.
    args.extend(["--max-sources", &max]);
    for n in &names {
        args.extend(["--source", n]);
    }
    let daemon = Daemon::start(&ns, &args);
    opts.zenoh_connect = Some(daemon.zenoh_endpoint());
    opts.daemon_pid = Some(daemon.pid());

    let log_tail = |daemon: &Daemon| {
        let log = daemon.log();
        let lines: Vec<&str> = log.lines().collect();
        lines[lines.len().saturating_sub(40)..].join("\n")
    };
    let report = soak::run(&opts).unwrap_or_else(|e| {
        panic!(
            "soak did not run: {e:#}\nghnetd log tail:\n{}",
            log_tail(&daemon)
        )
    });
    println!("{report}");
    daemon.assert_running();
    assert!(!report.interrupted);
    assert_eq!(report.sent, opts.samples_per_source());
    let failures = report.failures();
    assert!(
        failures.is_empty(),
        "{failures:#?}\n{report}\nghnetd log tail:\n{}",
        log_tail(&daemon)
    );
    // The daemon's own counters agree: it received every sample of a source.
    daemon.wait_for_stats(&names[0], |s| s.get("received") == Some(&report.sent));
    let (status, _) = daemon.terminate();
    assert!(status.success(), "{status}");
}
