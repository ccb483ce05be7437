//! `ghnet-ros2` binary: parses the command line, sets up logging, turns
//! SIGINT/SIGTERM into a stop request and calls [`ghnet_ros2::run`].

use std::process::ExitCode;

use clap::Parser;
use ghnet_ros2::cli::Args;

fn main() -> ExitCode {
    let config = Args::parse().to_config();
    // RustDDS logs every discovery step at info; its warnings and ours are what an
    // operator needs. ros2-client warns about an unset ROS_DISTRO, which a pure-Rust
    // node does not need.
    ghnet_client::cli::init_logs("info,rustdds=warn,ros2_client=error");
    ghnet_client::cli::run_bridge(config, ghnet_ros2::run)
}
