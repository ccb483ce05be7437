//! `ghnet-ros2` binary: parses the command line, sets up logging, turns
//! SIGINT/SIGTERM into a stop request and calls [`ghnet_ros2::run`].

use std::process::ExitCode;

use clap::Parser;
use ghnet_ros2::cli::Args;

fn main() -> ExitCode {
    // iceoryx2 logs through its own console logger; the bridge reports what matters.
    ghnet_client::iceoryx2::prelude::set_log_level_from_env_or(
        ghnet_client::iceoryx2::prelude::LogLevel::Error,
    );
    let args = Args::parse();
    // RustDDS logs every discovery step at info; its warnings and ours are what an
    // operator needs. ros2-client warns about an unset ROS_DISTRO, which a pure-Rust
    // node does not need.
    tracing_subscriber::fmt()
        .with_writer(std::io::stderr)
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| {
                tracing_subscriber::EnvFilter::new("info,rustdds=warn,ros2_client=error")
            }),
        )
        .init();
    let config = match args.to_config() {
        Ok(c) => c,
        Err(e) => {
            eprintln!("error: {e:#}");
            return ExitCode::FAILURE;
        }
    };
    // iceoryx2 captures SIGINT/SIGTERM once it is in use, so Ctrl-C only sets a flag:
    // the latch installs the handlers now, before anything blocks.
    let latch = ghnet_client::StopLatch::new();
    let stop = || latch.poll(|| tracing::info!("stop requested"));
    match ghnet_ros2::run(&config, &stop) {
        Ok(_) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
