//! The soak run behind the `soak` tool and the CI soak test: N sources at a fixed rate
//! against a real ghnetd; every sequence number must get exactly one heading on
//! iceoryx2 *and* on Zenoh, with the same value on both, while ghnetd's resident
//! memory stays flat.
//!
//! # Layout
//!
//! - [`Options`] → [`run`] → [`Report`]: the run itself, printing a progress line every
//!   [`Options::report_every`]. [`Report::failures`] is the verdict (empty = pass).
//!   [`Options::daemon`] is how the tool and the test start a ghnetd for it.
//! - [`book`]: the exactly-once bookkeeping ([`Book`]) shared by the two receivers,
//!   and [`Tally`]. Memory is one byte per (source, seq, transport) plus the values
//!   seen on one transport and not yet on the other, so an hour at 1000 samples/s
//!   stays near 10 MB.
//! - `receive`: one iceoryx2 thread waiting on every heading listener with one
//!   `WaitSet`, and one Zenoh callback subscriber on `<prefix>/*/heading`.
//! - [`report`]: [`Report`], [`RssSeries`] (`VmRSS` of ghnetd once a second; growth is
//!   judged after a warm-up).
//!
//! Threads: the caller's (pacing, all publishers on one node, RSS sampling, progress),
//! one iceoryx2 collector and Zenoh's runtime.

pub mod book;
mod receive;
pub mod report;

use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use anyhow::Context;
use ghnet_client::{termination_requested, IpcConfig, VelocityPublisher, VelocitySample};
use ghnet_testkit::{now_ns, poll_until, GhnetdBuilder, TestNamespace};
use iceoryx2::prelude::*;

use book::{lock, SharedBook};
pub use book::{Book, Tally, Transport};
use receive::Receivers;
pub use report::{Report, RssSeries, RssWindow, SourceReport};

/// What to run and where ghnetd is.
#[derive(Debug, Clone)]
pub struct Options {
    /// Service prefix and iceoryx2 namespace shared with ghnetd.
    pub ipc: IpcConfig,
    /// Source names, `<tag>-<i>`: unique per run so soaks never cross real sources.
    pub tag: String,
    /// Number of sources.
    pub sources: usize,
    /// Samples per second per source.
    pub rate_hz: f64,
    /// How long to publish.
    pub duration: Duration,
    /// ghnetd's Zenoh listen endpoint to connect to; `None` checks iceoryx2 only
    /// (for a daemon with `zenoh.enabled = false`).
    pub zenoh_connect: Option<String>,
    /// ghnetd's process id, for `VmRSS`; `None` skips the memory check.
    pub daemon_pid: Option<u32>,
    /// Resident-memory samples in the first `warmup` are not judged (allocators,
    /// Zenoh and iceoryx2 settle in); `None` = 20% of the run, at least 10 s.
    pub warmup: Option<Duration>,
    /// Fail when RSS grows by this much or more after the warm-up, kB.
    pub rss_limit_kb: u64,
    /// A progress line every so often.
    pub report_every: Duration,
    /// After the last sample, how long to wait for the last headings.
    pub drain_timeout: Duration,
    /// How long to wait for ghnetd (subscribers, Zenoh link) before the first sample.
    pub patience: Duration,
}

impl Options {
    /// Defaults for everything but where ghnetd is: 100 sources × 10 Hz × 60 s,
    /// 1024 kB RSS limit, progress every 10 s, 10 s drain, 30 s patience.
    pub fn new(ipc: IpcConfig, tag: &str) -> Self {
        Self {
            ipc,
            tag: tag.to_owned(),
            sources: 100,
            rate_hz: 10.0,
            duration: Duration::from_secs(60),
            zenoh_connect: None,
            daemon_pid: None,
            warmup: None,
            rss_limit_kb: 1024,
            report_every: Duration::from_secs(10),
            drain_timeout: Duration::from_secs(10),
            patience: Duration::from_secs(30),
        }
    }

    /// The warm-up actually used (see [`Options::warmup`]).
    pub fn effective_warmup(&self) -> Duration {
        self.warmup
            .unwrap_or_else(|| (self.duration / 5).max(Duration::from_secs(10)))
    }

    /// The source names.
    pub fn source_names(&self) -> Vec<String> {
        (0..self.sources)
            .map(|i| format!("{}-{i}", self.tag))
            .collect()
    }

    /// The warm-up source, `<tag>-warmup`: published on before the soak until its
    /// heading arrives over Zenoh. A subscriber's declaration reaches ghnetd some time
    /// after even a query round trip (measured: the first ~300 ms of headings were
    /// missing), and the soak's own seqs must all count. ghnetd must serve it too.
    pub fn warmup_source(&self) -> String {
        format!("{}-warmup", self.tag)
    }

    /// Every source ghnetd must serve: [`source_names`](Self::source_names) and the
    /// [`warmup_source`](Self::warmup_source).
    pub fn daemon_sources(&self) -> Vec<String> {
        let mut v = self.source_names();
        v.push(self.warmup_source());
        v
    }

    /// Samples per source.
    pub fn samples_per_source(&self) -> u64 {
        (self.duration.as_secs_f64() * self.rate_hz).round() as u64
    }

    /// A ghnetd for this soak in `ns`: serves exactly [`daemon_sources`](Self::daemon_sources)
    /// (static, no discovery) on the prefix of [`ipc`](Self::ipc). The caller adds the
    /// rest (log file, model) and sets `ipc`, `zenoh_connect` and `daemon_pid` from it.
    pub fn daemon<'a>(&self, ns: &'a TestNamespace) -> GhnetdBuilder<'a> {
        let sources = self.daemon_sources();
        let max = sources.len().to_string();
        let builder = ghnet_testkit::Ghnetd::builder(ns)
            .prefix(self.ipc.prefix())
            .discovery(false)
            .arg("--max-sources")
            .arg(max);
        sources.iter().fold(builder, |b, s| b.source(s))
    }

    /// The samples per source, or why the options cannot run.
    fn check(&self) -> anyhow::Result<u64> {
        anyhow::ensure!(self.sources > 0, "need at least one source");
        anyhow::ensure!(
            self.rate_hz > 0.0 && self.rate_hz.is_finite(),
            "rate must be > 0 Hz, got {}",
            self.rate_hz
        );
        let planned = self.samples_per_source();
        anyhow::ensure!(planned > 0, "duration × rate is less than one sample");
        anyhow::ensure!(
            planned.saturating_mul(self.sources as u64) <= 1 << 30,
            "sources × samples is over 2^30: run fewer or shorter"
        );
        Ok(planned)
    }
}

/// Runs the soak against a ghnetd that already serves (or discovers) `opts`' sources
/// on `opts.ipc`. Prints progress to stdout. Errors only when the run could not
/// happen (no daemon, ghnetd died, bad options); loss and growth are in the report.
pub fn run(opts: &Options) -> anyhow::Result<Report> {
    let planned = opts.check()?;
    let names = opts.source_names();
    let book: SharedBook = Arc::new(Mutex::new(Book::new(names.len(), planned)));
    // Receivers first, so no heading is published before both listen.
    let receivers = Receivers::start(opts, &names, &book)?;
    let node = NodeBuilder::new()
        .config(&opts.ipc.iceoryx2_config())
        .create::<ipc::Service>()
        .context("cannot create an iceoryx2 node")?;
    let pubs: Vec<VelocityPublisher> = (names.iter())
        .map(|n| VelocityPublisher::with_node(&node, &opts.ipc, n))
        .collect::<Result<_, _>>()?;
    let warmup = VelocityPublisher::with_node(&node, &opts.ipc, &opts.warmup_source())?;
    connect(opts, &pubs, &warmup, &receivers)?;
    println!(
        "soak: {} sources × {planned} samples at {} Hz ({:?}), prefix {}, zenoh {}, ghnetd pid {}",
        names.len(),
        opts.rate_hz,
        opts.duration,
        opts.ipc.prefix(),
        opts.zenoh_connect.as_deref().unwrap_or("not checked"),
        opts.daemon_pid
            .map_or("unknown (no RSS check)".to_owned(), |p| p.to_string()),
    );
    let mut run = publish(opts, &pubs, &book)?;
    drain(opts, &mut run, names.len() as u64, &book);
    receivers.stop()?;
    let report = Report::new(opts, &names, &lock(&book), run);
    Ok(report)
}

/// Waits until ghnetd serves every publisher and, with Zenoh, until a heading of the
/// warm-up source arrived over Zenoh (so ghnetd knows the Zenoh subscriber).
fn connect(
    opts: &Options,
    pubs: &[VelocityPublisher],
    warmup: &VelocityPublisher,
    receivers: &Receivers,
) -> anyhow::Result<()> {
    let poll = Duration::from_millis(20);
    let daemon_gone = || {
        opts.daemon_pid
            .is_some_and(|p| RssSeries::read(p).is_none())
    };
    let served = || {
        pubs.iter()
            .chain([warmup])
            .all(|p| p.subscriber_count() > 0)
    };
    let what = "ghnetd serving every source (is it running, with the same prefix?)";
    poll_until(what, opts.patience, poll, || served() || daemon_gone())?;
    let (mut seq, mut failed) = (0, None);
    let what = format!("heading of {} over Zenoh", opts.warmup_source());
    poll_until(&what, opts.patience, poll, || {
        seq += 1;
        failed = warmup.send(sample(0, seq)).err();
        receivers.warmed_up() || daemon_gone() || failed.is_some()
    })?;
    if let Some(e) = failed {
        return Err(e.into());
    }
    anyhow::ensure!(!daemon_gone(), "ghnetd (pid {:?}) is gone", opts.daemon_pid);
    Ok(())
}

/// What publishing did: samples sent per source, ghnetd's memory, whether Ctrl-C
/// stopped it early.
pub(crate) struct Published {
    pub(crate) sent: u64,
    pub(crate) rss: RssSeries,
    pub(crate) interrupted: bool,
    started: Instant,
    progress: Progress,
}

/// Sends one sample per source per slot (`1 / rate_hz`), samples ghnetd's memory once
/// a second and prints progress, until `planned` or Ctrl-C.
fn publish(
    opts: &Options,
    pubs: &[VelocityPublisher],
    book: &SharedBook,
) -> anyhow::Result<Published> {
    let planned = opts.samples_per_source();
    let period = Duration::from_secs_f64(1.0 / opts.rate_hz);
    let mut run = Published {
        sent: 0,
        rss: RssSeries::default(),
        interrupted: false,
        started: Instant::now(),
        progress: Progress::new(opts.report_every),
    };
    let mut next_rss = 0.0;
    while run.sent < planned {
        for (i, p) in pubs.iter().enumerate() {
            p.send(sample(i, run.sent))?;
        }
        run.sent += 1;
        let t = run.started.elapsed().as_secs_f64();
        if let (Some(pid), true) = (opts.daemon_pid, t >= next_rss) {
            let kb = RssSeries::read(pid)
                .with_context(|| format!("ghnetd (pid {pid}) is gone after {t:.1} s"))?;
            run.rss.samples.push((t, kb));
            next_rss = t.floor() + 1.0;
        }
        let answers = run.sent * pubs.len() as u64;
        run.progress.maybe_print(t, answers, book, &run.rss, false);
        // Until slot `sent`, not one period after this send: the rate does not drift.
        let slot = run.started + period.mul_f64(run.sent as f64);
        std::thread::sleep(slot.saturating_duration_since(Instant::now()));
        if termination_requested() {
            println!(
                "interrupted: stopping after {} samples per source",
                run.sent
            );
            run.interrupted = true;
            break;
        }
    }
    Ok(run)
}

/// Waits for the last headings: until every sent seq arrived on each checked
/// transport, or `drain_timeout`; then a last memory sample and progress line.
fn drain(opts: &Options, run: &mut Published, sources: u64, book: &SharedBook) {
    let expected = run.sent * sources;
    let zenoh = opts.zenoh_connect.is_some();
    let all_in = || {
        let b = lock(book);
        b.unique(Transport::Iceoryx2) >= expected
            && (!zenoh || b.unique(Transport::Zenoh) >= expected)
    };
    let _ = poll_until("", opts.drain_timeout, Duration::from_millis(10), all_in);
    // A late duplicate would arrive right behind; give it a moment.
    std::thread::sleep(Duration::from_millis(500));
    let t = run.started.elapsed().as_secs_f64();
    if let Some(kb) = opts.daemon_pid.and_then(RssSeries::read) {
        run.rss.samples.push((t, kb));
    }
    run.progress.maybe_print(t, expected, book, &run.rss, true);
}

/// Sample `seq` of source `i`: speed and direction sweep through stationary, low-speed
/// and normal cases, different per source and seq, so a heading delivered for the
/// wrong sample or source differs from its twin.
fn sample(i: usize, seq: u64) -> VelocitySample {
    let speed = 0.02 + (seq % 50) as f32 * 0.3;
    let angle = ((seq * 7 + i as u64 * 13) % 360) as f32;
    let (s, c) = angle.to_radians().sin_cos();
    VelocitySample::new(now_ns(), seq, speed * c, speed * s, 0.0)
}

/// Progress lines: answers so far and the RSS of the interval.
struct Progress {
    every: f64,
    next: f64,
    rss_from: usize,
}

impl Progress {
    fn new(every: Duration) -> Self {
        let every = every.as_secs_f64().max(1.0);
        Self {
            every,
            next: every,
            rss_from: 0,
        }
    }

    fn maybe_print(&mut self, t: f64, sent: u64, book: &SharedBook, rss: &RssSeries, last: bool) {
        if t < self.next && !last {
            return;
        }
        self.next += self.every * ((t - self.next) / self.every).floor().max(0.0) + self.every;
        let (iox, zen, stale) = {
            let b = lock(book);
            (
                b.unique(Transport::Iceoryx2),
                b.unique(Transport::Zenoh),
                b.stale,
            )
        };
        let mut line = format!(
            "[{t:>6.0} s] sent {sent:>9}  iceoryx2 {iox:>9}  zenoh {zen:>9}  stale {stale}"
        );
        if let Some(w) = RssWindow::of(rss.samples[self.rss_from..].iter().map(|&(_, kb)| kb)) {
            line += &format!(
                "  ghnetd RSS kB first {} last {} min {} max {}",
                w.first, w.last, w.min, w.max
            );
        }
        self.rss_from = rss.samples.len();
        println!("{line}");
    }
}
