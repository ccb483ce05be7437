//! Resources a source costs, checked before it is opened, and the backoff of sources
//! that could not be opened.
//!
//! Two resources run out under load, and iceoryx2 reports neither by name: file
//! descriptors (an opaque `InternalFailure` at `EMFILE`) and shared memory (a full
//! `/dev/shm` is not an error at all: tmpfs files are sparse, so creating a segment
//! succeeds and the first write to a page that cannot be allocated kills the process
//! with SIGBUS). So ghnetd raises its descriptor limit at start, and before opening a
//! source checks that the descriptors and the shared memory it needs are there; a
//! source that does not fit is reported with the resource named and retried
//! ([`Retry`]), and the sources already served go on.

use std::path::Path;
use std::time::{Duration, Instant};

use ghnet_client::{IpcConfig, OpenError, Setting};
use tracing::{info, warn};

use crate::config::Config;
use crate::host::{fs_size, shm_free, SHM_DIR};

/// Descriptors one source costs, measured (`/proc/self/fd` before and after opening
/// sources with Zenoh on): about 17. Used until ghnetd has measured its own sources.
const FDS_PER_SOURCE: u64 = 17;

/// Descriptors kept free for everything that is not a source: Zenoh's sessions and
/// accept threads (Zenoh 1.10 panics in an accept thread at `EMFILE`), a discovery
/// listing (opens every service's static config), dead-node cleanup, log files.
const FDS_RESERVE: u64 = 64;

/// Shared memory kept free beyond what a source needs: other processes (publishers,
/// consumers) create their segments there too, and running it to the last page is
/// what ends in SIGBUS.
const SHM_MARGIN: f64 = 1.5;

/// The budget of one ghnetd: descriptor limit, and what a source costs.
pub(crate) struct Budget {
    /// Soft `RLIMIT_NOFILE` after raising it.
    fd_limit: u64,
    fds_per_source: u64,
    /// Shared memory a source needs, bytes (computed from the `ipc.*` settings, then
    /// raised to what sources really took).
    shm_per_source: u64,
    /// iceoryx2's global prefix: the start of every file name it puts in [`SHM_DIR`].
    shm_prefix: String,
    /// Whether [`learn`](Self::learn) has measured a source yet (only the first is
    /// measured: later ones can overlap other processes' segments coming and going).
    learned: bool,
}

/// Descriptors and shared memory in use, to learn what a source really costs.
#[derive(Clone, Copy)]
pub(crate) struct Usage {
    fds: u64,
    shm: u64,
}

impl Budget {
    /// Raises the descriptor limit, computes what a source needs and logs the
    /// budget; warns when the limit cannot cover `sources.max_sources`.
    pub(crate) fn measure(config: &Config, ipc: &IpcConfig) -> Self {
        let fd_limit = raise_nofile_limit();
        let budget = Budget {
            fd_limit,
            fds_per_source: FDS_PER_SOURCE,
            shm_per_source: config.ipc.shm_per_source(),
            shm_prefix: ipc.iceoryx2_config().global.prefix.to_string(),
            learned: false,
        };
        let max = config.sources.max_sources as u64;
        let fds_needed = FDS_RESERVE + budget.fds_per_source * max;
        let shm_free = shm_free(Path::new(SHM_DIR));
        info!(
            fd_limit,
            fds_per_source = budget.fds_per_source,
            fds_reserved = FDS_RESERVE,
            max_sources = max,
            fds_needed,
            shm_per_source = budget.shm_per_source,
            shm_free = shm_free.unwrap_or(0),
            "resource budget"
        );
        let shm_size = fs_size(Path::new(SHM_DIR)).unwrap_or(u64::MAX);
        if budget.shm_per_source.saturating_mul(max) > shm_size {
            warn!(
                shm_size,
                shm_per_source = budget.shm_per_source,
                "{SHM_DIR} cannot hold sources.max_sources sources with these ipc.* settings: about {} fit",
                shm_size / budget.shm_per_source.max(1)
            );
        }
        if fds_needed > fd_limit {
            warn!(
                fd_limit,
                fds_needed,
                "the descriptor limit cannot cover sources.max_sources: about {} sources fit; raise LimitNOFILE (ulimit -n) or lower sources.max_sources",
                fd_limit.saturating_sub(FDS_RESERVE) / budget.fds_per_source
            );
        }
        budget
    }

    /// `Err` naming the resource when one more source does not fit now.
    pub(crate) fn check(&self) -> Result<(), String> {
        match self.shortage() {
            Some(short) => Err(short),
            None => Ok(()),
        }
    }

    /// What is short for one more source, if anything.
    pub(crate) fn shortage(&self) -> Option<String> {
        let open = open_fds();
        if open + self.fds_per_source + FDS_RESERVE > self.fd_limit {
            return Some(format!(
                "file descriptors (limit {}): {open} open, a source needs about {} and {FDS_RESERVE} are kept for Zenoh and discovery",
                self.fd_limit, self.fds_per_source
            ));
        }
        let need = (self.shm_per_source as f64 * SHM_MARGIN) as u64;
        match shm_free(Path::new(SHM_DIR)) {
            Some(free) if free < need => Some(format!(
                "shared memory: {SHM_DIR} has {free} bytes free, a source needs about {} (with margin {need})",
                self.shm_per_source
            )),
            _ => None,
        }
    }

    /// The reason to report for a source that failed to open: the error (a limit
    /// named by its `ipc.*` key), preceded by the resource that is short if one is
    /// (iceoryx2 reports `EMFILE` as an opaque internal failure).
    pub(crate) fn explain(&self, e: anyhow::Error) -> String {
        let e = in_config_keys(&e);
        match self.shortage() {
            Some(short) => format!("{short}: {e}"),
            None if open_fds() + 2 * self.fds_per_source + FDS_RESERVE > self.fd_limit => {
                format!("file descriptors (limit {}): {e}", self.fd_limit)
            }
            None => e,
        }
    }

    /// Descriptors and shared memory in use now (nothing to measure once learned).
    pub(crate) fn usage(&self) -> Option<Usage> {
        (!self.learned).then(|| Usage {
            fds: open_fds(),
            shm: shm_used(Path::new(SHM_DIR), &self.shm_prefix),
        })
    }

    /// Learns from one source opened since `before`: what it really took, when that
    /// is more than assumed.
    pub(crate) fn learn(&mut self, before: Option<Usage>) {
        let (Some(before), Some(now)) = (before, self.usage()) else {
            return;
        };
        self.learned = true;
        self.fds_per_source = self.fds_per_source.max(now.fds.saturating_sub(before.fds));
        self.shm_per_source = self.shm_per_source.max(now.shm.saturating_sub(before.shm));
    }
}

/// `e` as `{e:#}` prints it, with a client limit error naming ghnetd's `ipc.*` key to
/// raise instead of the client's `ServiceSettings` field: the operator sets the key.
fn in_config_keys(e: &anyhow::Error) -> String {
    let causes: Vec<String> = e
        .chain()
        .map(|cause| match cause.downcast_ref::<OpenError>() {
            Some(open) => open.naming(|s| ipc_key(s).to_owned()),
            None => cause.to_string(),
        })
        .collect();
    causes.join(": ")
}

/// ghnetd's key for a client [`Setting`]: the `[ipc]` key that sets it.
fn ipc_key(setting: Setting) -> &'static str {
    match setting {
        Setting::MaxPublishers => "ipc.max_publishers",
        Setting::MaxSubscribers => "ipc.max_subscribers",
        Setting::MaxNodes => "ipc.max_nodes",
        Setting::SubscriberBufferSize => "ipc.subscriber_buffer",
    }
}

/// Raises the soft `RLIMIT_NOFILE` to the hard limit (as most servers do: systemd's
/// default soft limit, 1024, is about 55 sources) and returns the soft limit then in
/// force.
fn raise_nofile_limit() -> u64 {
    let mut lim = libc::rlimit {
        rlim_cur: 0,
        rlim_max: 0,
    };
    // SAFETY: getrlimit/setrlimit only read and write `lim`.
    unsafe {
        if libc::getrlimit(libc::RLIMIT_NOFILE, &mut lim) != 0 {
            return 1024;
        }
        if lim.rlim_cur < lim.rlim_max {
            let old = lim.rlim_cur;
            let raised = libc::rlimit {
                rlim_cur: lim.rlim_max,
                rlim_max: lim.rlim_max,
            };
            if libc::setrlimit(libc::RLIMIT_NOFILE, &raised) == 0 {
                info!(
                    from = old,
                    to = lim.rlim_max,
                    "raised the soft descriptor limit to the hard limit"
                );
                lim.rlim_cur = lim.rlim_max;
            } else {
                warn!(soft = old, hard = lim.rlim_max, error = %std::io::Error::last_os_error(), "cannot raise the descriptor limit");
            }
        }
    }
    lim.rlim_cur
}

/// Descriptors this process has open.
fn open_fds() -> u64 {
    std::fs::read_dir("/proc/self/fd").map_or(0, |d| d.count() as u64)
}

/// Bytes of the files whose name starts with `prefix` in `dir` (their sizes, not the
/// pages touched: a segment can grow to its size at any time).
fn shm_used(dir: &Path, prefix: &str) -> u64 {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return 0;
    };
    entries
        .flatten()
        .filter(|e| e.file_name().to_string_lossy().starts_with(prefix))
        .filter_map(|e| e.metadata().ok())
        .map(|m| m.len())
        .sum()
}

/// Backoff of a source that could not be opened: tried again after 0.1 s, then
/// doubling up to 5 s, for as long as its velocity service exists (a static source:
/// for as long as ghnetd runs).
pub(crate) struct Retry {
    /// Why the last try failed.
    pub(crate) reason: String,
    /// Tries after the first failure.
    pub(crate) retries: u64,
    backoff: Duration,
    next: Instant,
}

impl Retry {
    const FIRST: Duration = Duration::from_millis(100);
    const CAP: Duration = Duration::from_secs(5);

    pub(crate) fn new(reason: String, now: Instant) -> Self {
        Self {
            reason,
            retries: 0,
            backoff: Self::FIRST,
            next: now + Self::FIRST,
        }
    }

    pub(crate) fn failed_again(&mut self, reason: String, now: Instant) {
        self.reason = reason;
        self.retries += 1;
        self.backoff = (self.backoff * 2).min(Self::CAP);
        self.next = now + self.backoff;
    }

    pub(crate) fn is_due(&self, now: Instant) -> bool {
        now >= self.next
    }

    pub(crate) fn backoff_ms(&self) -> u64 {
        self.backoff.as_millis() as u64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn backoff_doubles_to_the_cap() {
        let t0 = Instant::now();
        let mut r = Retry::new("x".into(), t0);
        assert!(!r.is_due(t0));
        assert!(r.is_due(t0 + Duration::from_millis(100)));
        let mut seen = Vec::new();
        for _ in 0..8 {
            r.failed_again("y".into(), t0);
            seen.push(r.backoff_ms());
        }
        assert_eq!(seen, [200, 400, 800, 1600, 3200, 5000, 5000, 5000]);
        assert_eq!(r.retries, 8);
    }
}
