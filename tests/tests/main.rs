//! Cross-process tests of ghnet: the real `ghnetd` binary, real iceoryx2 shared memory
//! and real Zenoh, each test in its own namespace with its own Zenoh endpoint, on the
//! test kit (`ghnet_testkit`). One binary, one module per topic.
//!
//! The kit finds `ghnetd` and its own bins next to this executable: `cargo test
//! --workspace` builds them; for this crate alone, `cargo build -p ghnetd -p
//! ghnet-testkit` first. Tests that need root and `ip`, or Python with the ghnet
//! packages, are `#[ignore]`d with the reason; `.ci/run` runs them with
//! `--include-ignored`.

mod bad_input;
mod config;
mod crash;
mod discovery;
mod echo;
mod faults;
mod invalid;
mod netns;
mod python;
mod shutdown;
mod soak;
mod zenoh_acl;
mod zenoh_output;
