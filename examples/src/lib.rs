//! Shared pieces of the ghnet examples, so that each example in `src/bin/` shows only
//! its one idea. See `examples/README.md` for how to run them.
//!
//! # Layout
//!
//! - [`CommonArgs`] — `--prefix`, flattened into every example; gives the
//!   [`IpcConfig`] all ghnet helpers take. [`ZenohArgs`] — `--connect` /
//!   `--zenoh-config` of the Zenoh examples.
//! - [`pacing_node`], [`Pacer`], [`wait_for_subscriber`] — an iceoryx2 node whose
//!   `wait` paces a loop and reports Ctrl-C / SIGTERM (the iceoryx2 idiom
//!   `while node.wait(cycle).is_ok()`), a fixed-rate schedule on it, and the wait for
//!   the daemon before the first sample.
//! - [`Vehicle`] — a simulated vehicle: one track of
//!   `ghnet_lab::sim::simulate_realistic`, replayed as [`VelocitySample`]s.
//! - [`now_ns`] — wall-clock timestamps in the unit the wire wants.
//! - [`table`] — the live heading table of `subscriber` and `demo`;
//!   [`TablePrinter`] prints it from a thread of its own.
//! - [`Collector`], [`Tally`], [`Percentiles`] — the bookkeeping of `soak`.
//! - [`SpawnedDaemon`] — a `ghnetd` child process that is stopped and reaped.
//! - [`soak`] — the soak run (`soak` binary and the CI soak test): exactly-once on
//!   iceoryx2 and Zenoh, ghnetd's resident memory.

#![warn(missing_docs)]

pub mod soak;

use std::fmt;
use std::path::Path;
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering::Relaxed};
use std::sync::{mpsc, Arc};
use std::thread::JoinHandle;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use anyhow::Context;
use ghnet_client::{
    flags, HeadingEstimate, HeadingStatus, HeadingSubscriber, IpcConfig, RecvError,
    VelocityPublisher, VelocitySample,
};
use ghnet_lab::sim::{simulate_realistic, RealisticParams, Sample};
use iceoryx2::prelude::*;

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

/// Where the Zenoh examples find ghnetd: flattened into `zenoh_echo` and `zenoh_stats`.
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

/// The live heading table printed by `subscriber` and `demo`.
pub mod table {
    use super::*;

    /// Column titles, aligned with [`row`].
    pub const HEADER: &str =
        "       seq  heading°      σ°   atan2°   speed m/s  status        latency";

    /// One heading as a table row; `latency` is from its sample's timestamp to receipt.
    pub fn row(h: &HeadingEstimate, latency: Duration) -> String {
        let status = match h.heading_status() {
            Some(s) => format!("{s:?}"),
            None => format!("unknown({})", h.status),
        };
        format!(
            "{:>10}  {:>8.2}  {:>6.2}  {:>7.2}  {:>10.3}  {:<12}  {:>9.1?}",
            h.seq, h.heading_deg, h.heading_std_deg, h.atan2_deg, h.speed, status, latency
        )
    }

    /// Whether a heading is usable as a heading (status `Ok` or `LowSpeed`).
    pub fn has_heading(h: &HeadingEstimate) -> bool {
        matches!(
            h.heading_status(),
            Some(HeadingStatus::Ok | HeadingStatus::LowSpeed)
        )
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

/// One answer as `soak` records it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Answer {
    /// Echoed sequence number.
    pub seq: u64,
    /// Sample timestamp → receipt, ns.
    pub latency_ns: u64,
}

/// Collects every heading of one source on a thread of its own.
#[derive(Debug)]
pub struct Collector {
    thread: JoinHandle<anyhow::Result<Vec<Answer>>>,
}

impl Collector {
    /// Starts collecting; returns once the subscriber exists. The thread ends when
    /// nothing arrived for `idle` (after a first answer; before it, it waits
    /// `startup`), or `idle / 4` after the answer to `expected - 1` (so a late
    /// duplicate is still seen).
    pub fn start(
        ipc: &IpcConfig,
        source: &str,
        expected: u64,
        startup: Duration,
        idle: Duration,
    ) -> anyhow::Result<Self> {
        let (ready_tx, ready_rx) = mpsc::channel();
        let (ipc, source) = (ipc.clone(), source.to_owned());
        let thread = std::thread::spawn(move || -> anyhow::Result<Vec<Answer>> {
            let headings = HeadingSubscriber::new(&ipc, &source)?;
            ready_tx.send(())?;
            let mut got = Vec::with_capacity(expected as usize);
            let mut timeout = startup;
            while let Some(h) = headings.recv_timeout(timeout)? {
                let latency_ns = latency_since(h.timestamp_ns).as_nanos() as u64;
                got.push(Answer {
                    seq: h.seq,
                    latency_ns,
                });
                let done = h.seq + 1 >= expected && got.len() as u64 >= expected;
                timeout = if done { idle / 4 } else { idle };
            }
            Ok(got)
        });
        if ready_rx.recv().is_err() {
            return Err(thread.join().expect("collector panicked").unwrap_err());
        }
        Ok(Self { thread })
    }

    /// Waits for the thread to end; the answers in arrival order.
    pub fn join(self) -> anyhow::Result<Vec<Answer>> {
        self.thread.join().expect("collector panicked")
    }
}

/// Nearest-rank latency percentiles.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Percentiles {
    /// Number of values.
    pub count: usize,
    /// Median.
    pub p50: Duration,
    /// 99th percentile.
    pub p99: Duration,
    /// 99.9th percentile.
    pub p999: Duration,
    /// Largest value.
    pub max: Duration,
}

impl Percentiles {
    /// Percentiles of `values_ns`; `None` when empty.
    ///
    /// ```
    /// # use ghnet_examples::Percentiles;
    /// let p = Percentiles::of((1..=1000).collect()).unwrap();
    /// assert_eq!(p.p50.as_nanos(), 500);
    /// assert_eq!(p.p99.as_nanos(), 990);
    /// assert_eq!(p.p999.as_nanos(), 999);
    /// assert_eq!(p.max.as_nanos(), 1000);
    /// ```
    pub fn of(mut values_ns: Vec<u64>) -> Option<Self> {
        if values_ns.is_empty() {
            return None;
        }
        values_ns.sort_unstable();
        let n = values_ns.len();
        let rank = |q: f64| {
            let i = ((q * n as f64).ceil() as usize).clamp(1, n) - 1;
            Duration::from_nanos(values_ns[i])
        };
        Some(Self {
            count: n,
            p50: rank(0.50),
            p99: rank(0.99),
            p999: rank(0.999),
            max: rank(1.0),
        })
    }
}

impl fmt::Display for Percentiles {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "p50 {:.1?}  p99 {:.1?}  p99.9 {:.1?}  max {:.1?}  (n={})",
            self.p50, self.p99, self.p999, self.max, self.count
        )
    }
}

/// A `ghnetd` child process. [`stop`](Self::stop) sends SIGTERM and reaps it; drop
/// kills and reaps it (an unreaped zombie keeps its iceoryx2 liveness lock).
#[derive(Debug)]
pub struct SpawnedDaemon {
    child: Option<Child>,
}

impl SpawnedDaemon {
    /// Starts `binary args…` with stdin closed and its log (stderr) passed through.
    pub fn spawn(binary: &Path, args: &[String]) -> anyhow::Result<Self> {
        let child = Command::new(binary)
            .args(args)
            .stdin(Stdio::null())
            .spawn()
            .with_context(|| format!("cannot start {}", binary.display()))?;
        Ok(Self { child: Some(child) })
    }

    /// `ghnetd --service-prefix PREFIX --discovery false --source S…`: serves exactly
    /// `sources` from the start.
    pub fn ghnetd(binary: &Path, prefix: &str, sources: &[String]) -> anyhow::Result<Self> {
        let mut args = vec!["--service-prefix".into(), prefix.into()];
        args.extend(["--discovery".into(), "false".into()]);
        for s in sources {
            args.extend(["--source".into(), s.clone()]);
        }
        Self::spawn(binary, &args)
    }

    /// Whether the process has exited already (e.g. bad config).
    pub fn has_exited(&mut self) -> bool {
        let child = self.child.as_mut().expect("child present until stop/drop");
        !matches!(child.try_wait(), Ok(None))
    }

    /// SIGTERM, then waits up to `grace` for the exit (after that it is killed and
    /// reaped on drop, and this returns an error).
    pub fn stop(mut self, grace: Duration) -> anyhow::Result<ExitStatus> {
        let child = self.child.as_mut().expect("child present until stop/drop");
        // SAFETY: kill(2) on our own child, not yet reaped, so its pid is not reused.
        unsafe { libc::kill(child.id() as libc::pid_t, libc::SIGTERM) };
        let t0 = Instant::now();
        while t0.elapsed() < grace {
            if let Some(status) = child.try_wait()? {
                self.child = None;
                return Ok(status);
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        anyhow::bail!("ghnetd ignored SIGTERM for {grace:?} and was killed")
    }
}

impl Drop for SpawnedDaemon {
    fn drop(&mut self) {
        if let Some(mut child) = self.child.take() {
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}

/// Exactly-once accounting of the answers to sequence numbers `0..sent`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Tally {
    /// Sequence numbers in `0..sent` that got no answer.
    pub lost: u64,
    /// Extra answers to a sequence number that was already answered.
    pub duplicates: u64,
    /// Answers whose sequence number was never sent (crossed sources, corruption).
    pub unexpected: u64,
}

impl Tally {
    /// Counts the answers `seqs` against the samples `0..sent`.
    ///
    /// ```
    /// # use ghnet_examples::Tally;
    /// let t = Tally::of(4, [0, 1, 1, 3, 9]);
    /// assert_eq!((t.lost, t.duplicates, t.unexpected), (1, 1, 1));
    /// assert!(!t.is_exactly_once());
    /// assert!(Tally::of(3, [2, 0, 1]).is_exactly_once());
    /// ```
    pub fn of(sent: u64, seqs: impl IntoIterator<Item = u64>) -> Self {
        let mut seen = vec![0u32; sent as usize];
        let mut t = Tally::default();
        for seq in seqs {
            match seen.get_mut(seq as usize) {
                Some(c) if seq < sent => {
                    t.duplicates += u64::from(*c > 0);
                    *c += 1;
                }
                _ => t.unexpected += 1,
            }
        }
        t.lost = seen.iter().filter(|&&c| c == 0).count() as u64;
        t
    }

    /// No loss, no duplicate, nothing unexpected.
    pub fn is_exactly_once(&self) -> bool {
        *self == Tally::default()
    }
}

impl fmt::Display for Tally {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "lost {}  duplicates {}  unexpected {}",
            self.lost, self.duplicates, self.unexpected
        )
    }
}
