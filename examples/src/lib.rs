//! Shared pieces of the ghnet examples, so that each example in `src/bin/` shows only
//! its one idea. See `examples/README.md` for how to run them.
//!
//! # Layout
//!
//! - [`CommonArgs`] — `--prefix`, flattened into every example; gives the
//!   [`IpcConfig`] all ghnet helpers take. [`SourceArgs`] — `--prefix` and `--source`.
//!   [`ZenohArgs`] — `--connect` / `--zenoh-config` of the Zenoh examples.
//! - [`pacing_node`], [`Pacer`], [`wait_for_subscriber`] — an iceoryx2 node whose
//!   `wait` paces a loop and reports Ctrl-C / SIGTERM (the iceoryx2 idiom
//!   `while node.wait(cycle).is_ok()`), a fixed-rate schedule on it, and the wait for
//!   the daemon before the first sample.
//! - [`Vehicle`] — a simulated vehicle: one track of
//!   `ghnet_lab::sim::simulate_realistic`, replayed as [`VelocitySample`]s.
//!   [`CarDrive`] — the demo's car that drives, stops and backs up, with its truth.
//! - [`now_ns`], [`latency_since`] — wall-clock timestamps in the unit the wire wants,
//!   and a heading's age; [`log_to_stderr`] — tracing for the demo's daemon.
//! - [`PrivateNamespace`] — the demo's `--isolated`: a private iceoryx2 namespace
//!   from the client's public `IpcConfig::isolated`, removed on drop.
//! - [`table`] — the live heading table of `subscriber`, `zenoh_subscriber` and
//!   `demo`, a list of columns (add one to show another estimate beside ghnet's);
//!   [`TablePrinter`] prints it from a thread of its own.

#![warn(missing_docs)]

use std::fmt;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering::Relaxed};
use std::sync::{mpsc, Arc};
use std::thread::JoinHandle;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use anyhow::Context;
use ghnet_client::{
    flags, HeadingEstimate, HeadingSubscriber, IpcConfig, RecvError, VelocityPublisher,
    VelocitySample,
};
use ghnet_lab::drive::{simulate_track, DriveParams, DriveSample, Platform};
use ghnet_lab::sim::{simulate_realistic, RealisticParams, Sample};
use iceoryx2::prelude::*;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// Arguments every example takes.
#[derive(Debug, Clone, clap::Args)]
pub struct CommonArgs {
    /// Service prefix: the services are `<PREFIX>/<source>/velocity` and
    /// `<PREFIX>/<source>/heading`. Must match ghnetd's `ipc.service_prefix`.
    #[arg(long, default_value = ghnet_client::DEFAULT_PREFIX, value_name = "PREFIX")]
    pub prefix: String,
}

impl CommonArgs {
    /// The [`IpcConfig`] for `--prefix`, on the system iceoryx2 config (where a
    /// `ghnetd` started without iceoryx2 overrides lives).
    pub fn ipc(&self) -> anyhow::Result<IpcConfig> {
        IpcConfig::new(&self.prefix).context("--prefix")
    }
}

/// `--prefix` and `--source`: the services of one source, for the examples that
/// publish or read them.
#[derive(Debug, Clone, clap::Args)]
pub struct SourceArgs {
    #[command(flatten)]
    #[allow(missing_docs)]
    pub common: CommonArgs,
    /// Source name: the `<source>` level of the service names.
    #[arg(long = "source", default_value = "gnss0", value_name = "SOURCE")]
    pub name: String,
}

impl SourceArgs {
    /// See [`CommonArgs::ipc`].
    pub fn ipc(&self) -> anyhow::Result<IpcConfig> {
        self.common.ipc()
    }
}

/// Where the Zenoh examples find ghnetd: flattened into `zenoh_subscriber` and
/// `zenoh_stats`.
#[derive(Debug, Clone, clap::Args)]
pub struct ZenohArgs {
    /// Zenoh endpoint to connect to: ghnetd's `zenoh.listen` (or a Zenoh router).
    #[arg(long, default_value_t = format!("tcp/127.0.0.1:{}", ghnet_client::DEFAULT_ZENOH_PORT), value_name = "ENDPOINT")]
    pub connect: String,
    /// A standard Zenoh json5 config instead of `--connect` (TLS, routers, ...).
    #[arg(long, value_name = "FILE")]
    pub zenoh_config: Option<std::path::PathBuf>,
}

impl ZenohArgs {
    /// Opens the session: loopback-only peer connected to `--connect` (no scouting, no
    /// listening), or the `--zenoh-config` file as is.
    pub fn open(&self) -> anyhow::Result<ghnet_client::zenoh::Session> {
        use ghnet_client::zenoh::{self, Wait};
        let config = match &self.zenoh_config {
            Some(path) => zenoh::Config::from_file(path)
                .map_err(|e| anyhow::anyhow!("--zenoh-config {}: {e}", path.display()))?,
            None => ghnet_client::peer_config(&[], std::slice::from_ref(&self.connect))
                .map_err(|e| anyhow::anyhow!("--connect {}: {e}", self.connect))?,
        };
        zenoh::open(config)
            .wait()
            .map_err(|e| anyhow::anyhow!("cannot open the Zenoh session: {e}"))
    }
}

/// A node on `ipc`'s iceoryx2 config in the default signal mode: `node.wait(d)` sleeps
/// `d` and returns `Err` once Ctrl-C or SIGTERM arrived, so a loop stops cleanly and
/// drops its ports (iceoryx2 captures those signals once its signal module is in use,
/// so a plain `sleep` loop would not stop).
pub fn pacing_node(ipc: &IpcConfig, name: &str) -> anyhow::Result<Node<ipc::Service>> {
    NodeBuilder::new()
        .name(&NodeName::new(name).context("node name")?)
        .config(&ipc.iceoryx2_config())
        .create::<ipc::Service>()
        .context("cannot create an iceoryx2 node")
}

/// Ctrl-C or SIGTERM arrived while waiting on a [`pacing_node`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Interrupted;

impl fmt::Display for Interrupted {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("interrupted by a signal")
    }
}

impl std::error::Error for Interrupted {}

/// A fixed-rate schedule: slot `k` is at `start + k / rate`. Sleeping until a slot
/// (instead of sleeping one period after each send) keeps the rate from drifting.
#[derive(Debug, Clone, Copy)]
pub struct Pacer {
    start: Instant,
    period: Duration,
}

impl Pacer {
    /// Slot 0 is now. `rate_hz` must be positive and finite.
    pub fn new(rate_hz: f64) -> anyhow::Result<Self> {
        anyhow::ensure!(
            rate_hz > 0.0 && rate_hz.is_finite(),
            "rate must be > 0 Hz, got {rate_hz}"
        );
        Ok(Self {
            start: Instant::now(),
            period: Duration::from_secs_f64(1.0 / rate_hz),
        })
    }

    /// Sleeps on `node` until slot `k` (at once if it is past).
    pub fn wait_for_slot(&self, node: &Node<ipc::Service>, k: u64) -> Result<(), Interrupted> {
        let at = self.start + self.period.mul_f64(k as f64);
        node.wait(at.saturating_duration_since(Instant::now()))
            .map_err(|_| Interrupted)
    }

    /// Time since slot 0.
    pub fn elapsed(&self) -> Duration {
        self.start.elapsed()
    }
}

/// Waits until every publisher in `publishers` has a subscriber (ghnetd), sleeping on
/// `node`. ghnet services keep no history, so a sample sent earlier is never
/// answered. Fails after `timeout`, on Ctrl-C, or when `gave_up()` says so (e.g. an
/// in-process daemon thread ended).
pub fn wait_for_subscriber(
    node: &Node<ipc::Service>,
    publishers: &[&VelocityPublisher],
    timeout: Duration,
    mut gave_up: impl FnMut() -> bool,
) -> anyhow::Result<()> {
    let t0 = Instant::now();
    while let Some(p) = publishers.iter().find(|p| p.subscriber_count() == 0) {
        anyhow::ensure!(!gave_up(), "gave up waiting for ghnetd");
        anyhow::ensure!(
            t0.elapsed() < timeout,
            "nobody subscribed to {} within {timeout:?}: is ghnetd running, with the same --prefix?",
            p.service_name()
        );
        node.wait(Duration::from_millis(10))
            .map_err(|_| Interrupted)?;
    }
    Ok(())
}

/// Log lines (ghnetd's, in the demo) to stderr at `info` or `RUST_LOG`, so stdout
/// stays a clean table; iceoryx2's own logger only for errors (it warns about a
/// missing config file otherwise).
pub fn log_to_stderr() {
    use std::io::IsTerminal;
    let filter = tracing_subscriber::EnvFilter::try_from_default_env();
    tracing_subscriber::fmt()
        .with_env_filter(filter.unwrap_or_else(|_| "info".into()))
        .with_writer(std::io::stderr)
        .with_ansi(std::io::stderr().is_terminal())
        .init();
    iceoryx2::prelude::set_log_level_from_env_or(iceoryx2::prelude::LogLevel::Error);
}

/// Nanoseconds since the Unix epoch (`CLOCK_REALTIME`), the unit of
/// [`VelocitySample::timestamp_ns`].
pub fn now_ns() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as u64)
}

/// Time from a sample's timestamp to now: the end-to-end latency of its heading.
pub fn latency_since(timestamp_ns: u64) -> Duration {
    Duration::from_nanos(now_ns().saturating_sub(timestamp_ns))
}

/// A simulated vehicle: one track of the realistic receiver simulation (stops, slow
/// manoeuvres, turns, straight runs, receiver noise), replayed in order and from the
/// start again when it runs out.
#[derive(Debug, Clone)]
pub struct Vehicle {
    track: Vec<Sample>,
    next: usize,
}

impl Vehicle {
    /// Longest track simulated; longer runs replay it.
    const MAX_TRACK_S: f64 = 600.0;

    /// A vehicle sampled at `rate_hz` for `seconds` (at most ten minutes, then it
    /// repeats); `seed` picks the trajectory and receiver.
    pub fn new(seed: u64, rate_hz: f64, seconds: f64) -> Self {
        let seconds = seconds.clamp(1.0, Self::MAX_TRACK_S);
        let rate = rate_hz.round().clamp(1.0, 1000.0) as u32;
        let params = RealisticParams {
            samples: (seconds * rate as f64).ceil() as usize,
            track_min_s: seconds,
            track_max_s: seconds,
            rate_min_hz: rate,
            rate_max_hz: rate,
            ..RealisticParams::default()
        };
        let samples = simulate_realistic(&params, seed);
        // One track is asked for; keep only the first in case the simulator splits.
        let first = samples.first().map_or(0, |s| s.track);
        let track: Vec<Sample> = samples.into_iter().filter(|s| s.track == first).collect();
        assert!(!track.is_empty(), "the simulation produced no samples");
        Self { track, next: 0 }
    }

    /// The next epoch as a wire sample with the given sequence number and timestamp,
    /// flagged [`flags::SIMULATED`].
    pub fn next_sample(&mut self, seq: u64, timestamp_ns: u64) -> VelocitySample {
        let s = &self.track[self.next % self.track.len()];
        self.next += 1;
        VelocitySample {
            speed_accuracy: s.speed_acc,
            flags: flags::SIMULATED,
            ..VelocitySample::new(timestamp_ns, seq, s.v_north, s.v_east, s.v_down)
        }
    }
}

/// A simulated car for the demo: a stretch of a car track of `ghnet_lab::drive` that
/// drives, slows down, stops and backs up (the moment single-epoch heading gets wrong
/// by 180°), with the truth beside every epoch.
#[derive(Debug, Clone)]
pub struct CarDrive {
    /// The epochs, `t_s` from 0.
    pub samples: Vec<DriveSample>,
    /// The receiver's output rate, Hz.
    pub rate_hz: u32,
}

impl CarDrive {
    /// Up to `seconds` of car at `rate_hz`, ending `seconds / 3` after the first time
    /// the car backs up after having driven faster than 4 m/s, and starting at most 8 s
    /// before the last fast epoch before it (so the stretch shows driving, the stop, the reversal
    /// and what follows). `seed` picks the first car tried; the
    /// next seeds are tried until one has such a moment.
    pub fn new(seed: u64, rate_hz: u32, seconds: f64) -> Self {
        let params = DriveParams {
            rates_hz: vec![rate_hz.max(1)],
            gaps_per_min: 0.0,
            ..DriveParams::default()
        };
        for s in seed..seed + 1_000 {
            let mut rng = ChaCha8Rng::seed_from_u64(s);
            let (_, rate_hz, track) = simulate_track(&params, Platform::Car, 900.0, &mut rng);
            if let Some(samples) = Self::stretch(&track, seconds) {
                return Self { samples, rate_hz };
            }
        }
        panic!("no car reversed after driving in 1000 simulated tracks");
    }

    fn stretch(track: &[DriveSample], seconds: f64) -> Option<Vec<DriveSample>> {
        let fast = track.iter().position(|s| s.true_speed > 4.0)?;
        let back = fast + track[fast..].iter().position(|s| s.reversing)?;
        let end_t = track[back].t_s + seconds / 3.0;
        // Start while the car drives, not in a long stand before it.
        let last_fast = track[..back].iter().rposition(|s| s.true_speed > 4.0)?;
        let start_t = (end_t - seconds).max(track[last_fast].t_s - 8.0).max(0.0);
        let stretch: Vec<DriveSample> = track
            .iter()
            .filter(|s| s.t_s >= start_t && s.t_s < end_t)
            .map(|s| DriveSample {
                t_s: s.t_s - start_t,
                ..*s
            })
            .collect();
        (!stretch.is_empty()).then_some(stretch)
    }
}

/// A private iceoryx2 namespace for one run (the demo's `--isolated`), so the demo
/// never meets a running ghnetd: its own `/dev/shm` file prefix and root directory,
/// both named after this process, removed on drop. Built on the client's public
/// [`IpcConfig::isolated`]; ghnetd takes the same two values as
/// `ipc.iceoryx2_global_prefix` and `ipc.iceoryx2_root_path`.
pub struct PrivateNamespace {
    /// The iceoryx2 global prefix (file-name prefix in `/dev/shm`).
    pub global_prefix: String,
    /// The iceoryx2 root directory (node and service records).
    pub root_path: std::path::PathBuf,
}

impl PrivateNamespace {
    /// A namespace named `name` plus this process's id.
    pub fn new(name: &str) -> Self {
        let pid = std::process::id();
        Self {
            global_prefix: format!("{name}{pid}_"),
            root_path: std::env::temp_dir().join(format!("ghnet-{name}-{pid}")),
        }
    }

    /// The client side: the default service prefix in this namespace.
    pub fn ipc(&self) -> anyhow::Result<IpcConfig> {
        Ok(IpcConfig::isolated(&self.global_prefix, &self.root_path)?)
    }
}

impl Drop for PrivateNamespace {
    fn drop(&mut self) {
        // iceoryx2 keeps a small management segment per prefix on purpose.
        let _ = std::fs::remove_dir_all(&self.root_path);
        for entry in std::fs::read_dir("/dev/shm")
            .into_iter()
            .flatten()
            .flatten()
        {
            if entry
                .file_name()
                .to_string_lossy()
                .starts_with(&self.global_prefix)
            {
                let _ = std::fs::remove_file(entry.path());
            }
        }
    }
}

/// The live heading table of `subscriber`, `zenoh_subscriber` and `demo`: one row per
/// heading, one [`Column`](table::Column) per quantity. To show another estimate beside
/// ghnet's (plain atan2 is there already; a Kalman filter, say), add a column.
pub mod table {
    use super::*;

    /// One column: its title, its width, and what a heading shows in it.
    pub struct Column {
        /// Title, right-aligned over the cells.
        pub title: &'static str,
        /// Characters.
        pub width: usize,
        /// The cell of heading `h`, received `latency` after its sample's timestamp.
        pub cell: fn(h: &HeadingEstimate, latency: Duration) -> String,
    }

    /// The columns, left to right.
    pub const COLUMNS: &[Column] = &[
        column("seq", 10, |h, _| h.seq.to_string()),
        column("heading°", 8, |h, _| format!("{:.2}", h.heading_deg)),
        column("σ°", 6, |h, _| format!("{:.2}", h.heading_std_deg)),
        column("atan2°", 7, |h, _| format!("{:.2}", h.atan2_deg)),
        column("speed m/s", 10, |h, _| format!("{:.3}", h.speed)),
        column("status", 12, |h, _| status(h)),
        column("latency", 9, |_, l| format!("{l:.1?}")),
    ];

    const fn column(
        title: &'static str,
        width: usize,
        cell: fn(&HeadingEstimate, Duration) -> String,
    ) -> Column {
        Column { title, width, cell }
    }

    /// Column titles, aligned with [`row`].
    pub fn header() -> String {
        line(COLUMNS.iter().map(|c| c.title.to_owned()))
    }

    /// One heading as a table row; `latency` is from its sample's timestamp to receipt.
    pub fn row(h: &HeadingEstimate, latency: Duration) -> String {
        line(COLUMNS.iter().map(|c| (c.cell)(h, latency)))
    }

    fn line(cells: impl Iterator<Item = String>) -> String {
        let padded: Vec<String> = COLUMNS
            .iter()
            .zip(cells)
            .map(|(c, text)| format!("{text:>width$}", width = c.width))
            .collect();
        padded.join("  ")
    }

    fn status(h: &HeadingEstimate) -> String {
        match h.heading_status() {
            Some(s) => format!("{s:?}"),
            None => format!("unknown({})", h.status),
        }
    }
}

/// Prints the heading table of one source from a thread of its own until stopped.
#[derive(Debug)]
pub struct TablePrinter {
    stop: Arc<AtomicBool>,
    rows: Arc<AtomicU64>,
    thread: JoinHandle<anyhow::Result<()>>,
}

impl TablePrinter {
    /// Starts the thread and returns once its [`HeadingSubscriber`] exists, so no
    /// heading published from now on is missed.
    pub fn start(ipc: &IpcConfig, source: &str) -> anyhow::Result<Self> {
        let (stop, rows) = (
            Arc::new(AtomicBool::new(false)),
            Arc::new(AtomicU64::new(0)),
        );
        let (ready_tx, ready_rx) = mpsc::channel();
        let thread = std::thread::spawn({
            let (ipc, source) = (ipc.clone(), source.to_owned());
            let (stop, rows) = (stop.clone(), rows.clone());
            // iceoryx2 ports are !Send: the subscriber is made on the thread using it.
            move || -> anyhow::Result<()> {
                let headings = HeadingSubscriber::new(&ipc, &source)?;
                ready_tx.send(())?;
                while !stop.load(Relaxed) {
                    match headings.recv_timeout(Duration::from_millis(100)) {
                        Ok(Some(h)) => {
                            println!("{}", table::row(&h, latency_since(h.timestamp_ns)));
                            rows.fetch_add(1, Relaxed);
                        }
                        // A signal is for the main thread to act on.
                        Ok(None) | Err(RecvError::Interrupted) => {}
                        Err(e) => return Err(e.into()),
                    }
                }
                Ok(())
            }
        });
        if ready_rx.recv().is_err() {
            return Err(thread.join().expect("table thread panicked").unwrap_err());
        }
        Ok(Self { stop, rows, thread })
    }

    /// Headings printed so far.
    pub fn rows(&self) -> u64 {
        self.rows.load(Relaxed)
    }

    /// Waits up to `grace` until `expected` rows are printed, then stops the thread;
    /// returns the number of rows.
    pub fn finish(self, expected: u64, grace: Duration) -> anyhow::Result<u64> {
        let t0 = Instant::now();
        while self.rows() < expected && t0.elapsed() < grace {
            std::thread::sleep(Duration::from_millis(10));
        }
        self.stop.store(true, Relaxed);
        let rows = self.rows.clone();
        self.thread.join().expect("table thread panicked")?;
        Ok(rows.load(Relaxed))
    }
}
