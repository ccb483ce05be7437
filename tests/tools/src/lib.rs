//! ghnet's tools for long and heavy runs, on the test kit (`ghnet-testkit`): the soak
//! (bin `soak`, and the CI soak test of the cross-process tests) and the daemon
//! benchmark (bin `perf`, its modules under `src/bin/perf/`).
//!
//! # Layout
//!
//! - [`soak`] — N sources at a fixed rate against a real ghnetd: every sequence number
//!   answered exactly once on iceoryx2 *and* on Zenoh, the same bytes on both, and
//!   ghnetd's resident memory flat after a warm-up.
//! - [`Percentiles`] — nearest-rank latency percentiles, shared by soak and perf.
//!
//! ```text
//! cargo build --release -p ghnetd -p ghnet-tools
//! target/release/soak --spawn-daemon --sources 100 --rate 10 --duration 3600
//! target/release/perf --quick
//! ```

#![warn(missing_docs)]

pub mod soak;

use std::fmt;
use std::time::Duration;

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
    /// # use ghnet_tools::Percentiles;
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
