//! `ghnet_ros2`: the ROS 2 bridge. Subscribes to ghnetd's headings over iceoryx2 and
//! publishes each as `sensor_msgs/msg/Imu` on `/ghnet/<source>/heading` (node
//! `ghnet`), plus `diagnostic_msgs/msg/DiagnosticArray` on `/diagnostics` once a
//! second; over DDS (interoperating with `rmw_fastrtps_cpp`) or rmw_zenoh's wire.
//!
//! # Layout
//!
//! - [`cli`] — [`Args`](cli::Args), the command line (its doc comments are `--help`),
//!   checked into a [`Config`].
//! - [`names`] — ROS names: the topic of a source, the documented mapping of ghnet
//!   source names onto ROS names, frame and domain ids.
//! - [`msg`] — the ROS messages as serde structs in `.msg` field order (CDR-ready).
//! - [`relay`] — the rules without I/O: heading → Imu (REP-103 yaw, covariances, the
//!   status rules, `Held` fused once per stop), a source's `DiagnosticStatus`.
//! - [`output`] — [`output::Output`], what a middleware must do; [`dds`]
//!   (ros2-client on RustDDS) and [`zenoh_out`] (rmw_zenoh's keys, payload,
//!   attachment and liveliness tokens) implement it.
//! - `bridge` — the loop: an iceoryx2 `WaitSet` over the heading services, discovery
//!   of sources, `/diagnostics` once a second.
//!
//! [`run`] takes the stop request as a parameter; the binary passes iceoryx2's
//! SIGINT/SIGTERM flag, tests their own.

#![warn(missing_docs)]

mod bridge;
pub mod cli;
pub mod dds;
pub mod msg;
pub mod names;
pub mod output;
pub mod relay;
pub mod zenoh_out;

use ghnet_client::IpcConfig;

pub use bridge::{heading_sources, TICK};
use output::Output;
pub use relay::Counters;

/// The ROS middleware the bridge speaks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Rmw {
    /// DDS (RTPS over UDP), as `rmw_fastrtps_cpp` and `rmw_cyclonedds_cpp`.
    Dds,
    /// rmw_zenoh's wire format on a Zenoh session (via a router).
    Zenoh,
}

/// Everything a run needs; [`cli::Args`] builds it from the command line.
#[derive(Debug, Clone)]
pub struct Config {
    /// Sources to relay; empty: every source ghnetd serves, found at run time.
    pub sources: Vec<String>,
    /// ROS domain id (0–232).
    pub domain_id: u16,
    /// `header.frame_id` of every Imu.
    pub frame_id: String,
    /// The middleware.
    pub rmw: Rmw,
    /// The Zenoh router to connect to (`--rmw zenoh`).
    pub zenoh_router: String,
    /// ghnetd's service prefix and iceoryx2 namespace.
    pub ipc: IpcConfig,
}

/// Runs the bridge until `stop` returns true; the counters of every source at the
/// end. Errors are start-up errors (a topic collision, a participant that cannot be
/// made) or a broken iceoryx2 installation; faults while running are counted and
/// logged, not returned.
pub fn run(config: &Config, stop: &dyn Fn() -> bool) -> anyhow::Result<Vec<(String, Counters)>> {
    let mut out: Box<dyn Output> = match config.rmw {
        Rmw::Dds => Box::new(dds::DdsOutput::new(config.domain_id)?),
        Rmw::Zenoh => Box::new(zenoh_out::ZenohOutput::new(
            config.domain_id,
            &config.zenoh_router,
        )?),
    };
    let mut sources = bridge::Sources::default();
    for s in &config.sources {
        sources.add(s, &config.ipc, out.as_mut())?;
    }
    tracing::info!(
        domain_id = config.domain_id,
        rmw = ?config.rmw,
        prefix = config.ipc.prefix(),
        sources = if config.sources.is_empty() { "discovered".to_owned() } else { config.sources.join(",") },
        "ghnet-ros2 started"
    );
    let counters = bridge::serve(config, sources, out.as_mut(), stop)?;
    for (name, c) in &counters {
        tracing::info!(
            source = %name,
            relayed = c.relayed,
            send_failures = c.send_failures,
            missed = c.missed,
            "summary"
        );
    }
    Ok(counters)
}
