//! The soak run behind `soak` and the CI soak test: N sources at a fixed rate against a
//! real ghnetd; every sequence number must get exactly one heading on iceoryx2 *and* on
//! Zenoh, with the same value on both, while ghnetd's resident memory stays flat.
//!
//! # Pieces
//!
//! - [`Options`] → [`run`] → [`Report`]: the run itself, printing a progress line every
//!   [`Options::report_every`]. [`Report::failures`] is the verdict (empty = pass).
//! - [`Book`]: the exactly-once bookkeeping shared by the two receivers — one
//!   iceoryx2 thread waiting on every heading listener with one `WaitSet`, and one
//!   Zenoh callback subscriber on `<prefix>/*/heading`. Memory is one byte per
//!   (source, seq, transport) plus the values seen on one transport and not yet on
//!   the other, so an hour at 1000 samples/s stays near 10 MB.
//! - [`RssSeries`]: `VmRSS` of ghnetd once a second; growth is judged after a warm-up.
//! - [`SpawnedGhnetd`]: a ghnetd child in a private iceoryx2 namespace, Zenoh on a
//!   free loopback port (read back from its log), log to a file.
//!
//! Threads: the caller's (pacing, all publishers on one node, RSS sampling, progress),
//! one iceoryx2 collector, Zenoh's runtime, and for a spawned ghnetd one log reader.

use std::collections::HashMap;
use std::fmt;
use std::fs::File;
use std::io::{BufRead, BufReader, Write};
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::atomic::{AtomicBool, Ordering::Relaxed};
use std::sync::{mpsc, Arc, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use anyhow::Context;
use ghnet_client::testing::TestNamespace;
use ghnet_client::zenoh::{self, Wait};
use ghnet_client::{
    decode_zenoh, HeadingEstimate, HeadingStatus, HeadingSubscriber, IpcConfig, VelocityPublisher,
    VelocitySample,
};
use iceoryx2::prelude::*;

use crate::{latency_since, now_ns, pacing_node, wait_for_subscriber, Pacer, Percentiles, Tally};

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
}

/// The two transports a heading arrives on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Transport {
    /// Shared memory, `<prefix>/<source>/heading` service.
    Iceoryx2 = 0,
    /// Zenoh key `<prefix>/<source>/heading`.
    Zenoh = 1,
}

impl Transport {
    fn other(self) -> Self {
        match self {
            Transport::Iceoryx2 => Transport::Zenoh,
            Transport::Zenoh => Transport::Iceoryx2,
        }
    }
}

/// Per source: how often each seq arrived on each transport, and the values waiting
/// for their twin on the other transport.
#[derive(Debug)]
struct SourceBook {
    /// `counts[t][seq]`, saturating at 255.
    counts: [Vec<u8>; 2],
    unexpected: [u64; 2],
    /// First arrival of a seq on one transport, until it arrives on the other.
    pending: HashMap<u64, (Transport, [u8; HeadingEstimate::SIZE])>,
    compared: u64,
    mismatches: u64,
}

/// Exactly-once bookkeeping of one soak, shared by the iceoryx2 collector and the
/// Zenoh callback (behind a mutex: about 2000 short updates a second at 100 × 10 Hz).
#[derive(Debug)]
pub struct Book {
    sources: Vec<SourceBook>,
    /// Distinct seqs answered so far, per transport (progress and drain).
    unique: [u64; 2],
    /// Status `Stale` messages (not answers; see the shared contract).
    stale: u64,
    /// Zenoh headings of sources that are not ours (same prefix, other publishers).
    foreign: u64,
    /// Zenoh payloads that did not decode.
    undecodable: u64,
    /// Sample timestamp → receipt, µs, per transport.
    latency_us: [Vec<u32>; 2],
}

impl Book {
    /// Room for `planned` seqs of `sources` sources.
    pub fn new(sources: usize, planned: u64) -> Self {
        let per = || SourceBook {
            counts: [vec![0; planned as usize], vec![0; planned as usize]],
            unexpected: [0; 2],
            pending: HashMap::new(),
            compared: 0,
            mismatches: 0,
        };
        Self {
            sources: (0..sources).map(|_| per()).collect(),
            unique: [0; 2],
            stale: 0,
            foreign: 0,
            undecodable: 0,
            latency_us: [Vec::new(), Vec::new()],
        }
    }

    /// Records one heading of source `index` received on `t`.
    pub fn record(&mut self, t: Transport, index: usize, h: &HeadingEstimate) {
        if h.heading_status() == Some(HeadingStatus::Stale) {
            self.stale += 1;
            return;
        }
        let latency = latency_since(h.timestamp_ns).as_micros();
        self.latency_us[t as usize].push(latency.min(u32::MAX as u128) as u32);
        let Some(s) = self.sources.get_mut(index) else {
            return;
        };
        let Some(c) = s.counts[t as usize].get_mut(h.seq as usize) else {
            s.unexpected[t as usize] += 1;
            return;
        };
        let first = *c == 0;
        *c = c.saturating_add(1);
        if !first {
            return;
        }
        self.unique[t as usize] += 1;
        let bytes = h.to_le_bytes();
        match s.pending.remove(&h.seq) {
            Some((from, twin)) if from == t.other() => {
                s.compared += 1;
                s.mismatches += u64::from(twin != bytes);
            }
            _ => {
                s.pending.insert(h.seq, (t, bytes));
            }
        }
    }

    /// Distinct seqs answered on `t` so far, all sources.
    pub fn unique(&self, t: Transport) -> u64 {
        self.unique[t as usize]
    }

    /// Exactly-once accounting of source `index` on `t` for seqs `0..sent`.
    fn tally(&self, index: usize, t: Transport, sent: u64) -> Tally {
        let s = &self.sources[index];
        let counts = &s.counts[t as usize];
        let (inside, after) = counts.split_at((sent as usize).min(counts.len()));
        Tally {
            lost: inside.iter().filter(|&&c| c == 0).count() as u64,
            duplicates: inside.iter().map(|&c| u64::from(c.saturating_sub(1))).sum(),
            unexpected: s.unexpected[t as usize] + after.iter().map(|&c| u64::from(c)).sum::<u64>(),
        }
    }
}

type SharedBook = Arc<Mutex<Book>>;

fn lock(book: &SharedBook) -> MutexGuard<'_, Book> {
    // A panicking receiver would poison it; the counts are still the best we have.
    book.lock().unwrap_or_else(|e| e.into_inner())
}

/// One source's result.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SourceReport {
    /// Source name.
    pub name: String,
    /// iceoryx2 accounting.
    pub iceoryx2: Tally,
    /// Zenoh accounting (`None` when Zenoh was not checked).
    pub zenoh: Option<Tally>,
    /// Seqs whose iceoryx2 and Zenoh headings were compared.
    pub compared: u64,
    /// Of those, how many differ in any byte.
    pub mismatches: u64,
}

/// ghnetd's resident memory, sampled once a second.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RssSeries {
    /// (seconds since the first sample was sent, VmRSS kB).
    pub samples: Vec<(f64, u64)>,
}

impl RssSeries {
    /// `VmRSS` of `pid` in kB; `None` when the process is gone (or a zombie).
    pub fn read(pid: u32) -> Option<u64> {
        let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
        let line = status.lines().find(|l| l.starts_with("VmRSS:"))?;
        line.split_whitespace().nth(1)?.parse().ok()
    }

    /// Samples at or after `from_s`.
    fn after(&self, from_s: f64) -> impl Iterator<Item = &(f64, u64)> {
        self.samples.iter().filter(move |(t, _)| *t >= from_s)
    }

    /// Growth after the warm-up: (first, last, min, max) kB of the samples at or after
    /// `warmup`; `None` with fewer than two such samples.
    pub fn after_warmup(&self, warmup: Duration) -> Option<RssWindow> {
        RssWindow::of(self.after(warmup.as_secs_f64()).map(|&(_, kb)| kb))
    }
}

/// First, last, min and max of some RSS samples, kB.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RssWindow {
    /// First sample.
    pub first: u64,
    /// Last sample.
    pub last: u64,
    /// Smallest.
    pub min: u64,
    /// Largest.
    pub max: u64,
    /// Number of samples.
    pub count: usize,
}

impl RssWindow {
    /// `None` for fewer than two samples.
    ///
    /// ```
    /// # use ghnet_examples::soak::RssWindow;
    /// let w = RssWindow::of([100, 90, 130, 110]).unwrap();
    /// assert_eq!((w.growth_kb(), w.range_kb()), (10, 40));
    /// assert!(RssWindow::of([5]).is_none());
    /// ```
    pub fn of(kb: impl IntoIterator<Item = u64>) -> Option<Self> {
        let mut it = kb.into_iter();
        let first = it.next()?;
        let mut w = Self {
            first,
            last: first,
            min: first,
            max: first,
            count: 1,
        };
        for kb in it {
            (w.last, w.min, w.max) = (kb, w.min.min(kb), w.max.max(kb));
            w.count += 1;
        }
        (w.count >= 2).then_some(w)
    }

    /// last − first, kB (negative when memory was given back).
    pub fn growth_kb(&self) -> i64 {
        self.last as i64 - self.first as i64
    }

    /// max − min, kB.
    pub fn range_kb(&self) -> u64 {
        self.max - self.min
    }
}

/// The result of a soak.
#[derive(Debug, Clone)]
pub struct Report {
    /// Samples sent per source (fewer than planned when interrupted).
    pub sent: u64,
    /// Samples planned per source.
    pub planned: u64,
    /// Per source.
    pub sources: Vec<SourceReport>,
    /// `Stale` status messages seen (skipped: they answer no sample).
    pub stale: u64,
    /// Zenoh headings of other sources on the prefix (ignored).
    pub foreign: u64,
    /// Zenoh payloads on our keys that were not headings.
    pub undecodable: u64,
    /// Latency on iceoryx2: sample timestamp → receipt.
    pub latency_iceoryx2: Option<Percentiles>,
    /// Latency on Zenoh.
    pub latency_zenoh: Option<Percentiles>,
    /// ghnetd's memory (empty without a pid).
    pub rss: RssSeries,
    /// Warm-up excluded from the memory verdict.
    pub warmup: Duration,
    /// Memory verdict threshold, kB.
    pub rss_limit_kb: u64,
    /// Whether the memory was sampled at all.
    pub rss_checked: bool,
    /// Whether Zenoh was checked.
    pub zenoh_checked: bool,
    /// Ctrl-C / SIGTERM stopped publishing early.
    pub interrupted: bool,
}

impl Report {
    /// Sum of one transport's tallies over all sources.
    pub fn total(&self, t: Transport) -> Tally {
        let mut sum = Tally::default();
        for s in &self.sources {
            let x = match t {
                Transport::Iceoryx2 => Some(s.iceoryx2),
                Transport::Zenoh => s.zenoh,
            };
            if let Some(x) = x {
                sum.lost += x.lost;
                sum.duplicates += x.duplicates;
                sum.unexpected += x.unexpected;
            }
        }
        sum
    }

    /// Growth window after the warm-up.
    pub fn rss_window(&self) -> Option<RssWindow> {
        self.rss.after_warmup(self.warmup)
    }

    /// Everything that makes this run a failure; empty = pass.
    pub fn failures(&self) -> Vec<String> {
        let mut f = Vec::new();
        let mut transports = vec![(Transport::Iceoryx2, "iceoryx2")];
        if self.zenoh_checked {
            transports.push((Transport::Zenoh, "zenoh"));
        }
        for (t, name) in transports {
            let tally = self.total(t);
            if !tally.is_exactly_once() {
                f.push(format!("{name}: {tally}"));
            }
        }
        let mismatches: u64 = self.sources.iter().map(|s| s.mismatches).sum();
        if mismatches > 0 {
            f.push(format!(
                "{mismatches} headings differ between iceoryx2 and Zenoh"
            ));
        }
        if self.undecodable > 0 {
            f.push(format!("{} undecodable Zenoh payloads", self.undecodable));
        }
        if self.rss_checked {
            match self.rss_window() {
                Some(w) if w.growth_kb() >= self.rss_limit_kb as i64 => f.push(format!(
                    "ghnetd RSS grew {} kB after the warm-up (limit {} kB)",
                    w.growth_kb(),
                    self.rss_limit_kb
                )),
                Some(_) => {}
                None => f.push(format!(
                    "ghnetd RSS not judged: fewer than 2 samples after the {:?} warm-up (run longer)",
                    self.warmup
                )),
            }
        }
        f
    }
}

impl fmt::Display for Report {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let n = self.sources.len() as u64;
        for s in &self.sources {
            let bad = !s.iceoryx2.is_exactly_once()
                || s.zenoh.is_some_and(|z| !z.is_exactly_once())
                || s.mismatches > 0;
            if bad {
                write!(f, "{}: iceoryx2 {}", s.name, s.iceoryx2)?;
                if let Some(z) = s.zenoh {
                    write!(f, " | zenoh {z}")?;
                }
                writeln!(f, " | {} values differ", s.mismatches)?;
            }
        }
        let latency = |p: &Option<Percentiles>| p.map_or("-".to_owned(), |p| p.to_string());
        let t = self.total(Transport::Iceoryx2);
        writeln!(
            f,
            "iceoryx2: {} sources × {} samples: answered {}  {t}",
            n,
            self.sent,
            n * self.sent - t.lost
        )?;
        writeln!(f, "  latency {}", latency(&self.latency_iceoryx2))?;
        if self.zenoh_checked {
            let t = self.total(Transport::Zenoh);
            writeln!(f, "zenoh:    answered {}  {t}", n * self.sent - t.lost)?;
            writeln!(f, "  latency {}", latency(&self.latency_zenoh))?;
            let compared: u64 = self.sources.iter().map(|s| s.compared).sum();
            let mismatches: u64 = self.sources.iter().map(|s| s.mismatches).sum();
            writeln!(
                f,
                "values: {compared} seqs compared between iceoryx2 and Zenoh, {mismatches} differ"
            )?;
        }
        writeln!(
            f,
            "stale status messages (skipped): {}  foreign Zenoh headings (ignored): {}",
            self.stale, self.foreign
        )?;
        if self.rss_checked {
            match self.rss_window() {
                Some(w) => writeln!(
                    f,
                    "ghnetd RSS after the {:.0?} warm-up ({} samples): first {} kB  last {} kB  \
                     growth {:+} kB  min {} kB  max {} kB  range {} kB  (limit: growth < {} kB)",
                    self.warmup,
                    w.count,
                    w.first,
                    w.last,
                    w.growth_kb(),
                    w.min,
                    w.max,
                    w.range_kb(),
                    self.rss_limit_kb
                )?,
                None => writeln!(f, "ghnetd RSS: too few samples after the warm-up")?,
            }
        }
        Ok(())
    }
}

/// Runs the soak against a ghnetd that already serves (or discovers) `opts`' sources
/// on `opts.ipc`. Prints progress to stdout. Errors only when the run could not
/// happen (no daemon, ghnetd died, bad options); loss and growth are in the report.
pub fn run(opts: &Options) -> anyhow::Result<Report> {
    anyhow::ensure!(opts.sources > 0, "need at least one source");
    let planned = opts.samples_per_source();
    anyhow::ensure!(planned > 0, "duration × rate is less than one sample");
    anyhow::ensure!(
        planned.saturating_mul(opts.sources as u64) <= 1 << 30,
        "sources × samples is over 2^30: run fewer or shorter"
    );
    let names = opts.source_names();
    let index: HashMap<String, usize> = (names.iter().enumerate())
        .map(|(i, n)| (n.clone(), i))
        .collect();
    let book: SharedBook = Arc::new(Mutex::new(Book::new(names.len(), planned)));

    // Receivers first, so no heading is published before both listen.
    let collector = IceoryxCollector::start(&opts.ipc, &names, book.clone())?;
    let warmed_up = Arc::new(AtomicBool::new(false));
    let zenoh = match &opts.zenoh_connect {
        Some(endpoint) => Some(ZenohCollector::start(
            endpoint,
            &opts.ipc,
            index,
            (opts.warmup_source(), warmed_up.clone()),
            book.clone(),
            opts.patience,
        )?),
        None => None,
    };

    let node = pacing_node(&opts.ipc, "ghnet-soak-pub")?;
    let pubs: Vec<VelocityPublisher> = (names.iter())
        .map(|n| VelocityPublisher::with_node(&node, &opts.ipc, n))
        .collect::<Result<_, _>>()?;
    let warmup = VelocityPublisher::with_node(&node, &opts.ipc, &opts.warmup_source())?;
    let pid = opts.daemon_pid;
    let all: Vec<&VelocityPublisher> = pubs.iter().chain([&warmup]).collect();
    wait_for_subscriber(&node, &all, opts.patience, || {
        pid.is_some_and(|p| RssSeries::read(p).is_none())
    })?;
    if zenoh.is_some() {
        let t0 = Instant::now();
        let mut seq = 0;
        while !warmed_up.load(Relaxed) {
            anyhow::ensure!(
                t0.elapsed() < opts.patience,
                "no heading of {} over Zenoh within {:?}",
                opts.warmup_source(),
                opts.patience
            );
            warmup.send(sample(0, seq))?;
            seq += 1;
            node.wait(Duration::from_millis(20))
                .map_err(|_| crate::Interrupted)?;
        }
    }

    println!(
        "soak: {} sources × {planned} samples at {} Hz ({:?}), prefix {}, zenoh {}, ghnetd pid {}",
        names.len(),
        opts.rate_hz,
        opts.duration,
        opts.ipc.prefix(),
        opts.zenoh_connect.as_deref().unwrap_or("not checked"),
        pid.map_or("unknown (no RSS check)".to_owned(), |p| p.to_string()),
    );
    let mut rss = RssSeries::default();
    let mut progress = Progress::new(opts.report_every);
    let pacer = Pacer::new(opts.rate_hz)?;
    let (mut sent, mut next_rss, mut interrupted) = (0, 0.0, false);
    while sent < planned {
        for (i, p) in pubs.iter().enumerate() {
            p.send(sample(i, sent))?;
        }
        sent += 1;
        let t = pacer.elapsed().as_secs_f64();
        if let (Some(pid), true) = (pid, t >= next_rss) {
            let kb = RssSeries::read(pid)
                .with_context(|| format!("ghnetd (pid {pid}) is gone after {t:.1} s"))?;
            rss.samples.push((t, kb));
            next_rss = t.floor() + 1.0;
        }
        progress.maybe_print(t, sent * names.len() as u64, &book, &rss, false);
        if pacer.wait_for_slot(&node, sent).is_err() {
            println!("interrupted: stopping after {sent} samples per source");
            interrupted = true;
            break;
        }
    }

    // The last headings: until every sent seq arrived on each checked transport.
    let expected = sent * names.len() as u64;
    let t0 = Instant::now();
    let all_in = || {
        let b = lock(&book);
        b.unique(Transport::Iceoryx2) >= expected
            && (zenoh.is_none() || b.unique(Transport::Zenoh) >= expected)
    };
    while !all_in() && t0.elapsed() < opts.drain_timeout {
        std::thread::sleep(Duration::from_millis(10));
    }
    // A late duplicate would arrive right behind; give it a moment.
    std::thread::sleep(Duration::from_millis(500));
    if let Some(pid) = pid {
        if let Some(kb) = RssSeries::read(pid) {
            rss.samples.push((pacer.elapsed().as_secs_f64(), kb));
        }
    }
    let t = pacer.elapsed().as_secs_f64();
    progress.maybe_print(t, expected, &book, &rss, true);
    collector.stop()?;
    drop(zenoh);

    // Zenoh may keep the callback (and its clone of the book) a little longer.
    let mut book = lock(&book);
    let sources = (names.iter().enumerate())
        .map(|(i, name)| SourceReport {
            name: name.clone(),
            iceoryx2: book.tally(i, Transport::Iceoryx2, sent),
            zenoh: opts
                .zenoh_connect
                .as_ref()
                .map(|_| book.tally(i, Transport::Zenoh, sent)),
            compared: book.sources[i].compared,
            mismatches: book.sources[i].mismatches,
        })
        .collect();
    let [lat_i, lat_z] = std::mem::take(&mut book.latency_us);
    let percentiles =
        |v: Vec<u32>| Percentiles::of(v.into_iter().map(|us| u64::from(us) * 1000).collect());
    Ok(Report {
        sent,
        planned,
        sources,
        stale: book.stale,
        foreign: book.foreign,
        undecodable: book.undecodable,
        latency_iceoryx2: percentiles(lat_i),
        latency_zenoh: percentiles(lat_z),
        rss,
        warmup: opts.effective_warmup(),
        rss_limit_kb: opts.rss_limit_kb,
        rss_checked: pid.is_some(),
        zenoh_checked: opts.zenoh_connect.is_some(),
        interrupted,
    })
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

/// One thread, one node, one `WaitSet` over every source's heading listener.
struct IceoryxCollector {
    stop: Arc<AtomicBool>,
    thread: JoinHandle<anyhow::Result<()>>,
}

impl IceoryxCollector {
    /// Returns once every subscriber exists.
    fn start(ipc: &IpcConfig, names: &[String], book: SharedBook) -> anyhow::Result<Self> {
        let stop = Arc::new(AtomicBool::new(false));
        let (ready_tx, ready_rx) = mpsc::channel();
        let (ipc, names, flag) = (ipc.clone(), names.to_vec(), stop.clone());
        // iceoryx2 ports are !Send: everything is made on the thread that uses it.
        let thread = std::thread::spawn(move || -> anyhow::Result<()> {
            let node = pacing_node(&ipc, "ghnet-soak-sub")?;
            let subs: Vec<HeadingSubscriber> = (names.iter())
                .map(|n| HeadingSubscriber::with_node(&node, &ipc, n))
                .collect::<Result<_, _>>()?;
            // The caller owns Ctrl-C (its pacing node); this thread stops on `stop`.
            let waitset = WaitSetBuilder::new()
                .signal_handling_mode(SignalHandlingMode::Disabled)
                .create::<ipc::Service>()
                .context("cannot create the collector's WaitSet")?;
            let guards = (subs.iter())
                .map(|s| waitset.attach_notification(s.listener()))
                .collect::<Result<Vec<_>, _>>()
                .context("cannot attach a heading listener")?;
            ready_tx.send(())?;
            let mut failure = None;
            while !flag.load(Relaxed) && failure.is_none() {
                let on_event = |id: WaitSetAttachmentId<ipc::Service>| {
                    if let Some(i) = guards.iter().position(|g| id.has_event_from(g)) {
                        if let Err(e) = drain(&subs[i], i, &book) {
                            failure = Some(e);
                            return CallbackProgression::Stop;
                        }
                    }
                    CallbackProgression::Continue
                };
                waitset
                    .wait_and_process_once_with_timeout(on_event, Duration::from_millis(100))
                    .context("collector WaitSet failed")?;
            }
            if let Some(e) = failure {
                return Err(e);
            }
            // Whatever arrived without a wake-up we processed.
            for (i, s) in subs.iter().enumerate() {
                drain(s, i, &book)?;
            }
            Ok(())
        });
        if ready_rx.recv().is_err() {
            return Err(thread
                .join()
                .map_err(|_| anyhow::anyhow!("collector panicked"))?
                .unwrap_err());
        }
        Ok(Self { stop, thread })
    }

    fn stop(self) -> anyhow::Result<()> {
        self.stop.store(true, Relaxed);
        self.thread
            .join()
            .map_err(|_| anyhow::anyhow!("collector panicked"))?
    }
}

/// Wake-ups first (or the WaitSet fires again at once), then every buffered heading.
fn drain(sub: &HeadingSubscriber, index: usize, book: &SharedBook) -> anyhow::Result<()> {
    sub.drain_notifications()?;
    let mut book = lock(book);
    while let Some(h) = sub.try_recv()? {
        book.record(Transport::Iceoryx2, index, &h);
    }
    Ok(())
}

/// A Zenoh session connected to ghnetd and one callback subscriber on
/// `<prefix>/*/heading`; undeclared on drop.
struct ZenohCollector {
    _subscriber: zenoh::pubsub::Subscriber<()>,
    _session: zenoh::Session,
}

impl ZenohCollector {
    /// Returns once ghnetd has answered a query on this session, so it knows the
    /// subscriber (a query travels behind the declarations made before it).
    fn start(
        endpoint: &str,
        ipc: &IpcConfig,
        index: HashMap<String, usize>,
        warmup: (String, Arc<AtomicBool>),
        book: SharedBook,
        patience: Duration,
    ) -> anyhow::Result<Self> {
        let config = ghnet_client::peer_config(&[], &[endpoint.to_owned()])
            .map_err(|e| anyhow::anyhow!("zenoh endpoint {endpoint}: {e}"))?;
        let session = zenoh::open(config)
            .wait()
            .map_err(|e| anyhow::anyhow!("cannot open the Zenoh session: {e}"))?;
        let prefix = format!("{}/", ipc.prefix());
        let suffix = format!("/{}", ghnet_client::names::HEADING_SUFFIX);
        let subscriber = session
            .declare_subscriber(format!("{prefix}*{suffix}"))
            .callback(move |sample| {
                let key = sample.key_expr().as_str();
                let source = key
                    .strip_prefix(&prefix)
                    .and_then(|k| k.strip_suffix(&suffix));
                if source == Some(warmup.0.as_str()) {
                    warmup.1.store(true, Relaxed);
                    return;
                }
                let i = source.and_then(|s| index.get(s).copied());
                let mut book = lock(&book);
                match (i, decode_zenoh(&sample.payload().to_bytes())) {
                    (None, _) => book.foreign += 1,
                    (Some(i), Ok(h)) => book.record(Transport::Zenoh, i, &h),
                    (Some(_), Err(_)) => book.undecodable += 1,
                }
            })
            .wait()
            .map_err(|e| anyhow::anyhow!("cannot declare the Zenoh subscriber: {e}"))?;
        let key = ipc.zenoh_model_key();
        let t0 = Instant::now();
        loop {
            let replies = session
                .get(key.as_str())
                .timeout(Duration::from_secs(2))
                .wait()
                .map_err(|e| anyhow::anyhow!("query {key}: {e}"))?;
            if matches!(replies.recv(), Ok(r) if r.result().is_ok()) {
                break;
            }
            anyhow::ensure!(
                t0.elapsed() < patience,
                "no ghnetd answered {key} via {endpoint} within {patience:?}: is ghnetd's \
                 zenoh.listen there, with the same prefix?"
            );
            std::thread::sleep(Duration::from_millis(100));
        }
        Ok(Self {
            _subscriber: subscriber,
            _session: session,
        })
    }
}

/// A ghnetd child for a soak: private iceoryx2 namespace, static sources, Zenoh on a
/// free loopback port, log in a file (warnings and errors echoed to stderr). Dies with
/// the soak (`PR_SET_PDEATHSIG`); killed and reaped on drop.
pub struct SpawnedGhnetd {
    child: Option<Child>,
    endpoint: String,
    log_thread: Option<JoinHandle<()>>,
    // Dropped last: the namespace's files go once the daemon is reaped.
    namespace: TestNamespace,
}

impl SpawnedGhnetd {
    /// Starts `binary` serving `sources` on `prefix`, in a fresh namespace, stats
    /// every `stats_interval_s`, log to `log`; returns once its Zenoh endpoint is known.
    /// The model and anything else come from `GHNETD_CONFIG`, as for any ghnetd.
    pub fn start(
        binary: &Path,
        prefix: &str,
        sources: &[String],
        stats_interval_s: u64,
        log: &Path,
        patience: Duration,
    ) -> anyhow::Result<Self> {
        let namespace = TestNamespace::new("soak");
        let mut cmd = Command::new(binary);
        cmd.arg("--service-prefix")
            .arg(prefix)
            .arg("--iceoryx2-global-prefix")
            .arg(namespace.global_prefix())
            .arg("--iceoryx2-root-path")
            .arg(namespace.root_path())
            .args(["--discovery", "false"])
            .args(["--max-sources", &sources.len().max(1).to_string()])
            .args(["--stats-interval-s", &stats_interval_s.to_string()])
            .args(["--zenoh-listen", "tcp/127.0.0.1:0"]);
        for s in sources {
            cmd.args(["--source", s]);
        }
        // The Zenoh endpoint is read from the info-level start line: ghnetd's
        // default log filter, whatever RUST_LOG the caller has.
        cmd.env_remove("RUST_LOG")
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::piped());
        // SAFETY: only an async-signal-safe syscall between fork and exec.
        unsafe {
            cmd.pre_exec(|| {
                libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGKILL);
                Ok(())
            });
        }
        let mut child = cmd
            .spawn()
            .with_context(|| format!("cannot start {}", binary.display()))?;
        let stderr = child.stderr.take().expect("piped");
        let mut file =
            File::create(log).with_context(|| format!("cannot create {}", log.display()))?;
        let (tx, rx) = mpsc::channel();
        let log_thread = std::thread::spawn(move || {
            for line in BufReader::new(stderr).lines() {
                let Ok(line) = line else { break };
                let _ = writeln!(file, "{line}");
                if line.contains("zenoh session open") {
                    let _ = tx.send(listening_endpoint(&line));
                }
                if line.contains(" WARN ") || line.contains(" ERROR ") || line.starts_with("error")
                {
                    eprintln!("ghnetd: {line}");
                }
            }
        });
        let mut this = Self {
            child: Some(child),
            endpoint: String::new(),
            log_thread: Some(log_thread),
            namespace,
        };
        let t0 = Instant::now();
        this.endpoint = loop {
            match rx.recv_timeout(Duration::from_millis(50)) {
                Ok(Some(e)) => break e,
                Ok(None) => anyhow::bail!("ghnetd's Zenoh start line names no endpoint"),
                Err(_) => {}
            }
            if let Some(status) = this.try_wait() {
                anyhow::bail!("ghnetd exited at start ({status}); log: {}", log.display());
            }
            anyhow::ensure!(
                t0.elapsed() < patience,
                "ghnetd did not open its Zenoh session within {patience:?}; log: {}",
                log.display()
            );
        };
        Ok(this)
    }

    /// The Zenoh endpoint ghnetd listens on, e.g. `tcp/127.0.0.1:40123`.
    pub fn zenoh_endpoint(&self) -> &str {
        &self.endpoint
    }

    /// The iceoryx2 side to use with this daemon, on `prefix`.
    pub fn ipc(&self, prefix: &str) -> anyhow::Result<IpcConfig> {
        self.namespace.ipc().with_prefix(prefix).context("--prefix")
    }

    /// Process id.
    pub fn pid(&self) -> u32 {
        self.child.as_ref().map_or(0, |c| c.id())
    }

    fn try_wait(&mut self) -> Option<ExitStatus> {
        self.child.as_mut()?.try_wait().ok().flatten()
    }

    /// SIGTERM, then up to `grace` for the exit; the exit status.
    pub fn stop(mut self, grace: Duration) -> anyhow::Result<ExitStatus> {
        let pid = self.pid() as libc::pid_t;
        // SAFETY: kill(2) on our own child, not yet reaped, so its pid is not reused.
        unsafe { libc::kill(pid, libc::SIGTERM) };
        let t0 = Instant::now();
        while t0.elapsed() < grace {
            if let Some(status) = self.try_wait() {
                self.child = None;
                if let Some(t) = self.log_thread.take() {
                    let _ = t.join();
                }
                return Ok(status);
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        anyhow::bail!("ghnetd ignored SIGTERM for {grace:?} and was killed")
    }
}

impl Drop for SpawnedGhnetd {
    fn drop(&mut self) {
        if let Some(mut child) = self.child.take() {
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}

/// The first endpoint of `listening=["tcp/127.0.0.1:40123", ...]` in a log line.
fn listening_endpoint(line: &str) -> Option<String> {
    let rest = line.split_once("listening=[\"")?.1;
    Some(rest.split('"').next()?.to_owned())
}

/// `ghnetd` next to the running executable (`target/<profile>/`), where `cargo build`
/// puts it; `None` if it is not there.
pub fn ghnetd_next_to_exe() -> Option<PathBuf> {
    let exe = std::env::current_exe().ok()?;
    let name = format!("ghnetd{}", std::env::consts::EXE_SUFFIX);
    exe.ancestors()
        .skip(1)
        .take(3)
        .map(|d| d.join(&name))
        .find(|p| p.is_file())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn heading(seq: u64, heading_deg: f32, status: HeadingStatus) -> HeadingEstimate {
        HeadingEstimate {
            seq,
            // The same on both transports, as ghnetd sends it.
            timestamp_ns: 1_700_000_000_000_000_000 + seq,
            heading_deg,
            status: status.as_u32(),
            ..HeadingEstimate::from_le_bytes(&[0; HeadingEstimate::SIZE])
        }
    }

    #[test]
    fn book_counts_loss_duplicates_unexpected_and_mismatches() {
        let mut b = Book::new(2, 4);
        let ok = HeadingStatus::Ok;
        for seq in [0, 1, 1, 3, 9] {
            b.record(Transport::Iceoryx2, 0, &heading(seq, 1.0, ok));
        }
        for seq in [0, 1, 2, 3] {
            // seq 3 differs between the transports.
            let deg = if seq == 3 { 2.0 } else { 1.0 };
            b.record(Transport::Zenoh, 0, &heading(seq, deg, ok));
        }
        b.record(Transport::Zenoh, 1, &heading(0, 1.0, HeadingStatus::Stale));
        let t = b.tally(0, Transport::Iceoryx2, 4);
        assert_eq!((t.lost, t.duplicates, t.unexpected), (1, 1, 1));
        assert!(b.tally(0, Transport::Zenoh, 4).is_exactly_once());
        assert_eq!((b.sources[0].compared, b.sources[0].mismatches), (3, 1));
        assert_eq!(b.stale, 1);
        assert_eq!(b.tally(1, Transport::Zenoh, 4).lost, 4);
        // Interrupted after 2 samples: seq 3 was never sent, so it is unexpected.
        let t = b.tally(0, Transport::Iceoryx2, 2);
        assert_eq!((t.lost, t.duplicates, t.unexpected), (0, 1, 2));
    }

    #[test]
    fn endpoint_from_the_start_line() {
        let line = r#"2026 INFO ghnetd::remote: zid=ab listening=["tcp/127.0.0.1:40123", "tcp/[::1]:1"] connect=[] "zenoh session open""#;
        assert_eq!(
            listening_endpoint(line).as_deref(),
            Some("tcp/127.0.0.1:40123")
        );
        assert_eq!(listening_endpoint("listening=[]"), None);
    }

    #[test]
    fn rss_of_this_process() {
        assert!(RssSeries::read(std::process::id()).is_some_and(|kb| kb > 0));
    }
}
