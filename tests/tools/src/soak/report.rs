//! The result of a soak ([`Report`]): per-source tallies, latencies, ghnetd's memory
//! over time ([`RssSeries`]) and the verdict ([`Report::failures`]).

use std::fmt;
use std::time::Duration;

use super::book::{Book, Tally, Transport};
use super::{Options, Published};
use crate::Percentiles;

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
    /// # use ghnet_tools::soak::RssWindow;
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
    /// What was run: sources, rate, duration, the memory limit and warm-up, and
    /// whether Zenoh (`zenoh_connect`) and the memory (`daemon_pid`) were checked.
    pub options: Options,
    /// Samples sent per source (fewer than planned when interrupted).
    pub sent: u64,
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
    /// Ctrl-C / SIGTERM stopped publishing early.
    pub interrupted: bool,
}

impl Report {
    /// The report of a finished run: the tallies of `sent` samples per source.
    pub(crate) fn new(opts: &Options, names: &[String], book: &Book, run: Published) -> Self {
        let zenoh_checked = opts.zenoh_connect.is_some();
        let sources = (names.iter().enumerate())
            .map(|(i, name)| SourceReport {
                name: name.clone(),
                iceoryx2: book.tally(i, Transport::Iceoryx2, run.sent),
                zenoh: zenoh_checked.then(|| book.tally(i, Transport::Zenoh, run.sent)),
                compared: book.sources[i].compared,
                mismatches: book.sources[i].mismatches,
            })
            .collect();
        let percentiles =
            |v: &[u32]| Percentiles::of(v.iter().map(|&us| u64::from(us) * 1000).collect());
        Self {
            options: opts.clone(),
            sent: run.sent,
            sources,
            stale: book.stale,
            foreign: book.foreign,
            undecodable: book.undecodable,
            latency_iceoryx2: percentiles(&book.latency_us[0]),
            latency_zenoh: percentiles(&book.latency_us[1]),
            rss: run.rss,
            interrupted: run.interrupted,
        }
    }

    /// Samples planned per source.
    pub fn planned(&self) -> u64 {
        self.options.samples_per_source()
    }

    /// Whether Zenoh was checked.
    pub fn zenoh_checked(&self) -> bool {
        self.options.zenoh_connect.is_some()
    }

    /// Whether ghnetd's memory was sampled.
    fn rss_checked(&self) -> bool {
        self.options.daemon_pid.is_some()
    }

    /// Sum of one transport's tallies over all sources.
    pub fn total(&self, t: Transport) -> Tally {
        let mut sum = Tally::default();
        for s in &self.sources {
            let x = match t {
                Transport::Iceoryx2 => Some(s.iceoryx2),
                Transport::Zenoh => s.zenoh,
            };
            if let Some(x) = x {
                sum.add(&x);
            }
        }
        sum
    }

    /// Growth window after the warm-up.
    pub fn rss_window(&self) -> Option<RssWindow> {
        self.rss.after_warmup(self.options.effective_warmup())
    }

    /// Everything that makes this run a failure; empty = pass.
    pub fn failures(&self) -> Vec<String> {
        let mut f = Vec::new();
        let mut transports = vec![(Transport::Iceoryx2, "iceoryx2")];
        if self.zenoh_checked() {
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
        if self.rss_checked() {
            match self.rss_window() {
                Some(w) if w.growth_kb() >= self.options.rss_limit_kb as i64 => f.push(format!(
                    "ghnetd RSS grew {} kB after the warm-up (limit {} kB)",
                    w.growth_kb(),
                    self.options.rss_limit_kb
                )),
                Some(_) => {}
                None => f.push(format!(
                    "ghnetd RSS not judged: fewer than 2 samples after the {:?} warm-up (run longer)",
                    self.options.effective_warmup()
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
        if self.zenoh_checked() {
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
        if self.rss_checked() {
            match self.rss_window() {
                Some(w) => writeln!(
                    f,
                    "ghnetd RSS after the {:.0?} warm-up ({} samples): first {} kB  last {} kB  \
                     growth {:+} kB  min {} kB  max {} kB  range {} kB  (limit: growth < {} kB)",
                    self.options.effective_warmup(),
                    w.count,
                    w.first,
                    w.last,
                    w.growth_kb(),
                    w.min,
                    w.max,
                    w.range_kb(),
                    self.options.rss_limit_kb
                )?,
                None => writeln!(f, "ghnetd RSS: too few samples after the warm-up")?,
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rss_of_this_process() {
        assert!(RssSeries::read(std::process::id()).is_some_and(|kb| kb > 0));
    }
}
