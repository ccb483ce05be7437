//! Service names and the [`IpcConfig`] every helper takes.
//!
//! Naming scheme (one place, so publisher, daemon and subscriber cannot disagree):
//!
//! | what | iceoryx2 service (pub-sub + event of the same name) | Zenoh key expression |
//! |---|---|---|
//! | input | `<prefix>/<source>/velocity` | — |
//! | output | `<prefix>/<source>/heading` | `<prefix>/<source>/heading` |
//!
//! `<source>`: 1 to [`MAX_SOURCE_LEN`] characters from `A-Z a-z 0-9 _ -`, starting
//! with a letter or digit. No `/` (it separates the levels, and the daemon's
//! discovery parses names back), no `.`, `*`, `$`, `?`, `#` (special in Zenoh key
//! expressions and shell globs).
//!
//! `<prefix>`: one or more `/`-separated segments of the same characters, at most
//! [`MAX_PREFIX_LEN`] bytes in total, no leading, trailing or double `/`.
//! Default [`DEFAULT_PREFIX`] (`ghnet`).

use std::path::PathBuf;

use iceoryx2::config::Config;
use iceoryx2::prelude::*;

use crate::settings::{Message, ServiceSettings, SERVICE_SETTINGS};
use crate::wire::{HeadingEstimate, VelocitySample};

/// The default service prefix.
pub const DEFAULT_PREFIX: &str = "ghnet";
/// Longest accepted source name in bytes.
pub const MAX_SOURCE_LEN: usize = 64;
/// Longest accepted service prefix in bytes (keeps full names far below iceoryx2's
/// 255-byte service-name limit).
pub const MAX_PREFIX_LEN: usize = 128;
/// Last level of the input service name (the payload type says which service it
/// travels on: [`Message::SERVICE_SUFFIX`]).
pub const VELOCITY_SUFFIX: &str = VelocitySample::SERVICE_SUFFIX;
/// Last level of the output service name and Zenoh key.
pub const HEADING_SUFFIX: &str = HeadingEstimate::SERVICE_SUFFIX;

/// A source name or prefix that breaks the naming rules in the [module docs](self).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum NameError {
    /// Source names must not be empty.
    #[error("source name is empty")]
    EmptySource,
    /// Source name longer than [`MAX_SOURCE_LEN`].
    #[error("source name `{0}` is longer than {MAX_SOURCE_LEN} bytes")]
    SourceTooLong(String),
    /// Source name with a character outside `A-Z a-z 0-9 _ -`, or not starting with a
    /// letter or digit.
    #[error(
        "source name `{0}` may only contain A-Z a-z 0-9 _ - and must start with a letter or digit"
    )]
    InvalidSource(String),
    /// Prefix empty, too long, or with a bad segment.
    #[error(
        "service prefix `{0}` must be 1..={MAX_PREFIX_LEN} bytes of `/`-separated segments of A-Z a-z 0-9 _ - (each starting with a letter or digit)"
    )]
    InvalidPrefix(String),
    /// iceoryx2 global prefix (a file-name prefix in `/dev/shm`) rejected.
    #[error("iceoryx2 global prefix `{0}` is not a valid file name")]
    InvalidGlobalPrefix(String),
    /// iceoryx2 root path rejected.
    #[error("iceoryx2 root path `{0}` is not a valid absolute path")]
    InvalidRootPath(String),
}

fn is_valid_segment(s: &str) -> bool {
    let mut chars = s.chars();
    match chars.next() {
        Some(c) if c.is_ascii_alphanumeric() => {}
        _ => return false,
    }
    chars.all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
}

/// Checks a source name against the rules in the [module docs](self).
///
/// ```
/// use ghnet_client::validate_source_name;
/// assert!(validate_source_name("gnss0").is_ok());
/// assert!(validate_source_name("rover_front-1").is_ok());
/// assert!(validate_source_name("a/b").is_err());
/// assert!(validate_source_name("-x").is_err());
/// ```
pub fn validate_source_name(source: &str) -> Result<(), NameError> {
    if source.is_empty() {
        return Err(NameError::EmptySource);
    }
    if source.len() > MAX_SOURCE_LEN {
        return Err(NameError::SourceTooLong(source.to_owned()));
    }
    if !is_valid_segment(source) {
        return Err(NameError::InvalidSource(source.to_owned()));
    }
    Ok(())
}

/// Checks a service prefix against the rules in the [module docs](self).
pub fn validate_prefix(prefix: &str) -> Result<(), NameError> {
    if prefix.is_empty()
        || prefix.len() > MAX_PREFIX_LEN
        || !prefix.split('/').all(is_valid_segment)
    {
        return Err(NameError::InvalidPrefix(prefix.to_owned()));
    }
    Ok(())
}

/// Where ghnet's services live: the service prefix plus, optionally, a private
/// iceoryx2 [`Config`].
///
/// Every helper takes one of these, so a test can move a whole publisher, daemon and
/// subscriber set into its own namespace. Two things separate namespaces:
/// - the service prefix (`ghnet` by default) separates ghnet *service names*;
/// - the iceoryx2 global prefix (file-name prefix in `/dev/shm`) and root path
///   (node and service records, default `/tmp/iceoryx2/`) separate *everything*
///   iceoryx2 creates, including service limits and dead-node cleanup. Tests running
///   in parallel need this: see [`IpcConfig::isolated`].
///
/// Without an override, the process-wide iceoryx2 config is used
/// (`Config::global_config()`, which reads `config/iceoryx2.toml`,
/// `~/.config/iceoryx2/iceoryx2.toml` or `/etc/iceoryx2/iceoryx2.toml`).
#[derive(Debug, Clone)]
pub struct IpcConfig {
    prefix: String,
    iceoryx2: Option<Config>,
    settings: ServiceSettings,
}

impl Default for IpcConfig {
    fn default() -> Self {
        Self {
            prefix: DEFAULT_PREFIX.to_owned(),
            iceoryx2: None,
            settings: SERVICE_SETTINGS,
        }
    }
}

impl IpcConfig {
    /// Service prefix `prefix`, process-wide iceoryx2 config.
    pub fn new(prefix: &str) -> Result<Self, NameError> {
        validate_prefix(prefix)?;
        Ok(Self {
            prefix: prefix.to_owned(),
            ..Self::default()
        })
    }

    /// Default service prefix in a private iceoryx2 namespace: `global_prefix` becomes
    /// the `/dev/shm` file-name prefix and `root_path` the directory for node and
    /// service records. Meant for tests (each test its own pair) and for running two
    /// independent ghnet deployments on one host.
    ///
    /// ```
    /// # use ghnet_client::IpcConfig;
    /// let dir = std::env::temp_dir().join("ghnet-doc-isolated");
    /// let ipc = IpcConfig::isolated("ghnet_doc_", &dir).unwrap();
    /// assert_eq!(ipc.prefix(), "ghnet");
    /// ```
    pub fn isolated(global_prefix: &str, root_path: impl Into<PathBuf>) -> Result<Self, NameError> {
        let cfg = iceoryx2_config(
            Config::default(),
            Some(global_prefix),
            Some(root_path.into()),
        )?;
        Ok(Self::default().with_iceoryx2_config(cfg))
    }

    /// This config with the iceoryx2 overrides a deployment was started with (a
    /// `global.prefix` and a root path), built on the process-wide iceoryx2 config;
    /// unchanged when both are `None`. ghnetd and the bridges all take these two
    /// settings, so the rule for applying them lives here once.
    pub fn with_iceoryx2_overrides(
        self,
        global_prefix: Option<&str>,
        root_path: Option<PathBuf>,
    ) -> Result<Self, NameError> {
        if global_prefix.is_none() && root_path.is_none() {
            return Ok(self);
        }
        let cfg = iceoryx2_config(Config::global_config().clone(), global_prefix, root_path)?;
        Ok(self.with_iceoryx2_config(cfg))
    }

    /// Replaces the service prefix.
    pub fn with_prefix(mut self, prefix: &str) -> Result<Self, NameError> {
        validate_prefix(prefix)?;
        self.prefix = prefix.to_owned();
        Ok(self)
    }

    /// Uses `config` instead of the process-wide iceoryx2 config.
    pub fn with_iceoryx2_config(mut self, config: Config) -> Self {
        self.iceoryx2 = Some(config);
        self
    }

    /// Uses `settings` instead of [`SERVICE_SETTINGS`] when opening or creating
    /// services, e.g. more subscriber slots for many consumers. Settings of an existing
    /// service are minimums: every process of the deployment (publishers, ghnetd with
    /// the matching `ipc.*` keys, consumers) must use the same values, or the one
    /// asking for more than the creator gave gets [`OpenError::Limit`].
    ///
    /// [`OpenError::Limit`]: crate::OpenError::Limit
    pub fn with_settings(mut self, settings: ServiceSettings) -> Self {
        self.settings = settings;
        self
    }

    /// The service settings used to open or create services.
    pub fn settings(&self) -> &ServiceSettings {
        &self.settings
    }

    /// The service prefix.
    pub fn prefix(&self) -> &str {
        &self.prefix
    }

    /// The iceoryx2 config that nodes are created with: the override, else a copy of
    /// the process-wide one, with the subscriber's expired-connection buffer capped
    /// at [`EXPIRED_CONNECTION_BUFFER`].
    pub fn iceoryx2_config(&self) -> Config {
        let mut c = match &self.iceoryx2 {
            Some(c) => c.clone(),
            None => Config::global_config().clone(),
        };
        let ps = &mut c.defaults.publish_subscribe;
        ps.subscriber_expired_connection_buffer = ps
            .subscriber_expired_connection_buffer
            .min(EXPIRED_CONNECTION_BUFFER.max(ps.subscriber_max_borrowed_samples));
        c
    }

    /// `<prefix>/<source>/velocity`, the service a source publishes on.
    pub fn velocity_service(&self, source: &str) -> Result<String, NameError> {
        self.service(source, VELOCITY_SUFFIX)
    }

    /// `<prefix>/<source>/heading`, the service the daemon answers on.
    pub fn heading_service(&self, source: &str) -> Result<String, NameError> {
        self.service(source, HEADING_SUFFIX)
    }

    /// `<prefix>/<source>/heading` as a Zenoh key expression, for the Zenoh output.
    /// Same string as the iceoryx2 service on purpose, so one name finds both.
    pub fn zenoh_heading_key(&self, source: &str) -> Result<String, NameError> {
        self.service(source, HEADING_SUFFIX)
    }

    /// The inverse of [`velocity_service`](Self::velocity_service): the source name if
    /// `service_name` is `<prefix>/<source>/velocity` with a valid source, else `None`.
    /// The daemon's discovery uses it to recognise new sources.
    ///
    /// ```
    /// # use ghnet_client::IpcConfig;
    /// let ipc = IpcConfig::default();
    /// assert_eq!(ipc.source_of_velocity_service("ghnet/gnss0/velocity"), Some("gnss0"));
    /// assert_eq!(ipc.source_of_velocity_service("ghnet/gnss0/heading"), None);
    /// assert_eq!(ipc.source_of_velocity_service("other/gnss0/velocity"), None);
    /// ```
    pub fn source_of_velocity_service<'a>(&self, service_name: &'a str) -> Option<&'a str> {
        let rest = service_name.strip_prefix(self.prefix.as_str())?;
        let rest = rest.strip_prefix('/')?;
        let source = rest.strip_suffix(VELOCITY_SUFFIX)?.strip_suffix('/')?;
        validate_source_name(source).ok()?;
        Some(source)
    }

    fn service(&self, source: &str, suffix: &str) -> Result<String, NameError> {
        validate_source_name(source)?;
        Ok(format!("{}/{}/{}", self.prefix, source, suffix))
    }
}

/// Connections to publishers that went away which a subscriber keeps while it still
/// holds their samples. iceoryx2's default, 128, preallocates about 480 KB of heap
/// per subscriber (in `Subscriber::new`), which would be most of ghnetd's resident
/// memory with many sources. ghnet's receivers copy each sample out and
/// release it at once, so they never hold more than iceoryx2's
/// `subscriber_max_borrowed_samples` (2 by default), which stays the lower bound.
pub const EXPIRED_CONNECTION_BUFFER: usize = 4;

/// Applies the optional global-prefix and root-path overrides to `base`.
///
/// Public because the daemon builds its iceoryx2 config from its own config file with
/// the same rules as [`IpcConfig::isolated`].
pub fn iceoryx2_config(
    mut base: Config,
    global_prefix: Option<&str>,
    root_path: Option<PathBuf>,
) -> Result<Config, NameError> {
    if let Some(p) = global_prefix {
        base.global.prefix = FileName::new(p.as_bytes())
            .map_err(|_| NameError::InvalidGlobalPrefix(p.to_owned()))?;
    }
    if let Some(root) = root_path {
        let s = root.to_string_lossy().into_owned();
        // iceoryx2 joins entries onto the root path; a trailing '/' keeps it a
        // directory in every version.
        let with_slash = if s.ends_with('/') {
            s.clone()
        } else {
            format!("{s}/")
        };
        if !root.is_absolute() {
            return Err(NameError::InvalidRootPath(s));
        }
        let path =
            Path::new(with_slash.as_bytes()).map_err(|_| NameError::InvalidRootPath(s.clone()))?;
        base.global.set_root_path(&path);
    }
    Ok(base)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn source_names() {
        for ok in ["a", "gnss0", "G_1-x", &"x".repeat(MAX_SOURCE_LEN)] {
            assert_eq!(validate_source_name(ok), Ok(()), "{ok}");
        }
        assert_eq!(validate_source_name(""), Err(NameError::EmptySource));
        assert!(matches!(
            validate_source_name(&"x".repeat(MAX_SOURCE_LEN + 1)),
            Err(NameError::SourceTooLong(_))
        ));
        for bad in [
            "a/b", "a.b", "-a", "_a", "a b", "a*", "a$", "a?", "a#", "ä", "a\0",
        ] {
            assert!(
                matches!(validate_source_name(bad), Err(NameError::InvalidSource(_))),
                "{bad:?}"
            );
        }
    }

    #[test]
    fn prefixes() {
        for ok in ["ghnet", "site1/ghnet", "a/b/c", "x-1_y"] {
            assert_eq!(validate_prefix(ok), Ok(()), "{ok}");
        }
        for bad in [
            "",
            "/ghnet",
            "ghnet/",
            "a//b",
            "a b",
            "a.b",
            &"x".repeat(129),
        ] {
            assert!(validate_prefix(bad).is_err(), "{bad:?}");
        }
    }

    #[test]
    fn service_names_and_keys() {
        let ipc = IpcConfig::new("site1/ghnet").unwrap();
        assert_eq!(
            ipc.velocity_service("gnss0").unwrap(),
            "site1/ghnet/gnss0/velocity"
        );
        assert_eq!(
            ipc.heading_service("gnss0").unwrap(),
            "site1/ghnet/gnss0/heading"
        );
        assert_eq!(
            ipc.zenoh_heading_key("gnss0").unwrap(),
            "site1/ghnet/gnss0/heading"
        );
        assert!(ipc.velocity_service("a/b").is_err());
        // Every valid name must be accepted by iceoryx2 too.
        let longest = IpcConfig::new(&"p".repeat(MAX_PREFIX_LEN))
            .unwrap()
            .velocity_service(&"s".repeat(MAX_SOURCE_LEN))
            .unwrap();
        assert!(ServiceName::new(&longest).is_ok());
    }

    #[test]
    fn parse_back() {
        let ipc = IpcConfig::new("site1/ghnet").unwrap();
        assert_eq!(
            ipc.source_of_velocity_service("site1/ghnet/gnss0/velocity"),
            Some("gnss0")
        );
        for other in [
            "site1/ghnet/gnss0/heading",
            "site1/ghnet/a/b/velocity",
            "site1/ghnetx/gnss0/velocity",
            "site1/ghnet//velocity",
            "site1/ghnet/velocity",
            "ghnet/gnss0/velocity",
        ] {
            assert_eq!(ipc.source_of_velocity_service(other), None, "{other}");
        }
        // Round trip for any valid source.
        let name = ipc.velocity_service("x_1-y").unwrap();
        assert_eq!(ipc.source_of_velocity_service(&name), Some("x_1-y"));
    }

    #[test]
    fn isolated_config_sets_prefix_and_root() {
        let ipc = IpcConfig::isolated("ghnet_t_", "/tmp/ghnet-test-root").unwrap();
        let cfg = ipc.iceoryx2_config();
        assert_eq!(cfg.global.prefix.as_bytes(), b"ghnet_t_");
        assert_eq!(cfg.global.root_path().as_bytes(), b"/tmp/ghnet-test-root/");
        assert!(IpcConfig::isolated("a/b", "/tmp/x").is_err());
        assert!(IpcConfig::isolated("ok_", "relative/dir").is_err());
    }
}
