//! The roster: sources that have a velocity service but are not served, why (over
//! `sources.max_sources`, or failed to open) and when to try a failed one again (the
//! backoff of [`Retry`]). The event loop asks it what to open; the stats list it.

use std::collections::btree_map::{BTreeMap, Entry};
use std::collections::BTreeSet;
use std::time::Instant;

use tracing::{debug, info, warn};

use crate::pressure::Retry;
use crate::source::Kind;

/// What a housekeeping pass wants changed in the set of sources.
#[derive(Default)]
pub(crate) struct Changes {
    /// Source names to open.
    pub(crate) add: Vec<String>,
    /// Indices into the sources, any order.
    pub(crate) remove: Vec<usize>,
}

impl Changes {
    pub(crate) fn is_empty(&self) -> bool {
        self.add.is_empty() && self.remove.is_empty()
    }
}

/// Why a source that has a velocity service is not served. Listed in the stats
/// (`unserved`, with [`Unserved::reason`] and the retry count) for as long as its
/// velocity service exists (a static source: for as long as ghnetd runs).
enum Unserved {
    /// `sources.max_sources` were served when it appeared; it is served as soon as a
    /// slot frees.
    OverLimit,
    /// Its services could not be opened, or a resource it needs is short (the message
    /// names the service and the setting, or the resource); tried again with backoff.
    Failed(Retry),
}

impl Unserved {
    fn reason(&self, max_sources: usize) -> String {
        match self {
            Unserved::OverLimit => format!("sources.max_sources ({max_sources}) reached"),
            Unserved::Failed(r) => r.reason.clone(),
        }
    }

    fn retries(&self) -> u64 {
        match self {
            Unserved::OverLimit => 0,
            Unserved::Failed(r) => r.retries,
        }
    }
}

/// Sources found but not served, reported once each (and again when the reason
/// changes). Forgotten when their velocity service disappears; static ones never.
#[derive(Default)]
pub(crate) struct Roster {
    unserved: BTreeMap<String, Unserved>,
}

impl Roster {
    /// Adds to `changes` the sources that failed to open and whose backoff is over,
    /// as long as `max` (`sources.max_sources`) leaves room (`served` are served now).
    pub(crate) fn retries_due(
        &self,
        now: Instant,
        served: usize,
        max: usize,
        changes: &mut Changes,
    ) {
        let mut after = served - changes.remove.len() + changes.add.len();
        for (name, u) in &self.unserved {
            if after >= max {
                return;
            }
            if let Unserved::Failed(r) = u {
                if r.is_due(now) && !changes.add.contains(name) {
                    changes.add.push(name.clone());
                    after += 1;
                }
            }
        }
    }

    /// Adds to `changes` the `found` velocity services that are not served yet, up to
    /// `sources.max_sources`; forgets unserved sources whose service is gone (a failed
    /// static source stays: it is retried for as long as ghnetd runs).
    /// `is_served` tells a served source; `served` are served once `changes` apply;
    /// `true` when the list of unserved sources changed.
    pub(crate) fn discover(
        &mut self,
        found: BTreeSet<String>,
        statics: &[String],
        is_served: impl Fn(&str) -> bool,
        mut served: usize,
        max: usize,
        changes: &mut Changes,
    ) -> bool {
        let before = self.unserved.len();
        self.unserved
            .retain(|name, _| found.contains(name) || statics.contains(name));
        let mut roster_changed = self.unserved.len() != before;
        for name in found {
            let failed = matches!(self.unserved.get(&name), Some(Unserved::Failed(_)));
            if failed || is_served(&name) {
                continue;
            }
            if served >= max {
                if let Entry::Vacant(e) = self.unserved.entry(name) {
                    warn!(source = %e.key(), max_sources = max, "source ignored: sources.max_sources reached");
                    e.insert(Unserved::OverLimit);
                    roster_changed = true;
                }
                continue;
            }
            served += 1;
            changes.add.push(name);
        }
        roster_changed
    }

    /// Records that `name` could not be opened; warns the first time and when the
    /// reason changes, and schedules the next try.
    pub(crate) fn failed(&mut self, name: String, kind: Kind, reason: String) {
        let what = match kind {
            Kind::Static => "cannot serve static source",
            Kind::Discovered => "cannot serve discovered source",
        };
        match self.unserved.get_mut(&name) {
            Some(Unserved::Failed(r)) => {
                let changed = r.reason != reason;
                r.failed_again(reason, Instant::now());
                match changed {
                    true => {
                        warn!(source = %name, error = %r.reason, retries = r.retries, "{what}")
                    }
                    false => {
                        debug!(source = %name, retries = r.retries, retry_in_ms = r.backoff_ms(), "still cannot serve source")
                    }
                }
            }
            _ => {
                warn!(source = %name, error = %reason, "{what}; retrying with backoff");
                let retry = Retry::new(reason, Instant::now());
                self.unserved.insert(name, Unserved::Failed(retry));
            }
        }
    }

    /// `name` is served now: no longer listed.
    pub(crate) fn served(&mut self, name: &str) {
        if let Some(Unserved::Failed(r)) = self.unserved.remove(name) {
            info!(source = %name, retries = r.retries, "source served after all (was unserved: {})", r.reason);
        }
    }

    /// Name → (reason, retries) of every unserved source (`max`: `sources.max_sources`).
    pub(crate) fn listing(&self, max: usize) -> BTreeMap<String, (String, u64)> {
        (self.unserved.iter())
            .map(|(name, u)| (name.clone(), (u.reason(max), u.retries())))
            .collect()
    }
}
