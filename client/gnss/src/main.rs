//! `ghnet-gnss` binary: parses the command line, sets up logging, turns
//! SIGINT/SIGTERM into a stop request and calls [`ghnet_gnss::run`].

use std::process::ExitCode;

use clap::Parser;
use ghnet_gnss::cli::Args;

fn main() -> ExitCode {
    let config = Args::parse().to_config();
    ghnet_client::cli::init_logs("info");
    ghnet_client::cli::run_bridge(config, ghnet_gnss::run)
}
