//! Cross-process tests of ghnet: the real `ghnetd` binary, real iceoryx2 shared memory
//! and real Zenoh, each test in its own namespace with its own Zenoh endpoint, on the
//! test kit (`ghnet_testkit`). One binary, one module per topic.
//!
//! # Layout
//!
//! - `echo` — answers equal the in-process model, exactly once, in order; `invalid`,
//!   `bad_input` — every row of the bad-input table; `config` — start-up errors.
//! - `discovery` — sources that appear at run time, sources that never cross.
//! - `live_offline` — a tricky log answered alike by a real ghnetd and `ghnet infer`.
//! - `history` — stateful models: `Held` stops, answers equal to the in-process
//!   `StreamPredictor` to the bit, per-source histories, resets and their counters.
//! - `crash`, `faults`, `shutdown` — `kill -9` of the daemon, a publisher or a
//!   subscriber; stuck subscribers, silent sources, a second daemon, full services,
//!   permissions; SIGTERM.
//! - `zenoh_output`, `zenoh_acl`, `netns`, `python` — the Zenoh output, its access
//!   control, another network namespace, the Python clients.
//! - `pressure` — reliability under pressure: sources retried until
//!   served, descriptors and shared memory running out, hostile model files, root
//!   paths, source names and `ghnet infer` arguments.
//! - `soak` — 100 sources × 10 Hz × 60 s through `ghnet_tools::soak`.
//! - `ros2` — the `ghnet-ros2` bridge against real ROS 2: an rclpy node (Fast DDS) in a
//!   network namespace checks every Imu and `/diagnostics`; rmw_zenoh's wire read by
//!   `eclipse-zenoh` and decoded by `rosbags`.
//! - `gnss` — every real receiver capture through the `ghnet-gnss` bridge; `fleet` —
//!   two vehicles through a Zenoh router, one wildcard consumer, a router restart;
//!   again with each vehicle and the router in network namespaces of their own.
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
mod fleet;
mod gnss;
mod history;
mod invalid;
mod live_offline;
mod netns;
mod pressure;
mod python;
mod ros2;
mod shutdown;
mod soak;
mod zenoh_acl;
mod zenoh_output;
