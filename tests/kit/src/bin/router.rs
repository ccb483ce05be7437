//! `ghnet-test-router`: a Zenoh router in its own process (the zenoh crate in router
//! mode, as `zenohd` runs it), for the fleet tests: it can run in a network namespace
//! of its own and be killed and restarted like a real one. Listens on every ENDPOINT,
//! scouting off, prints `ready` once it listens, and runs until killed.
//!
//! ```text
//! ghnet-test-router ENDPOINT...
//! ```

use std::io::Write;

use ghnet_client::zenoh::{self, Wait};
use ghnet_testkit::router_config;

fn main() {
    let endpoints: Vec<String> = std::env::args().skip(1).collect();
    if endpoints.is_empty() {
        eprintln!("usage: ghnet-test-router ENDPOINT...");
        std::process::exit(2);
    }
    // `open` returns once every listener is bound: connecting clients find it.
    let _router = zenoh::open(router_config(&endpoints))
        .wait()
        .expect("router session");
    let mut out = std::io::stdout().lock();
    writeln!(out, "ready")
        .and_then(|_| out.flush())
        .expect("stdout");
    loop {
        std::thread::park();
    }
}
