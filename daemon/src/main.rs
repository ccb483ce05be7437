//! `ghnetd` binary: layers the config, initialises tracing, turns SIGINT/SIGTERM into
//! a shutdown request, and calls [`ghnetd::run`]. Everything else is in the library.

use std::io::IsTerminal;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::OnceLock;

use clap::{CommandFactory, FromArgMatches, Parser};
use ghnetd::{Config, ShutdownFlag};
use iceoryx2_bb_posix::signal::{FetchableSignal, SignalHandler};

/// The command line: which file, what to do, and every config key as its flag (the
/// keys' flags, docs and defaults are defined on [`Config`]'s fields).
#[derive(Debug, Parser)]
#[command(
    name = "ghnetd",
    version,
    about = "ghnet heading sidecar: answers GNSS velocity samples on iceoryx2 with heading estimates",
    long_about = "ghnet heading sidecar: reads VelocitySample from <prefix>/<source>/velocity \
                  and answers each with one HeadingEstimate on <prefix>/<source>/heading.\n\n\
                  Precedence: built-in defaults < --config file < flags. Logging: RUST_LOG \
                  (default info, Zenoh's gossip-disabled warning off). SIGINT/SIGTERM: \
                  answer what is buffered, release iceoryx2 resources, exit 0."
)]
struct Cli {
    /// TOML config file; without one the built-in defaults apply.
    #[arg(long, short = 'c', env = "GHNETD_CONFIG", value_name = "FILE")]
    config: Option<PathBuf>,
    /// Print the effective config as TOML and exit.
    #[arg(long)]
    print_config: bool,
    /// The keys; [`Config::load`] reads which of them were given from the matches.
    #[command(flatten)]
    keys: Config,
}

/// The flag the signal handler sets; a static because handlers take no context.
static SHUTDOWN: OnceLock<ShutdownFlag> = OnceLock::new();

fn on_signal(_: FetchableSignal) {
    // Async-signal-safe: an atomic load and an atomic store.
    if let Some(flag) = SHUTDOWN.get() {
        flag.request();
    }
}

/// The log filter without `RUST_LOG`: see `main`.
const DEFAULT_LOG: &str = "info,zenoh::net::routing::hat::peer=error";

fn main() -> ExitCode {
    // iceoryx2 logs through its own multi-line console logger; ghnetd reports every
    // failure that matters itself, so keep iceoryx2 to errors unless IOX2_LOG_LEVEL
    // asks for more (e.g. IOX2_LOG_LEVEL=warn when debugging the transport).
    ghnet_client::iceoryx2::prelude::set_log_level_from_env_or(
        ghnet_client::iceoryx2::prelude::LogLevel::Error,
    );
    let matches = Cli::command().get_matches();
    let cli = Cli::from_arg_matches(&matches).unwrap_or_else(|e| e.exit());
    let config = match Config::load(cli.config.as_deref(), &matches) {
        Ok(c) => c,
        Err(e) => {
            eprintln!("error: {e:#}");
            return ExitCode::FAILURE;
        }
    };
    if cli.print_config {
        print!("{}", config.to_toml());
        return ExitCode::SUCCESS;
    }
    // Owner-only for everything created from here on: the lock file, the iceoryx2
    // root directory if it does not exist yet, and the initial mode of iceoryx2's
    // files. iceoryx2 0.10 already gives its shared memory, records and sockets
    // owner-only modes, but creates some directories group/other-readable
    // (client/README.md, "Permissions"). Only a process of the same user can then
    // open ghnet's services, which iceoryx2's owner-only shared memory requires anyway.
    // SAFETY: umask(2) cannot fail and touches no memory.
    unsafe {
        libc::umask(0o077);
    }

    // Logs go to stderr (stdout stays clean for --print-config and pipes). Without
    // RUST_LOG: info, except Zenoh's peer routing, which warns at every start that
    // gossip is disabled, as ghnetd configures it on purpose (no scouting).
    tracing_subscriber::fmt()
        .with_writer(std::io::stderr)
        .with_ansi(std::io::stderr().is_terminal())
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(DEFAULT_LOG)),
        )
        .init();
    // ghnetd owns the signals. Registering through iceoryx2's SignalHandler (not
    // another crate) matters: iceoryx2 installs its own capturing handlers the first
    // time its signal module is used, which would silently replace a foreign handler.
    let shutdown = SHUTDOWN.get_or_init(ShutdownFlag::new).clone();
    let _signal_guard = match SignalHandler::register_multiple_signals(
        &vec![FetchableSignal::Interrupt, FetchableSignal::Terminate],
        &on_signal,
    ) {
        Ok(g) => g,
        Err(e) => {
            eprintln!("error: cannot install SIGINT/SIGTERM handlers: {e:?}");
            return ExitCode::FAILURE;
        }
    };

    match ghnetd::run(config, shutdown) {
        Ok(_) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
