//! `ghnet-test-subscriber`: a heading consumer in its own process, for the fault
//! tests (`kill -9` of a subscriber). Prints `ready` once subscribed, then one line
//! `<seq> <status>` per heading, until killed.
//!
//! ```text
//! ghnet-test-subscriber IOX2_GLOBAL_PREFIX IOX2_ROOT_PATH SOURCE
//! ```

use std::io::Write;
use std::time::Duration;

use ghnet_client::{HeadingSubscriber, IpcConfig};

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [prefix, root, source] = args.as_slice() else {
        eprintln!("usage: ghnet-test-subscriber IOX2_GLOBAL_PREFIX IOX2_ROOT_PATH SOURCE");
        std::process::exit(2);
    };
    let ipc = IpcConfig::isolated(prefix, root).expect("namespace");
    let headings = HeadingSubscriber::new(&ipc, source).expect("subscriber");
    let mut out = std::io::stdout().lock();
    writeln!(out, "ready")
        .and_then(|_| out.flush())
        .expect("stdout");
    loop {
        // A short timeout keeps the process responsive to a closed stdout.
        if let Some(h) = headings
            .recv_timeout(Duration::from_millis(500))
            .expect("receive")
        {
            if writeln!(out, "{} {}", h.seq, h.status)
                .and_then(|_| out.flush())
                .is_err()
            {
                return; // the test is gone
            }
        }
    }
}
