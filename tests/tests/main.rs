//! Cross-process tests of ghnet: the real `ghnetd` binary (found by
//! `ghnet_tests::ghnetd_binary`; build it with `cargo build -p ghnetd` or run
//! `cargo test --workspace`), real iceoryx2 shared memory, each test in its own
//! namespace. One binary, one module per topic.

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

/// Path of the helper publisher binary of this package.
pub const TEST_PUBLISHER: &str = env!("CARGO_BIN_EXE_ghnet-test-publisher");

/// Path of the helper subscriber binary of this package.
pub const TEST_SUBSCRIBER: &str = env!("CARGO_BIN_EXE_ghnet-test-subscriber");
