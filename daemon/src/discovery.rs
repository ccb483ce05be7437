//! Finding sources: which `<prefix>/<source>/velocity` services exist, and when it
//! is worth looking.

use std::collections::BTreeSet;
use std::path::PathBuf;
use std::time::{Duration, Instant, SystemTime};

use ghnet_client::iceoryx2::config::Config as IoxConfig;
use ghnet_client::iceoryx2::prelude::*;
use ghnet_client::iceoryx2::service::static_config::messaging_pattern::MessagingPattern;
use ghnet_client::names::VELOCITY_SUFFIX;
use ghnet_client::{validate_source_name, IpcConfig};
use tracing::warn;

/// The sources of every velocity service under the iceoryx2 root: publish-subscribe
/// services named `<prefix>/<source>/velocity` with a valid source name. Services of
/// that shape whose source name breaks the naming rules are reported to `bad` (logged
/// once each).
pub(crate) fn velocity_sources(
    iox_config: &IoxConfig,
    ipc: &IpcConfig,
    bad: &mut BadNames,
) -> anyhow::Result<BTreeSet<String>> {
    let mut found = BTreeSet::new();
    ipc::Service::list(iox_config, |details| {
        if let MessagingPattern::PublishSubscribe(_) = details.static_details.messaging_pattern() {
            let name = details.static_details.name().as_str();
            if let Some(source) = ipc.source_of_velocity_service(name) {
                found.insert(source.to_owned());
            } else if let Some(source) = velocity_shaped(ipc, name) {
                bad.report(source);
            }
        }
        CallbackProgression::Continue
    })
    .map_err(|e| anyhow::anyhow!("cannot list iceoryx2 services: {e:?}"))?;
    Ok(found)
}

/// The part between `<prefix>/` and `/velocity` of `service`, whatever it is.
fn velocity_shaped<'a>(ipc: &IpcConfig, service: &'a str) -> Option<&'a str> {
    service
        .strip_prefix(ipc.prefix())?
        .strip_prefix('/')?
        .strip_suffix(VELOCITY_SUFFIX)?
        .strip_suffix('/')
}

/// Source names seen that break the naming rules: each is logged once, at warn, with
/// the rule it breaks, then ignored (not every discovery pass).
#[derive(Default)]
pub(crate) struct BadNames(BTreeSet<String>);

impl BadNames {
    fn report(&mut self, source: &str) {
        if self.0.contains(source) {
            return;
        }
        let rule = match validate_source_name(source) {
            Err(e) => e.to_string(),
            // Valid as a name but not a single level (e.g. `a/b`).
            Ok(()) => format!("source name `{source}` is not one level of the service name"),
        };
        warn!(source = %source.escape_debug(), rule = %rule, "velocity service ignored: its source name breaks the naming rules");
        self.0.insert(source.to_owned());
    }
}

/// Tells a discovery pass whether listing the iceoryx2 services can find anything.
///
/// Listing opens and parses the static config of every service under the root, far
/// more than anything else an idle ghnetd does. A new service always creates a file
/// in the services directory, which changes the directory's mtime, so a pass lists
/// only when:
/// - the mtime changed since the last listing (a service appeared or went away);
/// - the mtime is younger than [`Self::TRUST_AFTER`]: file times are coarse (one
///   kernel tick), so a file created in the same tick just after a listing would not
///   change it;
/// - [`Self::FULL_LIST_EVERY`] passed: a publisher that comes back to a service that
///   still exists (held open by another process) creates no file.
pub(crate) struct ServiceDirWatch {
    dir: PathBuf,
    mtime: Option<SystemTime>,
    listed_at: Option<Instant>,
}

impl ServiceDirWatch {
    const TRUST_AFTER: Duration = Duration::from_millis(100);
    const FULL_LIST_EVERY: Duration = Duration::from_secs(5);

    pub(crate) fn new(iox_config: &IoxConfig) -> Self {
        Self::of(iox_config.global.service_dir().to_string().into())
    }

    fn of(dir: PathBuf) -> Self {
        Self {
            dir,
            mtime: None,
            listed_at: None,
        }
    }

    /// True when a listing is due now; then records the state it saw.
    pub(crate) fn due(&mut self, now: Instant) -> bool {
        let mtime = std::fs::metadata(&self.dir).and_then(|m| m.modified()).ok();
        self.should_list(now, mtime, SystemTime::now())
    }

    /// [`due`](Self::due) with the clocks and the directory's mtime passed in, so
    /// tests decide how much time has passed.
    fn should_list(&mut self, now: Instant, mtime: Option<SystemTime>, wall: SystemTime) -> bool {
        let young = mtime
            .and_then(|m| wall.duration_since(m).ok())
            .is_none_or(|age| age < Self::TRUST_AFTER);
        let periodic = self
            .listed_at
            .is_none_or(|at| now.duration_since(at) >= Self::FULL_LIST_EVERY);
        if mtime.is_none() || mtime != self.mtime || young || periodic {
            self.mtime = mtime;
            self.listed_at = Some(now);
            true
        } else {
            false
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn service_dir_watch_lists_on_change_young_mtime_and_periodically() {
        let mut w = ServiceDirWatch::of("unused".into());
        let (t0, wall0) = (
            Instant::now(),
            SystemTime::UNIX_EPOCH + Duration::from_secs(1e9 as u64),
        );
        let ms = Duration::from_millis;
        let made = Some(wall0);
        assert!(w.should_list(t0, made, wall0), "first pass lists");
        // The directory was just changed: its mtime is too young to trust.
        assert!(w.should_list(t0 + ms(50), made, wall0 + ms(50)));
        // The young passes listed everything up to a time long after the mtime's
        // tick, so an old, unchanged mtime means nothing new.
        assert!(
            !w.should_list(t0 + ms(150), made, wall0 + ms(150)),
            "nothing changed: no listing"
        );
        let changed = Some(wall0 + ms(160));
        assert!(
            w.should_list(t0 + ms(300), changed, wall0 + ms(300)),
            "a new service file lists"
        );
        assert!(!w.should_list(t0 + ms(400), changed, wall0 + ms(400)));
        assert!(
            w.should_list(
                t0 + ms(300) + ServiceDirWatch::FULL_LIST_EVERY,
                changed,
                wall0 + ms(5300)
            ),
            "a full listing every FULL_LIST_EVERY regardless"
        );
        // A missing directory (no service yet) always lists.
        assert!(w.should_list(t0 + ms(5400), None, wall0 + ms(5400)));
        assert!(w.should_list(t0 + ms(5500), None, wall0 + ms(5500)));
        // A clock set back (mtime in the future) counts as young: list.
        assert!(w.should_list(t0 + ms(5600), changed, wall0));
    }
}
