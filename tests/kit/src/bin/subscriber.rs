//! `ghnet-test-subscriber`: a heading consumer in its own process, for the tests that
//! `kill -9` a subscriber (iceoryx2) or read headings from another network namespace
//! (Zenoh). Prints `ready` once subscribed, then one line `<seq> <status> <hex>` per
//! heading (hex: the 64 bytes of `encode_zenoh`), until killed.
//!
//! ```text
//! ghnet-test-subscriber iceoryx2 IOX2_GLOBAL_PREFIX IOX2_ROOT_PATH SOURCE
//! ghnet-test-subscriber zenoh ENDPOINT SERVICE_PREFIX SOURCE
//! ```

use std::io::Write;
use std::time::Duration;

use ghnet_client::zenoh::Wait;
use ghnet_client::{encode_zenoh, HeadingEstimate, HeadingSubscriber, IpcConfig};
use ghnet_client::{peer_config, ZenohHeadingSubscriber};

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let refs: Vec<&str> = args.iter().map(String::as_str).collect();
    match refs.as_slice() {
        ["iceoryx2", prefix, root, source] => {
            let ipc = IpcConfig::isolated(prefix, root).expect("namespace");
            let headings = HeadingSubscriber::new(&ipc, source).expect("subscriber");
            // A short timeout keeps the process responsive to a closed stdout.
            print_all(|| {
                headings
                    .recv_timeout(Duration::from_millis(500))
                    .expect("receive")
            });
        }
        ["zenoh", endpoint, prefix, source] => {
            let ipc = IpcConfig::new(prefix).expect("service prefix");
            let config = peer_config(&[], &[endpoint.to_string()]).expect("zenoh config");
            let session = ghnet_client::zenoh::open(config)
                .wait()
                .expect("zenoh session");
            let headings = ZenohHeadingSubscriber::new(&session, &ipc, source).expect("subscriber");
            // The model query travels behind the subscriber's declaration: once it is
            // answered, the daemon knows the subscription.
            ghnet_testkit::zenoh_barrier(&session, &ipc);
            print_all(|| {
                headings
                    .recv_timeout(Duration::from_millis(500))
                    .expect("decode")
            });
        }
        _ => {
            eprintln!(
                "usage: ghnet-test-subscriber iceoryx2 IOX2_GLOBAL_PREFIX IOX2_ROOT_PATH SOURCE\n       \
                 ghnet-test-subscriber zenoh ENDPOINT SERVICE_PREFIX SOURCE"
            );
            std::process::exit(2);
        }
    }
}

/// Prints `ready`, then every heading `next` returns, until stdout is closed.
fn print_all(mut next: impl FnMut() -> Option<HeadingEstimate>) {
    let mut out = std::io::stdout().lock();
    writeln!(out, "ready")
        .and_then(|_| out.flush())
        .expect("stdout");
    loop {
        if let Some(h) = next() {
            let hex: String = encode_zenoh(&h)
                .iter()
                .map(|b| format!("{b:02x}"))
                .collect();
            if writeln!(out, "{} {} {hex}", h.seq, h.status)
                .and_then(|_| out.flush())
                .is_err()
            {
                return; // the test is gone
            }
        }
    }
}
