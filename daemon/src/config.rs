//! Configuration: built-in defaults, then a TOML file, then command-line flags.
//!
//! The file is optional; with none, `ghnetd` serves discovered sources with the
//! embedded default model. Unknown keys are errors (a typo must not silently fall
//! back to a default). `ghnetd --print-config` prints the effective result, and
//! `daemon/ghnetd.example.toml` is tested to equal the defaults.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::{bail, Context};
use clap::Parser;
use ghnet_client::{names, IpcConfig, ServiceSettings};
use ghnet_models::Platform;
use serde::{Deserialize, Serialize};

/// Upper bound for `sources.max_sources`: every source is one WaitSet attachment and
/// four iceoryx2 ports; far more than one host's GNSS receivers.
pub const MAX_SOURCES_LIMIT: usize = 1024;

/// The daemon's configuration. Field docs are the documentation of the TOML keys.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
#[serde(deny_unknown_fields, default)]
pub struct Config {
    /// Where the services live.
    pub ipc: IpcSection,
    /// Which sources are served.
    pub sources: SourcesSection,
    /// Which model answers, and its status thresholds.
    pub model: ModelSection,
    /// Per-source history of stateful models.
    pub history: HistorySection,
    /// Periodic counters in the log.
    pub stats: StatsSection,
    /// The Zenoh output, presence token and queryables.
    pub zenoh: ZenohSection,
}

/// `[ipc]`
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct IpcSection {
    /// First level(s) of every service name: `<service_prefix>/<source>/velocity`.
    pub service_prefix: String,
    /// iceoryx2 `global.prefix` override (file-name prefix in `/dev/shm`); unset = the
    /// system iceoryx2 config. Set it (with `iceoryx2_root_path`) to run an isolated
    /// instance, e.g. in tests.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub iceoryx2_global_prefix: Option<String>,
    /// iceoryx2 root path override (node and service records, default `/tmp/iceoryx2/`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub iceoryx2_root_path: Option<PathBuf>,
    /// Publishers per service (ghnetd holds one per heading service; a source one per
    /// velocity service, plus slack for a restarted one next to its dead predecessor).
    /// Like every limit here: a *minimum* when the service already exists, so every
    /// process of the deployment must use the same value (Rust clients:
    /// `ServiceSettings` via `IpcConfig::with_settings`).
    pub max_publishers: usize,
    /// Subscribers per service (ghnetd holds one per velocity service; consumers,
    /// recorders and monitors one each per heading service).
    pub max_subscribers: usize,
    /// Processes (iceoryx2 nodes) that may have one service open at once.
    pub max_nodes: usize,
    /// Messages a subscriber buffers before safe overflow overwrites the oldest (a
    /// slow reader never blocks the publisher; it sees sequence gaps instead).
    pub subscriber_buffer: usize,
}

impl Default for IpcSection {
    fn default() -> Self {
        let s = ghnet_client::SERVICE_SETTINGS;
        Self {
            service_prefix: names::DEFAULT_PREFIX.to_owned(),
            iceoryx2_global_prefix: None,
            iceoryx2_root_path: None,
            max_publishers: s.max_publishers,
            max_subscribers: s.max_subscribers,
            max_nodes: s.max_nodes,
            subscriber_buffer: s.subscriber_buffer_size,
        }
    }
}

impl IpcSection {
    fn validate(&self) -> anyhow::Result<()> {
        for (key, v) in [
            ("ipc.max_publishers", self.max_publishers),
            ("ipc.max_subscribers", self.max_subscribers),
            ("ipc.max_nodes", self.max_nodes),
        ] {
            if !(1..=MAX_SLOTS_LIMIT).contains(&v) {
                bail!("{key}: {v} is outside 1..={MAX_SLOTS_LIMIT}");
            }
        }
        let b = self.subscriber_buffer;
        if !(1..=MAX_SUBSCRIBER_BUFFER).contains(&b) {
            bail!("ipc.subscriber_buffer: {b} is outside 1..={MAX_SUBSCRIBER_BUFFER}");
        }
        Ok(())
    }
}

/// Upper bound of the `ipc.max_*` slot limits: each slot costs shared memory in every
/// service, and far more than one host needs.
pub const MAX_SLOTS_LIMIT: usize = 1024;

/// Upper bound of `ipc.subscriber_buffer` (messages).
pub const MAX_SUBSCRIBER_BUFFER: usize = 65_536;

/// `[sources]`
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SourcesSection {
    /// Sources served from the start and never dropped, even without publishers.
    #[serde(rename = "static")]
    pub static_sources: Vec<String>,
    /// Serve any `<prefix>/<source>/velocity` service that appears while running, and
    /// drop it again when its last publisher is gone.
    pub discovery: bool,
    /// How often to look for new sources, gone publishers and dead processes (ms).
    /// A pass lists the iceoryx2 services only when their directory changed (or
    /// every 5 s), so a short interval costs next to nothing while idle.
    pub discovery_interval_ms: u64,
    /// Most sources served at once (static + discovered); more are logged and ignored.
    pub max_sources: usize,
    /// A source that has sent nothing for longer than this (ms) gets ONE
    /// `HeadingEstimate` with status `Stale` (sequence number and timestamp of its last
    /// sample, heading and σ NaN), so a consumer learns that the silence is not a
    /// stationary vehicle; checked every `discovery_interval_ms`. A discovered source
    /// whose publishers are gone is dropped only after its Stale message. 0 = off.
    pub stale_after_ms: u64,
}

impl Default for SourcesSection {
    fn default() -> Self {
        Self {
            static_sources: Vec::new(),
            discovery: true,
            discovery_interval_ms: 250,
            max_sources: 32,
            stale_after_ms: 2500,
        }
    }
}

impl SourcesSection {
    fn validate(&self) -> anyhow::Result<()> {
        let mut seen = BTreeSet::new();
        for s in &self.static_sources {
            names::validate_source_name(s).context("sources.static")?;
            if !seen.insert(s) {
                bail!("sources.static: source `{s}` is listed twice");
            }
        }
        let si = self.discovery_interval_ms;
        if !(10..=60_000).contains(&si) {
            bail!("sources.discovery_interval_ms: {si} is outside 10..=60000");
        }
        let stale = self.stale_after_ms;
        if stale != 0 && !(10..=3_600_000).contains(&stale) {
            bail!("sources.stale_after_ms: {stale} is outside 10..=3600000 (0 = off)");
        }
        let max = self.max_sources;
        if !(1..=MAX_SOURCES_LIMIT).contains(&max) {
            bail!("sources.max_sources: {max} is outside 1..={MAX_SOURCES_LIMIT}");
        }
        if self.static_sources.len() > max {
            bail!(
                "sources.static: {} sources but sources.max_sources is {max}",
                self.static_sources.len()
            );
        }
        Ok(())
    }
}

/// `[model]`
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ModelSection {
    /// A built-in model (`ghnet-epoch`, `ghnet-temporal`, `kf`, `paper-s1`) or a path to a `.safetensors` file
    /// (relative to the working directory).
    pub name: String,
    /// Below this horizontal speed (m/s) the status is `Stationary`.
    pub stationary_speed: f64,
    /// Above this heading σ (deg) the status is `LowSpeed`.
    pub max_std_deg: f64,
    /// Above this speed (m/s) the input is `InvalidInput` (a receiver glitch, not a
    /// vehicle).
    pub max_speed: f64,
    /// What carries the sources' receivers, for the temporal model: `auto` (decides
    /// online), `car` (reverses, never turns in place) or `robot` (turns in place).
    /// Unset: the model's own default (`auto` for the built-in models).
    pub platform: Option<Platform>,
    /// Per-source overrides of `platform`: source name to platform.
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub platforms: BTreeMap<String, Platform>,
}

impl Default for ModelSection {
    fn default() -> Self {
        let p = ghnet_models::StatusPolicy::default();
        Self {
            name: ghnet_models::DEFAULT_MODEL.to_owned(),
            // Through the f32 Display so 0.05f32 becomes 0.05, not 0.05000000074505806.
            stationary_speed: f32_to_f64(p.stationary_speed),
            max_std_deg: f32_to_f64(p.max_std_deg),
            max_speed: f32_to_f64(p.max_speed),
            platform: None,
            platforms: BTreeMap::new(),
        }
    }
}

impl ModelSection {
    /// The platform of `source`: its override, else `platform`; `None` leaves the
    /// model's own default.
    pub fn platform_of(&self, source: &str) -> Option<Platform> {
        self.platforms.get(source).copied().or(self.platform)
    }
}

impl ModelSection {
    fn validate(&self) -> anyhow::Result<()> {
        if self.name.trim().is_empty() {
            bail!("model.name: empty; use a built-in name (ghnet-epoch, ghnet-temporal, kf, paper-s1) or a .safetensors path");
        }
        for (key, v) in [
            ("model.stationary_speed", self.stationary_speed),
            ("model.max_std_deg", self.max_std_deg),
            ("model.max_speed", self.max_speed),
        ] {
            if !(v.is_finite() && v > 0.0) {
                bail!("{key}: {v} must be a positive number");
            }
        }
        for name in self.platforms.keys() {
            names::validate_source_name(name).context("model.platforms")?;
        }
        if self.stationary_speed >= self.max_speed {
            bail!(
                "model.stationary_speed: {} must be below model.max_speed ({})",
                self.stationary_speed,
                self.max_speed
            );
        }
        Ok(())
    }
}

/// Longest `history.max_gap_s`: beyond an hour a held heading means nothing.
pub const MAX_GAP_LIMIT_S: f64 = 3600.0;

/// `[history]`: how stateful models (`kf`, `ghnet-temporal`) keep each source's
/// history. Per-epoch models keep none and ignore it.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct HistorySection {
    /// A time step longer than this (seconds) clears the source's history (the vehicle
    /// may have turned anywhere meanwhile). Unset: the model's own `max_gap_s` (10 s
    /// for the built-in models). Raise it for receivers that report rarely (below
    /// 0.1 Hz) or lose fixes in tunnels on roads that do not turn; lower it for
    /// platforms that turn in place.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_gap_s: Option<f64>,
}

impl HistorySection {
    fn validate(&self) -> anyhow::Result<()> {
        if let Some(g) = self.max_gap_s {
            if !(g.is_finite() && g > 0.0 && g <= MAX_GAP_LIMIT_S) {
                bail!("history.max_gap_s: {g} must be above 0 and at most {MAX_GAP_LIMIT_S} s");
            }
        }
        Ok(())
    }
}

fn f32_to_f64(v: f32) -> f64 {
    v.to_string().parse().unwrap_or(v as f64)
}

/// `[stats]`
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct StatsSection {
    /// Seconds between per-source counter lines at info level (0..=86400); 0 = never.
    pub interval_s: u64,
}

impl Default for StatsSection {
    fn default() -> Self {
        Self { interval_s: 10 }
    }
}

/// `[zenoh]`
///
/// ghnetd's keys are applied on top of `config_file` (a standard Zenoh json5 config),
/// so the loopback-only defaults hold unless they are changed here; everything
/// without a key here (TLS, ACL, timeouts, ...) comes from the file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ZenohSection {
    /// Publish every heading on Zenoh too, and declare presence and queryables.
    pub enabled: bool,
    /// Zenoh mode: `peer` (default; consumers connect directly), `client` (connect to
    /// a router, listen nowhere) or `router`.
    pub mode: String,
    /// Endpoints to listen on. Loopback only by default; port 0 picks a free port
    /// (the log says which). An empty list listens nowhere.
    pub listen: Vec<String>,
    /// Endpoints to connect to, e.g. a Zenoh router `tcp/10.0.0.1:7447`. Empty: keep
    /// the file's (none without a file).
    pub connect: Vec<String>,
    /// Zenoh multicast scouting (UDP 224.0.0.224:7446). Off: ghnetd announces itself
    /// to nobody.
    pub multicast_scouting: bool,
    /// Zenoh gossip scouting (peers telling each other about peers). Off by default.
    pub gossip: bool,
    /// A standard Zenoh json5 config file for everything else (router connection,
    /// TLS, access control, timeouts). Unset: Zenoh's defaults under the keys above,
    /// except ghnetd's transmit queue ([`ZENOH_TX_DEFAULTS`]); a file's own values rule
    /// instead, so a file should keep them.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub config_file: Option<PathBuf>,
}

impl Default for ZenohSection {
    fn default() -> Self {
        Self {
            enabled: true,
            mode: "peer".to_owned(),
            listen: vec![format!(
                "tcp/127.0.0.1:{}",
                ghnet_client::DEFAULT_ZENOH_PORT
            )],
            connect: Vec::new(),
            multicast_scouting: false,
            gossip: false,
            config_file: None,
        }
    }
}

/// ghnetd's Zenoh transmit queue when no `zenoh.config_file` is given (JSON5 values
/// by config path; a config file replaces them): 16 batches, and up to 50 ms for one
/// to free before a heading is dropped. Why: daemon/README.md, section "Zenoh
/// transmit queue".
pub const ZENOH_TX_DEFAULTS: [(&str, &str); 2] = ghnet_client::ZENOH_TX_QUEUE;

impl ZenohSection {
    fn validate(&self) -> anyhow::Result<()> {
        if !["peer", "client", "router"].contains(&self.mode.as_str()) {
            bail!(
                "zenoh.mode: `{}` is not one of peer, client, router",
                self.mode
            );
        }
        if self.enabled {
            // Parses the file and every endpoint now, so a typo is a start-up error.
            self.zenoh_config()?;
        }
        Ok(())
    }

    /// The Zenoh session config: `config_file` (or Zenoh's defaults), then these keys.
    /// Errors name the key.
    pub fn zenoh_config(&self) -> anyhow::Result<ghnet_client::zenoh::Config> {
        use ghnet_client::zenoh;
        let mut c = match &self.config_file {
            Some(path) => zenoh::Config::from_file(path)
                .map_err(|e| anyhow::anyhow!("zenoh.config_file {}: {e}", path.display()))?,
            None => {
                let mut c = zenoh::Config::default();
                for (key, value) in ZENOH_TX_DEFAULTS {
                    c.insert_json5(key, value)
                        .map_err(|e| anyhow::anyhow!("zenoh default {key}: {e}"))?;
                }
                c
            }
        };
        let set = |c: &mut zenoh::Config, key: &str, what: &str, json: String| {
            c.insert_json5(key, &json)
                .map_err(|e| anyhow::anyhow!("{what}: {json}: {e}"))
        };
        set(&mut c, "mode", "zenoh.mode", format!("\"{}\"", self.mode))?;
        set(
            &mut c,
            "listen/endpoints",
            "zenoh.listen",
            json_list(&self.listen),
        )?;
        if !self.connect.is_empty() || self.config_file.is_none() {
            set(
                &mut c,
                "connect/endpoints",
                "zenoh.connect",
                json_list(&self.connect),
            )?;
        }
        set(
            &mut c,
            "scouting/multicast/enabled",
            "zenoh.multicast_scouting",
            self.multicast_scouting.to_string(),
        )?;
        set(
            &mut c,
            "scouting/gossip/enabled",
            "zenoh.gossip",
            self.gossip.to_string(),
        )?;
        Ok(c)
    }
}

/// A flag that was given replaces the key.
fn set<T: Clone>(key: &mut T, flag: &Option<T>) {
    if let Some(v) = flag {
        *key = v.clone();
    }
}

/// A flag that was given sets an optional key.
fn set_some<T: Clone>(key: &mut Option<T>, flag: &Option<T>) {
    if flag.is_some() {
        key.clone_from(flag);
    }
}

/// A repeatable flag given at least once replaces the whole list.
fn set_list(key: &mut Vec<String>, flag: &[String]) {
    if !flag.is_empty() {
        *key = flag.to_vec();
    }
}

fn json_list(items: &[String]) -> String {
    serde_json::to_string(items).expect("strings always serialise")
}

/// Command-line flags. Every flag overrides the matching config key.
#[derive(Debug, Clone, Default, Parser)]
#[command(
    name = "ghnetd",
    version,
    about = "ghnet heading sidecar: answers GNSS velocity samples on iceoryx2 with heading estimates",
    long_about = "ghnet heading sidecar: reads VelocitySample from <prefix>/<source>/velocity \
                  and answers each with one HeadingEstimate on <prefix>/<source>/heading.\n\n\
                  Precedence: built-in defaults < --config file < flags. Logging: RUST_LOG \
                  (default info, Zenoh's gossip-disabled warning off). SIGINT/SIGTERM: \
                  answer what is buffered, release iceoryx2 resources, exit 0."
)]
pub struct Cli {
    /// TOML config file; without one the built-in defaults apply.
    #[arg(long, short = 'c', env = "GHNETD_CONFIG", value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Print the effective config as TOML and exit.
    #[arg(long)]
    pub print_config: bool,
    /// ipc.service_prefix: first level(s) of the service names.
    #[arg(long, value_name = "PREFIX")]
    pub service_prefix: Option<String>,
    /// ipc.iceoryx2_global_prefix: iceoryx2 /dev/shm file prefix (isolated instances).
    #[arg(long, value_name = "PREFIX")]
    pub iceoryx2_global_prefix: Option<String>,
    /// ipc.iceoryx2_root_path: iceoryx2 root directory (isolated instances).
    #[arg(long, value_name = "DIR")]
    pub iceoryx2_root_path: Option<PathBuf>,
    /// ipc.max_publishers: publisher slots per service (all processes must agree).
    #[arg(long, value_name = "N")]
    pub max_publishers: Option<usize>,
    /// ipc.max_subscribers: subscriber slots per service (all processes must agree).
    #[arg(long, value_name = "N")]
    pub max_subscribers: Option<usize>,
    /// ipc.max_nodes: processes per service (all processes must agree).
    #[arg(long, value_name = "N")]
    pub max_nodes: Option<usize>,
    /// ipc.subscriber_buffer: messages buffered per subscriber (all processes must agree).
    #[arg(long, value_name = "N")]
    pub subscriber_buffer: Option<usize>,
    /// sources.static: serve this source from the start (repeatable; replaces the
    /// file's list).
    #[arg(long = "source", value_name = "NAME")]
    pub sources: Vec<String>,
    /// sources.discovery: serve sources that appear while running.
    #[arg(long, value_name = "BOOL", num_args = 1)]
    pub discovery: Option<bool>,
    /// sources.discovery_interval_ms: discovery and liveness period.
    #[arg(long, value_name = "MS")]
    pub discovery_interval_ms: Option<u64>,
    /// sources.max_sources: most sources served at once.
    #[arg(long, value_name = "N")]
    pub max_sources: Option<usize>,
    /// sources.stale_after_ms: silence after which a source gets one Stale message,
    /// 0 = off.
    #[arg(long, value_name = "MS")]
    pub stale_after_ms: Option<u64>,
    /// model.name: built-in model name or .safetensors path.
    #[arg(long, value_name = "NAME|PATH")]
    pub model: Option<String>,
    /// model.stationary_speed (m/s).
    #[arg(long, value_name = "M_PER_S")]
    pub stationary_speed: Option<f64>,
    /// model.max_std_deg (deg).
    #[arg(long, value_name = "DEG")]
    pub max_std_deg: Option<f64>,
    /// model.max_speed (m/s).
    #[arg(long, value_name = "M_PER_S")]
    pub max_speed: Option<f64>,
    /// model.platform: auto, car or robot (every source without an override).
    #[arg(long, value_name = "PLATFORM")]
    pub platform: Option<Platform>,
    /// model.platforms: one source's platform, as SOURCE=PLATFORM (repeatable).
    #[arg(long, value_name = "SOURCE=PLATFORM", value_parser = parse_source_platform)]
    pub source_platform: Vec<(String, Platform)>,
    /// history.max_gap_s: a longer time step clears a source's history (stateful
    /// models; default: the model's own limit).
    #[arg(long, value_name = "S")]
    pub history_max_gap_s: Option<f64>,
    /// stats.interval_s: seconds between counter log lines, 0 = never.
    #[arg(long, value_name = "S")]
    pub stats_interval_s: Option<u64>,
    /// zenoh.enabled: also publish headings on Zenoh.
    #[arg(long = "zenoh", value_name = "BOOL", num_args = 1)]
    pub zenoh_enabled: Option<bool>,
    /// zenoh.mode: peer, client or router.
    #[arg(long, value_name = "MODE")]
    pub zenoh_mode: Option<String>,
    /// zenoh.listen: Zenoh endpoint to listen on, e.g. tcp/127.0.0.1:7447 (repeatable;
    /// replaces the file's list).
    #[arg(long = "zenoh-listen", value_name = "ENDPOINT")]
    pub zenoh_listen: Vec<String>,
    /// zenoh.connect: Zenoh endpoint to connect to, e.g. a router (repeatable).
    #[arg(long = "zenoh-connect", value_name = "ENDPOINT")]
    pub zenoh_connect: Vec<String>,
    /// zenoh.config_file: standard Zenoh json5 config for everything else (TLS, ACL,
    /// router); ghnetd's zenoh keys still apply on top.
    #[arg(long = "zenoh-config", value_name = "FILE")]
    pub zenoh_config: Option<PathBuf>,
}

impl Config {
    /// Parses TOML text (unknown keys are errors).
    ///
    /// Errors are one line that names the place: `line 2 ([sources] discovery =
    /// "yes"): invalid type: string "yes", expected a boolean`. toml's own message
    /// says what is wrong but not which key (a wrong type points at the value), and its
    /// `Display` spans several lines, so the line's section and text are quoted here.
    pub fn from_toml(text: &str) -> anyhow::Result<Self> {
        toml::from_str(text).map_err(|e| {
            let msg = e.message().replace(['\n', '\r'], " ");
            // `get`, not indexing: a span is a byte range and must never panic here.
            match e.span().and_then(|span| text.get(..span.start)) {
                Some(before) => {
                    let line = before.matches('\n').count() + 1;
                    // The lines before this one (the span may start mid-line).
                    let above = &before[..before.rfind('\n').unwrap_or(0)];
                    let section = above
                        .lines()
                        .rev()
                        .map(str::trim)
                        .find(|l| l.starts_with('['));
                    let quoted: String = text
                        .lines()
                        .nth(line - 1)
                        .unwrap_or_default()
                        .trim()
                        .chars()
                        .take(80)
                        .collect();
                    let place = match section {
                        Some(s) if !quoted.starts_with('[') => format!("{s} {quoted}"),
                        _ => quoted,
                    };
                    anyhow::anyhow!("line {line} ({place}): {msg}")
                }
                None => anyhow::anyhow!(msg),
            }
        })
    }

    /// Reads and parses a TOML file.
    pub fn from_file(path: &Path) -> anyhow::Result<Self> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("cannot read config file {}", path.display()))?;
        Self::from_toml(&text).with_context(|| format!("config file {}", path.display()))
    }

    /// Defaults, then `cli.config` if given, then the flags; validated.
    pub fn from_cli(cli: &Cli) -> anyhow::Result<Self> {
        let mut cfg = match &cli.config {
            Some(path) => Self::from_file(path)?,
            None => Self::default(),
        };
        cfg.apply_flags(cli);
        cfg.validate()?;
        Ok(cfg)
    }

    /// Overrides keys with the flags that were given.
    pub fn apply_flags(&mut self, cli: &Cli) {
        set(&mut self.ipc.service_prefix, &cli.service_prefix);
        set_some(
            &mut self.ipc.iceoryx2_global_prefix,
            &cli.iceoryx2_global_prefix,
        );
        set_some(&mut self.ipc.iceoryx2_root_path, &cli.iceoryx2_root_path);
        set(&mut self.ipc.max_publishers, &cli.max_publishers);
        set(&mut self.ipc.max_subscribers, &cli.max_subscribers);
        set(&mut self.ipc.max_nodes, &cli.max_nodes);
        set(&mut self.ipc.subscriber_buffer, &cli.subscriber_buffer);
        set_list(&mut self.sources.static_sources, &cli.sources);
        set(&mut self.sources.discovery, &cli.discovery);
        set(
            &mut self.sources.discovery_interval_ms,
            &cli.discovery_interval_ms,
        );
        set(&mut self.sources.max_sources, &cli.max_sources);
        set(&mut self.sources.stale_after_ms, &cli.stale_after_ms);
        set(&mut self.model.name, &cli.model);
        set(&mut self.model.stationary_speed, &cli.stationary_speed);
        set(&mut self.model.max_std_deg, &cli.max_std_deg);
        set(&mut self.model.max_speed, &cli.max_speed);
        set_some(&mut self.model.platform, &cli.platform);
        self.model
            .platforms
            .extend(cli.source_platform.iter().cloned());
        set_some(&mut self.history.max_gap_s, &cli.history_max_gap_s);
        set(&mut self.stats.interval_s, &cli.stats_interval_s);
        set(&mut self.zenoh.enabled, &cli.zenoh_enabled);
        set(&mut self.zenoh.mode, &cli.zenoh_mode);
        set_list(&mut self.zenoh.listen, &cli.zenoh_listen);
        set_list(&mut self.zenoh.connect, &cli.zenoh_connect);
        set_some(&mut self.zenoh.config_file, &cli.zenoh_config);
    }

    /// Checks every value; the error names the key to fix. (The model file is checked
    /// when it is loaded.)
    pub fn validate(&self) -> anyhow::Result<()> {
        names::validate_prefix(&self.ipc.service_prefix).context("ipc.service_prefix")?;
        // Builds the iceoryx2 config, which checks prefix and root path.
        self.ipc_config()?;
        if let Some(root) = &self.ipc.iceoryx2_root_path {
            check_root_path(root).context("ipc.iceoryx2_root_path")?;
        }
        self.ipc.validate()?;
        self.check_shared_memory()?;
        self.sources.validate()?;
        if self.stats.interval_s > 86_400 {
            bail!(
                "stats.interval_s: {} is above one day (86400)",
                self.stats.interval_s
            );
        }
        self.model.validate()?;
        self.history.validate()?;
        self.zenoh.validate()
    }

    /// The `ipc.*` settings are allowed up to far more than a host has shared memory
    /// for (every service of every source reserves its slots and buffers): refuses
    /// settings whose one source would not fit in the whole of /dev/shm, saying how
    /// much they need, rather than let the first source end in SIGBUS.
    fn check_shared_memory(&self) -> anyhow::Result<()> {
        let need = crate::pressure::shm_per_source(self);
        let dir = std::path::Path::new(crate::pressure::SHM_DIR);
        match crate::pressure::fs_size(dir) {
            Some(size) if need > size => bail!(
                "ipc.max_publishers / max_subscribers / max_nodes / subscriber_buffer: one source needs about {need} bytes of shared memory with these values, more than {} holds ({size} bytes)",
                dir.display()
            ),
            _ => Ok(()),
        }
    }

    /// The client-side view: service prefix plus the iceoryx2 config with overrides
    /// applied on top of the system iceoryx2 config.
    pub fn ipc_config(&self) -> anyhow::Result<IpcConfig> {
        let i = &self.ipc;
        let ipc = IpcConfig::new(&i.service_prefix)
            .context("ipc.service_prefix")?
            .with_settings(ServiceSettings::with_limits(
                i.max_publishers,
                i.max_subscribers,
                i.max_nodes,
                i.subscriber_buffer,
            ));
        ipc.with_iceoryx2_overrides(
            i.iceoryx2_global_prefix.as_deref(),
            i.iceoryx2_root_path.clone(),
        )
        .context("ipc.iceoryx2_global_prefix / ipc.iceoryx2_root_path")
    }

    /// The model's status thresholds.
    pub fn status_policy(&self) -> ghnet_models::StatusPolicy {
        ghnet_models::StatusPolicy {
            stationary_speed: self.model.stationary_speed as f32,
            max_std_deg: self.model.max_std_deg as f32,
            max_speed: self.model.max_speed as f32,
        }
    }

    /// `sources.discovery_interval_ms` as a duration.
    pub fn discovery_interval(&self) -> Duration {
        Duration::from_millis(self.sources.discovery_interval_ms)
    }

    /// `sources.stale_after_ms` as a duration, `None` when disabled.
    pub fn stale_after(&self) -> Option<Duration> {
        (self.sources.stale_after_ms > 0)
            .then(|| Duration::from_millis(self.sources.stale_after_ms))
    }

    /// `stats.interval_s` as a duration, `None` when disabled.
    pub fn stats_interval(&self) -> Option<Duration> {
        (self.stats.interval_s > 0).then(|| Duration::from_secs(self.stats.interval_s))
    }

    /// The effective config as TOML (what `--print-config` prints).
    pub fn to_toml(&self) -> String {
        toml::to_string_pretty(self).expect("the config always serialises")
    }
}

/// Refuses an iceoryx2 root path ghnetd must not own: ghnetd writes its lock file,
/// node and service records there and makes it owner-only, so `/`, a pseudo
/// filesystem, a file, another user's directory or a world-writable directory without
/// the sticky bit (anyone could replace ghnetd's records) are configuration errors,
/// reported before anything is created. A path that does not exist yet is created.
fn check_root_path(root: &std::path::Path) -> anyhow::Result<()> {
    use std::os::unix::fs::MetadataExt;
    let shown = root.display();
    let canonical = root.canonicalize().unwrap_or_else(|_| root.to_owned());
    if canonical == std::path::Path::new("/") {
        bail!("`{shown}` is the filesystem root; use a directory of its own, e.g. /tmp/iceoryx2");
    }
    for pseudo in ["/proc", "/sys", "/dev"] {
        if canonical.starts_with(pseudo) {
            bail!("`{shown}` is under {pseudo}, not a directory ghnetd may own");
        }
    }
    let meta = match std::fs::metadata(&canonical) {
        Ok(m) => m,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(()),
        Err(e) => bail!("`{shown}`: {e}"),
    };
    if !meta.is_dir() {
        bail!("`{shown}` is not a directory");
    }
    // SAFETY: geteuid cannot fail and touches no memory.
    let me = unsafe { libc::geteuid() };
    if meta.uid() != me {
        bail!(
            "`{shown}` is owned by uid {}, not by this user (uid {me})",
            meta.uid()
        );
    }
    let mode = meta.mode();
    if mode & 0o002 != 0 && mode & 0o1000 == 0 {
        bail!(
            "`{shown}` is world-writable without the sticky bit (mode {:o})",
            mode & 0o7777
        );
    }
    Ok(())
}

/// `SOURCE=PLATFORM` of `--source-platform`.
fn parse_source_platform(s: &str) -> Result<(String, Platform), String> {
    let (name, platform) = s
        .split_once('=')
        .ok_or_else(|| format!("`{s}` is not SOURCE=PLATFORM"))?;
    Ok((name.to_owned(), platform.parse()?))
}

#[cfg(test)]
mod tests {
    use super::*;

    const EXAMPLE: &str = include_str!("../ghnetd.example.toml");

    #[test]
    fn example_file_equals_defaults_and_print_config() {
        let example = Config::from_toml(EXAMPLE).expect("example parses");
        assert_eq!(example, Config::default());
        // Same keys and values as --print-config, so a new key must be added to the
        // example (optional keys may appear there commented out).
        let printed: toml::Table = toml::from_str(&Config::default().to_toml()).unwrap();
        let shipped: toml::Table = toml::from_str(EXAMPLE).unwrap();
        assert_eq!(printed, shipped);
    }

    #[test]
    fn print_config_round_trips() {
        let mut c = Config::default();
        c.ipc.iceoryx2_global_prefix = Some("t_".into());
        c.ipc.iceoryx2_root_path = Some("/tmp/x".into());
        c.sources.static_sources = vec!["a".into(), "b".into()];
        c.model.max_speed = 55.5;
        assert_eq!(Config::from_toml(&c.to_toml()).unwrap(), c);
        assert!(Config::default()
            .to_toml()
            .contains("stationary_speed = 0.05\n"));
    }

    #[test]
    fn empty_file_is_defaults_and_partial_file_merges() {
        assert_eq!(Config::from_toml("").unwrap(), Config::default());
        let c = Config::from_toml("[sources]\nstatic = [\"gnss0\"]\n").unwrap();
        assert_eq!(c.sources.static_sources, vec!["gnss0"]);
        assert!(c.sources.discovery, "unset keys keep their defaults");
        assert_eq!(c.model, ModelSection::default());
    }

    #[test]
    fn unknown_keys_are_rejected_with_line() {
        let err = Config::from_toml("[sources]\ndiscovery = true\ndiscovry_interval_ms = 5\n")
            .unwrap_err()
            .to_string();
        assert!(err.contains("line 3"), "{err}");
        assert!(err.contains("discovry_interval_ms"), "{err}");
        assert!(!err.contains('\n'), "one line: {err}");
        assert!(Config::from_toml("[nope]\n").is_err());
        assert!(Config::from_toml("[model]\nname = 3\n").is_err());
    }

    fn cli(args: &[&str]) -> Cli {
        Cli::try_parse_from(std::iter::once("ghnetd").chain(args.iter().copied())).unwrap()
    }

    #[test]
    fn flags_override_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("g.toml");
        std::fs::write(
            &path,
            "[sources]\nstatic = [\"a\", \"b\"]\ndiscovery_interval_ms = 300\n[model]\nmax_speed = 80.0\n",
        )
        .unwrap();
        let p = path.to_str().unwrap();

        let c = Config::from_cli(&cli(&["-c", p])).unwrap();
        assert_eq!(c.sources.static_sources, vec!["a", "b"]);
        assert_eq!(c.sources.discovery_interval_ms, 300);
        assert_eq!(c.model.max_speed, 80.0);

        let c = Config::from_cli(&cli(&[
            "-c",
            p,
            "--source",
            "x",
            "--source",
            "y",
            "--discovery",
            "false",
            "--max-speed",
            "70",
            "--service-prefix",
            "site1/ghnet",
            "--stats-interval-s",
            "0",
            "--model",
            "paper-s1",
        ]))
        .unwrap();
        assert_eq!(c.sources.static_sources, vec!["x", "y"]);
        assert!(!c.sources.discovery);
        assert_eq!(c.sources.discovery_interval_ms, 300, "file value kept");
        assert_eq!(c.model.max_speed, 70.0);
        assert_eq!(c.model.name, "paper-s1");
        assert_eq!(c.ipc.service_prefix, "site1/ghnet");
        assert_eq!(c.stats_interval(), None);
        assert_eq!(c.history.max_gap_s, None, "unset: the model's own");
        let c = Config::from_cli(&cli(&["--history-max-gap-s", "30"])).unwrap();
        assert_eq!(c.history.max_gap_s, Some(30.0));

        // No file at all: defaults.
        assert_eq!(Config::from_cli(&cli(&[])).unwrap(), Config::default());
    }

    #[test]
    fn missing_file_error_names_the_file() {
        let err = Config::from_cli(&cli(&["-c", "/nonexistent/ghnetd.toml"])).unwrap_err();
        let msg = format!("{err:#}");
        assert!(msg.contains("/nonexistent/ghnetd.toml"), "{msg}");
        assert!(!msg.contains('\n'), "{msg}");
    }

    fn invalid(f: impl FnOnce(&mut Config)) -> String {
        let mut c = Config::default();
        f(&mut c);
        let msg = format!("{:#}", c.validate().unwrap_err());
        assert!(!msg.contains('\n'), "one line: {msg}");
        msg
    }

    #[test]
    fn validation_names_the_key() {
        assert!(invalid(|c| c.ipc.service_prefix = "/x".into()).starts_with("ipc.service_prefix"));
        assert!(invalid(|c| c.sources.static_sources = vec!["a/b".into()])
            .starts_with("sources.static"));
        assert!(
            invalid(|c| c.sources.static_sources = vec!["a".into(), "a".into()]).contains("twice")
        );
        assert!(invalid(|c| c.sources.discovery_interval_ms = 0)
            .starts_with("sources.discovery_interval_ms"));
        assert!(invalid(|c| c.sources.max_sources = 0).starts_with("sources.max_sources"));
        assert!(invalid(|c| c.sources.stale_after_ms = 5).starts_with("sources.stale_after_ms"));
        assert!(invalid(|c| c.ipc.max_subscribers = 0).starts_with("ipc.max_subscribers"));
        assert!(invalid(|c| c.ipc.max_publishers = 5000).starts_with("ipc.max_publishers"));
        assert!(invalid(|c| c.ipc.max_nodes = 0).starts_with("ipc.max_nodes"));
        assert!(invalid(|c| c.ipc.subscriber_buffer = 0).starts_with("ipc.subscriber_buffer"));
        assert!(invalid(|c| {
            c.sources.max_sources = 1;
            c.sources.static_sources = vec!["a".into(), "b".into()];
        })
        .contains("max_sources"));
        assert!(invalid(|c| c.model.max_speed = f64::NAN).starts_with("model.max_speed"));
        for bad in [0.0, -1.0, f64::INFINITY, 3601.0] {
            assert!(invalid(|c| c.history.max_gap_s = Some(bad)).starts_with("history.max_gap_s"));
        }
        assert!(invalid(|c| c.model.max_std_deg = -1.0).starts_with("model.max_std_deg"));
        assert!(invalid(|c| c.model.stationary_speed = 200.0).starts_with("model.stationary_speed"));
        assert!(invalid(|c| c.model.name = " ".into()).starts_with("model.name"));
        assert!(invalid(|c| c.stats.interval_s = 100_000).starts_with("stats.interval_s"));
        assert!(invalid(|c| c.zenoh.mode = "server".into()).starts_with("zenoh.mode"));
        assert!(invalid(|c| c.zenoh.listen = vec!["nonsense".into()]).starts_with("zenoh.listen"));
        assert!(
            invalid(|c| c.zenoh.config_file = Some("/nonexistent.json5".into()))
                .starts_with("zenoh.config_file")
        );
        assert!(
            invalid(|c| c.ipc.iceoryx2_root_path = Some("relative".into()))
                .contains("iceoryx2_root_path")
        );
        assert!(
            invalid(|c| c.ipc.iceoryx2_global_prefix = Some("a/b".into()))
                .contains("iceoryx2_global_prefix")
        );
        Config::default().validate().unwrap();
    }

    #[test]
    fn zenoh_flags_and_loopback_defaults() {
        let c = Config::default().zenoh.zenoh_config().unwrap();
        assert_eq!(c.get_json("scouting/multicast/enabled").unwrap(), "false");
        assert_eq!(c.get_json("scouting/gossip/enabled").unwrap(), "false");
        assert!(c
            .get_json("listen/endpoints")
            .unwrap()
            .contains("tcp/127.0.0.1:7447"));
        // ghnetd's deeper transmit queue without a file; a file's own values rule.
        assert_eq!(
            c.get_json("transport/link/tx/queue/size/data").unwrap(),
            "16"
        );
        let wait = "transport/link/tx/queue/congestion_control/drop/wait_before_drop";
        assert_eq!(c.get_json(wait).unwrap(), "50000");
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("z.json5");
        std::fs::write(&file, "{ mode: \"peer\" }").unwrap();
        let section = ZenohSection {
            config_file: Some(file),
            ..ZenohSection::default()
        };
        let zenoh_default = ghnet_client::zenoh::Config::default();
        assert_eq!(
            section.zenoh_config().unwrap().get_json(wait).unwrap(),
            zenoh_default.get_json(wait).unwrap()
        );
        let c = Config::from_cli(&cli(&[
            "--zenoh",
            "false",
            "--zenoh-mode",
            "client",
            "--zenoh-listen",
            "tcp/127.0.0.1:0",
            "--zenoh-connect",
            "tcp/127.0.0.1:7448",
        ]))
        .unwrap();
        assert!(!c.zenoh.enabled);
        assert_eq!(c.zenoh.mode, "client");
        assert_eq!(c.zenoh.listen, vec!["tcp/127.0.0.1:0"]);
        assert_eq!(c.zenoh.connect, vec!["tcp/127.0.0.1:7448"]);
    }

    #[test]
    fn ipc_limits_reach_the_client_settings() {
        let c = Config::from_cli(&cli(&[
            "--max-subscribers",
            "12",
            "--max-publishers",
            "3",
            "--max-nodes",
            "20",
            "--subscriber-buffer",
            "64",
            "--stale-after-ms",
            "0",
        ]))
        .unwrap();
        let s = *c.ipc_config().unwrap().settings();
        assert_eq!(s, ServiceSettings::with_limits(3, 12, 20, 64));
        assert_eq!((s.max_notifiers, s.max_listeners), (3, 12));
        assert_eq!(c.stale_after(), None);
        assert_eq!(
            *Config::default().ipc_config().unwrap().settings(),
            ghnet_client::SERVICE_SETTINGS,
            "defaults are the client's"
        );
        assert_eq!(
            Config::default().stale_after(),
            Some(Duration::from_millis(2500))
        );
    }

    #[test]
    fn policy_matches_model_defaults() {
        assert_eq!(
            Config::default().status_policy(),
            ghnet_models::StatusPolicy::default()
        );
    }
}
