//! The command-line flags every ghnet bridge takes to find ghnetd's services
//! (feature `cli`): one [`IpcArgs`] flattened into each program's clap arguments, so
//! the flags, their docs and the rule that turns them into an [`IpcConfig`] exist
//! once.

use std::path::PathBuf;

use crate::names::{IpcConfig, NameError, DEFAULT_PREFIX};

/// Where ghnetd's services are: `--service-prefix`, `--iceoryx2-global-prefix` and
/// `--iceoryx2-root-path`, to `#[command(flatten)]` into a program's arguments.
#[derive(Debug, Clone, clap::Args)]
pub struct IpcArgs {
    /// Service prefix; must match ghnetd's ipc.service_prefix.
    #[arg(long, default_value = DEFAULT_PREFIX, value_name = "PREFIX")]
    pub service_prefix: String,

    /// iceoryx2 shared-memory file prefix, for an isolated ghnetd (its
    /// ipc.iceoryx2_global_prefix).
    #[arg(long, value_name = "PREFIX")]
    pub iceoryx2_global_prefix: Option<String>,

    /// iceoryx2 root directory, for an isolated ghnetd (its ipc.iceoryx2_root_path).
    #[arg(long, value_name = "DIR")]
    pub iceoryx2_root_path: Option<PathBuf>,
}

/// A flag of [`IpcArgs`] that breaks the naming rules; the message names the flag.
#[derive(Debug, thiserror::Error)]
pub enum IpcArgsError {
    /// `--service-prefix` is not a valid service prefix.
    #[error("--service-prefix")]
    Prefix(#[source] NameError),
    /// The iceoryx2 overrides are not a valid file-name prefix or absolute path.
    #[error("--iceoryx2-global-prefix / --iceoryx2-root-path")]
    Iceoryx2(#[source] NameError),
}

impl IpcArgs {
    /// The [`IpcConfig`] these flags describe: the prefix, with the iceoryx2
    /// overrides on top of the process-wide iceoryx2 config.
    pub fn ipc(&self) -> Result<IpcConfig, IpcArgsError> {
        IpcConfig::new(&self.service_prefix)
            .map_err(IpcArgsError::Prefix)?
            .with_iceoryx2_overrides(
                self.iceoryx2_global_prefix.as_deref(),
                self.iceoryx2_root_path.clone(),
            )
            .map_err(IpcArgsError::Iceoryx2)
    }
}

/// A bridge's `main` after parsing and logging set-up: reports a bad configuration, installs
/// the stop latch before anything blocks (iceoryx2 captures SIGINT/SIGTERM once it
/// is in use, so Ctrl-C only sets a flag), runs until stopped or failed, and maps
/// the outcome to the exit code. A stop is logged when first seen. Errors print
/// with `{:#}`, so an `anyhow` chain shows in full.
pub fn run_bridge<C, T, E: std::fmt::Display, F: std::fmt::Display>(
    config: Result<C, E>,
    run: impl FnOnce(&C, &dyn Fn() -> bool) -> Result<T, F>,
) -> std::process::ExitCode {
    use std::process::ExitCode;
    let config = match config {
        Ok(c) => c,
        Err(e) => {
            eprintln!("error: {e:#}");
            return ExitCode::FAILURE;
        }
    };
    let latch = crate::StopLatch::new();
    match run(&config, &|| latch.poll(|| tracing::info!("stop requested"))) {
        Ok(_) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

/// Sets up a bridge's logs: `tracing` on stderr (so output on stdout stays clean),
/// filtered by `RUST_LOG` or else `default_filter`; iceoryx2's own console logger
/// only for errors unless its environment variable asks for more, because the
/// bridge reports what an operator needs.
pub fn init_logs(default_filter: &str) {
    use tracing_subscriber::EnvFilter;
    iceoryx2::prelude::set_log_level_from_env_or(iceoryx2::prelude::LogLevel::Error);
    tracing_subscriber::fmt()
        .with_writer(std::io::stderr)
        .with_env_filter(
            EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new(default_filter)),
        )
        .init();
}
