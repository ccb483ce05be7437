//! Configuration: built-in defaults, then a TOML file, then command-line flags.
//!
//! Every key is defined once, as a field of its section struct: its type, its doc
//! (the TOML key's documentation and the flag's `--help`), its flag and its default
//! (`#[arg(...)]`) all sit on that field. serde reads the TOML file into the same
//! structs clap fills from the command line, and [`Config::with_flags`] lays the keys
//! a flag gave over the file's; the defaults are what clap fills in when no flag is
//! given, so `Default` and `--help` cannot disagree.
//!
//! The file is optional; with none, `ghnetd` serves discovered sources with the
//! embedded default model. Unknown keys are errors (a typo must not silently fall
//! back to a default). `ghnetd --print-config` prints the effective result;
//! `daemon/ghnetd.example.toml` and the table in `daemon/README.md` are tested to name
//! every key with its default.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;
use std::path::PathBuf;
use std::time::Duration;

use anyhow::{bail, Context};
use clap::{ArgAction, ArgMatches, FromArgMatches};
use ghnet_client::{names, IpcConfig, ServiceSettings, SERVICE_SETTINGS};
use ghnet_inference::Platform;
use serde::{Deserialize, Serialize};

use crate::{host, layering};

/// Upper bound for `sources.max_sources`: every source is one WaitSet attachment and
/// four iceoryx2 ports; far more than one host's GNSS receivers.
pub const MAX_SOURCES_LIMIT: usize = 1024;

/// The daemon's configuration: one section per TOML table, each key a field whose
/// doc is the key's documentation and whose `#[arg]` is its flag and default.
///
/// `clap::Args` so a command line can flatten it (every key becomes its flag, with
/// the key as the argument id, e.g. `ipc.max_publishers`), serde for the TOML file
/// and `--print-config`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default, clap::Args)]
#[serde(deny_unknown_fields, default)]
pub struct Config {
    /// Where the services live.
    #[command(flatten)]
    pub ipc: IpcSection,
    /// Which sources are served.
    #[command(flatten)]
    pub sources: SourcesSection,
    /// Which model answers, and its status thresholds.
    #[command(flatten)]
    pub model: ModelSection,
    /// Per-source history of stateful models.
    #[command(flatten)]
    pub history: HistorySection,
    /// Periodic counters in the log.
    #[command(flatten)]
    pub stats: StatsSection,
    /// The Zenoh output, presence token and queryables.
    #[command(flatten)]
    pub zenoh: ZenohSection,
}

/// `[ipc]`: service names and the iceoryx2 limits every process must share.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, clap::Args)]
#[serde(deny_unknown_fields, default)]
#[command(next_help_heading = "[ipc]")]
pub struct IpcSection {
    /// ipc.service_prefix: first level(s) of the service names.
    ///
    /// `<service_prefix>/<source>/velocity` and `.../heading`.
    #[arg(id = "ipc.service_prefix", long = "service-prefix", value_name = "PREFIX",
          default_value_t = names::DEFAULT_PREFIX.to_owned())]
    pub service_prefix: String,
    /// ipc.iceoryx2_global_prefix: iceoryx2 /dev/shm file prefix (isolated instances).
    ///
    /// Unset: the system iceoryx2 config. Set it (with `iceoryx2_root_path`) to run
    /// an isolated instance, e.g. in tests.
    #[serde(skip_serializing_if = "Option::is_none")]
    #[arg(
        id = "ipc.iceoryx2_global_prefix",
        long = "iceoryx2-global-prefix",
        value_name = "PREFIX"
    )]
    pub iceoryx2_global_prefix: Option<String>,
    /// ipc.iceoryx2_root_path: iceoryx2 root directory (isolated instances).
    ///
    /// Node and service records; the system default is `/tmp/iceoryx2/`.
    #[serde(skip_serializing_if = "Option::is_none")]
    #[arg(
        id = "ipc.iceoryx2_root_path",
        long = "iceoryx2-root-path",
        value_name = "DIR"
    )]
    pub iceoryx2_root_path: Option<PathBuf>,
    /// ipc.max_publishers: publisher slots per service (all processes must agree).
    ///
    /// ghnetd holds one per heading service; a source one per velocity service, plus
    /// slack for a restarted one next to its dead predecessor. Like every limit here:
    /// a *minimum* when the service already exists, so every process of the
    /// deployment must use the same value (Rust clients: `ServiceSettings` via
    /// `IpcConfig::with_settings`).
    #[arg(id = "ipc.max_publishers", long = "max-publishers", value_name = "N",
          default_value_t = SERVICE_SETTINGS.max_publishers)]
    pub max_publishers: usize,
    /// ipc.max_subscribers: subscriber slots per service (all processes must agree).
    ///
    /// ghnetd holds one per velocity service; consumers, recorders and monitors one
    /// each per heading service.
    #[arg(id = "ipc.max_subscribers", long = "max-subscribers", value_name = "N",
          default_value_t = SERVICE_SETTINGS.max_subscribers)]
    pub max_subscribers: usize,
    /// ipc.max_nodes: processes per service (all processes must agree).
    ///
    /// Processes (iceoryx2 nodes) that may have one service open at once.
    #[arg(id = "ipc.max_nodes", long = "max-nodes", value_name = "N",
          default_value_t = SERVICE_SETTINGS.max_nodes)]
    pub max_nodes: usize,
    /// ipc.subscriber_buffer: messages buffered per subscriber (all processes must agree).
    ///
    /// When full, safe overflow overwrites the oldest (a slow reader never blocks the
    /// publisher; it sees sequence gaps instead).
    #[arg(id = "ipc.subscriber_buffer", long = "subscriber-buffer", value_name = "N",
          default_value_t = SERVICE_SETTINGS.subscriber_buffer_size)]
    pub subscriber_buffer: usize,
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

    /// Shared memory one source's services take with these limits, in bytes (the
    /// model and its measurements: `host::shm_need`).
    pub(crate) fn shm_per_source(&self) -> u64 {
        host::shm_need(
            self.max_publishers as u64,
            self.max_subscribers as u64,
            self.max_nodes as u64,
            self.subscriber_buffer as u64,
        )
    }
}

/// Upper bound of the `ipc.max_*` slot limits: each slot costs shared memory in every
/// service, and far more than one host needs.
pub const MAX_SLOTS_LIMIT: usize = 1024;

/// Upper bound of `ipc.subscriber_buffer` (messages).
pub const MAX_SUBSCRIBER_BUFFER: usize = 65_536;

/// `[sources]`: which sources are served, and how they are found and watched.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, clap::Args)]
#[serde(deny_unknown_fields, default)]
#[command(next_help_heading = "[sources]")]
pub struct SourcesSection {
    /// sources.static: serve this source from the start (repeatable; replaces the
    /// file's list).
    ///
    /// Static sources are never dropped, even without publishers.
    #[serde(rename = "static")]
    #[arg(id = "sources.static", long = "source", value_name = "NAME")]
    pub static_sources: Vec<String>,
    /// sources.discovery: serve sources that appear while running.
    ///
    /// Serves any `<prefix>/<source>/velocity` service that appears, and drops it
    /// again when its last publisher is gone.
    #[arg(id = "sources.discovery", long = "discovery", value_name = "BOOL",
          num_args = 1, action = ArgAction::Set, default_value_t = true)]
    pub discovery: bool,
    /// sources.discovery_interval_ms: discovery and liveness period.
    ///
    /// How often to look for new sources, gone publishers and dead processes. A pass
    /// lists the iceoryx2 services only when their directory changed (or every 5 s),
    /// so a short interval costs next to nothing while idle.
    #[arg(
        id = "sources.discovery_interval_ms",
        long = "discovery-interval-ms",
        value_name = "MS",
        default_value_t = 250
    )]
    pub discovery_interval_ms: u64,
    /// sources.max_sources: most sources served at once.
    ///
    /// Static + discovered; more are logged and ignored.
    #[arg(
        id = "sources.max_sources",
        long = "max-sources",
        value_name = "N",
        default_value_t = 32
    )]
    pub max_sources: usize,
    /// sources.stale_after_ms: silence after which a source gets one Stale message,
    /// 0 = off.
    ///
    /// A source that has sent nothing for longer than this gets ONE `HeadingEstimate`
    /// with status `Stale` (sequence number and timestamp of its last sample, heading
    /// and σ NaN), so a consumer learns that the silence is not a stationary vehicle;
    /// checked every `discovery_interval_ms`. A discovered source whose publishers
    /// are gone is dropped only after its Stale message.
    #[arg(
        id = "sources.stale_after_ms",
        long = "stale-after-ms",
        value_name = "MS",
        default_value_t = 2500
    )]
    pub stale_after_ms: u64,
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

/// `[model]`: which model answers, its status thresholds and the sources' platforms.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, clap::Args)]
#[serde(deny_unknown_fields, default)]
#[command(next_help_heading = "[model]")]
pub struct ModelSection {
    /// model.name: built-in model name or .safetensors path.
    ///
    /// Built-in: `ghnet-epoch`, `ghnet-temporal`, `kf`, `paper-s1`; a path is
    /// relative to the working directory.
    #[arg(id = "model.name", long = "model", value_name = "NAME|PATH",
          default_value_t = ghnet_inference::DEFAULT_MODEL.to_owned())]
    pub name: String,
    /// model.stationary_speed (m/s): below this horizontal speed the status is
    /// `Stationary`.
    #[arg(id = "model.stationary_speed", long = "stationary-speed", value_name = "M_PER_S",
          default_value_t = f32_to_f64(ghnet_inference::StatusPolicy::default().stationary_speed))]
    pub stationary_speed: f64,
    /// model.max_std_deg (deg): above this heading σ the status is `LowSpeed`.
    #[arg(id = "model.max_std_deg", long = "max-std-deg", value_name = "DEG",
          default_value_t = f32_to_f64(ghnet_inference::StatusPolicy::default().max_std_deg))]
    pub max_std_deg: f64,
    /// model.max_speed (m/s): above this speed the input is `InvalidInput` (a
    /// receiver glitch, not a vehicle).
    #[arg(id = "model.max_speed", long = "max-speed", value_name = "M_PER_S",
          default_value_t = f32_to_f64(ghnet_inference::StatusPolicy::default().max_speed))]
    pub max_speed: f64,
    /// model.platform: auto, car or robot (every source without an override).
    ///
    /// What carries the sources' receivers, for the temporal model: `auto` (decides
    /// online), `car` (reverses, never turns in place) or `robot` (turns in place).
    /// Unset: the model's own default (`auto` for the built-in models).
    #[arg(id = "model.platform", long = "platform", value_name = "PLATFORM")]
    pub platform: Option<Platform>,
    /// Per-source overrides of `platform` (`[model.platforms]`, `--source-platform`).
    #[serde(skip_serializing_if = "Platforms::is_empty")]
    #[command(flatten)]
    pub platforms: Platforms,
}

impl ModelSection {
    /// The platform of `source`: its override, else `platform`; `None` leaves the
    /// model's own default.
    pub fn platform_of(&self, source: &str) -> Option<Platform> {
        self.platforms.0.get(source).copied().or(self.platform)
    }

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
        for name in self.platforms.0.keys() {
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

/// `model.platforms`: source name to platform, overriding `model.platform` per
/// source. In TOML a `[model.platforms]` table; on the command line
/// `--source-platform SOURCE=PLATFORM`, repeatable, each adding to the file's table
/// (a map has no derived flag, so this type says how clap fills it).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(transparent)]
pub struct Platforms(pub BTreeMap<String, Platform>);

impl Platforms {
    /// The flag's argument id: the key, like every other flag's.
    const ID: &'static str = "model.platforms";

    /// Whether no source has an override.
    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }
}

impl clap::FromArgMatches for Platforms {
    fn from_arg_matches(matches: &ArgMatches) -> Result<Self, clap::Error> {
        let given = matches.get_many::<(String, Platform)>(Self::ID);
        Ok(Self(given.into_iter().flatten().cloned().collect()))
    }

    fn update_from_arg_matches(&mut self, matches: &ArgMatches) -> Result<(), clap::Error> {
        self.0.extend(Self::from_arg_matches(matches)?.0);
        Ok(())
    }
}

impl clap::Args for Platforms {
    fn augment_args(cmd: clap::Command) -> clap::Command {
        cmd.arg(
            clap::Arg::new(Self::ID)
                .long("source-platform")
                .value_name("SOURCE=PLATFORM")
                .action(ArgAction::Append)
                .value_parser(parse_source_platform)
                .help("model.platforms: one source's platform, as SOURCE=PLATFORM (repeatable)"),
        )
    }

    fn augment_args_for_update(cmd: clap::Command) -> clap::Command {
        Self::augment_args(cmd)
    }
}

/// Longest `history.max_gap_s`: beyond an hour a held heading means nothing.
pub const MAX_GAP_LIMIT_S: f64 = 3600.0;

/// `[history]`: how stateful models (`kf`, `ghnet-temporal`) keep each source's
/// history. Per-epoch models keep none and ignore it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, clap::Args)]
#[serde(deny_unknown_fields, default)]
#[command(next_help_heading = "[history]")]
pub struct HistorySection {
    /// history.max_gap_s: a longer time step clears a source's history (stateful
    /// models; default: the model's own limit).
    ///
    /// In seconds (the vehicle may have turned anywhere meanwhile). Unset: the
    /// model's own `max_gap_s` (10 s for the built-in models). Raise it for receivers
    /// that report rarely (below 0.1 Hz) or lose fixes in tunnels on roads that do not
    /// turn; lower it for platforms that turn in place.
    #[serde(skip_serializing_if = "Option::is_none")]
    #[arg(id = "history.max_gap_s", long = "history-max-gap-s", value_name = "S")]
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

/// `[stats]`: the periodic counter lines in the log.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, clap::Args)]
#[serde(deny_unknown_fields, default)]
#[command(next_help_heading = "[stats]")]
pub struct StatsSection {
    /// stats.interval_s: seconds between counter log lines, 0 = never.
    ///
    /// Per-source counter lines at info level, 0..=86400.
    #[arg(
        id = "stats.interval_s",
        long = "stats-interval-s",
        value_name = "S",
        default_value_t = 10
    )]
    pub interval_s: u64,
}

/// `[zenoh]`: the Zenoh output, presence token and queryables.
///
/// ghnetd's keys are applied on top of `config_file` (a standard Zenoh json5 config),
/// so the loopback-only defaults hold unless they are changed here; everything
/// without a key here (TLS, ACL, timeouts, ...) comes from the file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, clap::Args)]
#[serde(deny_unknown_fields, default)]
#[command(next_help_heading = "[zenoh]")]
pub struct ZenohSection {
    /// zenoh.enabled: also publish headings on Zenoh.
    ///
    /// Every heading, plus the presence token and the queryables.
    #[arg(id = "zenoh.enabled", long = "zenoh", value_name = "BOOL", num_args = 1,
          action = ArgAction::Set, default_value_t = true)]
    pub enabled: bool,
    /// zenoh.mode: peer, client or router.
    ///
    /// `peer` (consumers connect directly), `client` (connect to a router, listen
    /// nowhere) or `router`.
    #[arg(id = "zenoh.mode", long = "zenoh-mode", value_name = "MODE",
          default_value_t = String::from("peer"))]
    pub mode: String,
    /// zenoh.listen: Zenoh endpoint to listen on, e.g. tcp/127.0.0.1:7447 (repeatable;
    /// replaces the file's list).
    ///
    /// Loopback only by default; port 0 picks a free port (the log says which). An
    /// empty list (in the file) listens nowhere.
    #[arg(id = "zenoh.listen", long = "zenoh-listen", value_name = "ENDPOINT",
          default_values_t = [format!("tcp/127.0.0.1:{}", ghnet_client::DEFAULT_ZENOH_PORT)])]
    pub listen: Vec<String>,
    /// zenoh.connect: Zenoh endpoint to connect to, e.g. a router (repeatable).
    ///
    /// E.g. a Zenoh router `tcp/10.0.0.1:7447`. Empty: keep the file's (none without
    /// a file).
    #[arg(id = "zenoh.connect", long = "zenoh-connect", value_name = "ENDPOINT")]
    pub connect: Vec<String>,
    /// Zenoh multicast scouting (UDP 224.0.0.224:7446). Off: ghnetd announces itself
    /// to nobody. No flag: a file key only.
    #[arg(skip = false)]
    pub multicast_scouting: bool,
    /// Zenoh gossip scouting (peers telling each other about peers). Off by default.
    /// No flag: a file key only.
    #[arg(skip = false)]
    pub gossip: bool,
    /// zenoh.config_file: standard Zenoh json5 config for everything else (TLS, ACL,
    /// router); ghnetd's zenoh keys still apply on top.
    ///
    /// Unset: Zenoh's defaults under the keys above, except ghnetd's transmit queue
    /// (`ghnet_client::ZENOH_TX_QUEUE`; why: daemon/README.md, "Zenoh transmit
    /// queue"); a file's own values rule instead, so a file should keep them.
    #[serde(skip_serializing_if = "Option::is_none")]
    #[arg(id = "zenoh.config_file", long = "zenoh-config", value_name = "FILE")]
    pub config_file: Option<PathBuf>,
}

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
                for (key, value) in ghnet_client::ZENOH_TX_QUEUE {
                    c.insert_json5(key, value)
                        .map_err(|e| anyhow::anyhow!("zenoh default {key}: {e}"))?;
                }
                c
            }
        };
        let connect = !self.connect.is_empty() || self.config_file.is_none();
        let keys = [
            Some(("mode", "zenoh.mode", format!("\"{}\"", self.mode))),
            Some(("listen/endpoints", "zenoh.listen", json_list(&self.listen))),
            connect.then(|| {
                (
                    "connect/endpoints",
                    "zenoh.connect",
                    json_list(&self.connect),
                )
            }),
            Some((
                "scouting/multicast/enabled",
                "zenoh.multicast_scouting",
                self.multicast_scouting.to_string(),
            )),
            Some((
                "scouting/gossip/enabled",
                "zenoh.gossip",
                self.gossip.to_string(),
            )),
        ];
        for (path, key, json) in keys.into_iter().flatten() {
            c.insert_json5(path, &json)
                .map_err(|e| anyhow::anyhow!("{key}: {json}: {e}"))?;
        }
        Ok(c)
    }
}

fn json_list(items: &[String]) -> String {
    serde_json::to_string(items).expect("strings always serialise")
}

impl Config {
    /// Parses TOML text (unknown keys are errors); an error is one line naming the
    /// line, its section and its text.
    pub fn from_toml(text: &str) -> anyhow::Result<Self> {
        layering::parse(text)
    }

    /// Reads and parses a TOML file.
    pub fn from_file(path: &Path) -> anyhow::Result<Self> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("cannot read config file {}", path.display()))?;
        Self::from_toml(&text).with_context(|| format!("config file {}", path.display()))
    }

    /// The effective config of one start: `file` if given (else the defaults), then
    /// the keys the command line gave ([`with_flags`](Self::with_flags)); validated.
    pub fn load(file: Option<&Path>, matches: &ArgMatches) -> anyhow::Result<Self> {
        let base = match file {
            Some(path) => Self::from_file(path)?,
            None => Self::default(),
        };
        let cfg = base.with_flags(matches)?;
        cfg.validate()?;
        Ok(cfg)
    }

    /// This config with every key a flag (or its environment variable) gave replaced
    /// by that value. `matches` come from a command that flattens [`Config`], whose
    /// argument ids are the keys. A list flag replaces the list; a table flag
    /// (`--source-platform`) adds its entries to the table.
    pub fn with_flags(&self, matches: &ArgMatches) -> anyhow::Result<Self> {
        let flags = toml::Table::try_from(Self::from_arg_matches(matches)?)
            .context("command-line flags")?;
        let base = toml::Table::try_from(self).expect("the config always serialises");
        let merged = layering::overlay(base, &flags, matches);
        merged.try_into().context("command-line flags")
    }

    /// Checks every value, and that the host can hold what the `ipc.*` settings ask
    /// for; the error names the key to fix. (The model file is checked when it is
    /// loaded.)
    pub fn validate(&self) -> anyhow::Result<()> {
        names::validate_prefix(&self.ipc.service_prefix).context("ipc.service_prefix")?;
        // Builds the iceoryx2 config, which checks prefix and root path.
        self.ipc_config()?;
        if let Some(root) = &self.ipc.iceoryx2_root_path {
            host::check_root_path(root).context("ipc.iceoryx2_root_path")?;
        }
        self.ipc.validate()?;
        // The `ipc.*` settings are allowed up to far more than a host has shared
        // memory for: refuse settings whose one source would not fit in the whole of
        // /dev/shm rather than let the first source end in SIGBUS.
        host::check_shm_fits(self.ipc.shm_per_source())
            .context("ipc.max_publishers / max_subscribers / max_nodes / subscriber_buffer")?;
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
    pub fn status_policy(&self) -> ghnet_inference::StatusPolicy {
        ghnet_inference::StatusPolicy {
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

/// Each section's `Default` is what clap fills in when no flag is given, so each
/// default is written once, on its field's `#[arg]`.
macro_rules! defaults_from_clap {
    ($($section:ty),*) => {$(
        impl Default for $section {
            fn default() -> Self {
                clap_defaults()
            }
        }
    )*};
}
defaults_from_clap!(
    IpcSection,
    SourcesSection,
    ModelSection,
    HistorySection,
    StatsSection,
    ZenohSection
);

/// A section with every key at its default (see `defaults_from_clap`).
fn clap_defaults<T: clap::Args + FromArgMatches>() -> T {
    let cmd = T::augment_args(clap::Command::new("ghnetd").no_binary_name(true));
    let matches = cmd
        .try_get_matches_from(std::iter::empty::<String>())
        .expect("no key is required");
    T::from_arg_matches(&matches).expect("every default parses")
}

/// Through the f32 `Display`, so 0.05f32 becomes 0.05, not 0.05000000074505806.
fn f32_to_f64(v: f32) -> f64 {
    v.to_string().parse().unwrap_or(v as f64)
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
    use clap::{Arg, Args, Command};

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

    /// `ghnetd ARGS` as the binary loads it: `-c FILE`, then the keys' flags.
    fn load(args: &[&str]) -> anyhow::Result<Config> {
        let cmd = Config::augment_args(Command::new("ghnetd").arg(Arg::new("config").short('c')));
        let argv = std::iter::once("ghnetd").chain(args.iter().copied());
        let matches = cmd.try_get_matches_from(argv).unwrap();
        let file = matches.get_one::<String>("config").map(Path::new);
        Config::load(file, &matches)
    }

    /// `text` as a config file in a fresh directory (kept while the guard lives).
    fn config_file(text: &str) -> (tempfile::TempDir, String) {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("g.toml");
        std::fs::write(&path, text).unwrap();
        let path = path.to_str().unwrap().to_owned();
        (dir, path)
    }

    #[test]
    fn flags_override_file() {
        let (_dir, p) = config_file(
            "[sources]\nstatic = [\"a\", \"b\"]\ndiscovery_interval_ms = 300\n[model]\nmax_speed = 80.0\n",
        );
        let p = p.as_str();

        let c = load(&["-c", p]).unwrap();
        assert_eq!(c.sources.static_sources, vec!["a", "b"]);
        assert_eq!(c.sources.discovery_interval_ms, 300);
        assert_eq!(c.model.max_speed, 80.0);

        let c = load(&[
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
        ])
        .unwrap();
        assert_eq!(c.sources.static_sources, vec!["x", "y"]);
        assert!(!c.sources.discovery);
        assert_eq!(c.sources.discovery_interval_ms, 300, "file value kept");
        assert_eq!(c.model.max_speed, 70.0);
        assert_eq!(c.model.name, "paper-s1");
        assert_eq!(c.ipc.service_prefix, "site1/ghnet");
        assert_eq!(c.stats_interval(), None);
        assert_eq!(c.history.max_gap_s, None, "unset: the model's own");
        let c = load(&["--history-max-gap-s", "30"]).unwrap();
        assert_eq!(c.history.max_gap_s, Some(30.0));

        // No file at all: defaults.
        assert_eq!(load(&[]).unwrap(), Config::default());
    }

    /// Every key of the definition: its flag (`None`: a file key only) and its
    /// default as TOML (`None`: unset, or an empty table).
    fn definition() -> BTreeMap<String, (Option<String>, Option<toml::Value>)> {
        let defaults = toml::Table::try_from(Config::default()).unwrap();
        let mut keys = BTreeMap::new();
        for arg in Config::augment_args(Command::new("ghnetd")).get_arguments() {
            let long = arg.get_long().map(|l| format!("--{l}"));
            keys.insert(arg.get_id().to_string(), (long, None));
        }
        for (section, table) in &defaults {
            for (key, value) in table.as_table().unwrap() {
                keys.entry(format!("{section}.{key}"))
                    .or_insert((None, None))
                    .1 = Some(value.clone());
            }
        }
        assert!(keys.keys().all(|k| k.contains('.')), "{keys:?}");
        keys
    }

    #[test]
    fn readme_table_names_every_key_with_its_flag_and_default() {
        let readme = include_str!("../README.md");
        let section = readme.split("\n## Configuration\n").nth(1).unwrap();
        let section = section.split("\n## ").next().unwrap();
        let mut rows = BTreeMap::new();
        for line in section.lines().filter(|l| l.starts_with("| `")) {
            let cols: Vec<&str> = line.split(" | ").collect();
            rows.insert(
                cols[0].trim_start_matches("| ").trim_matches('`'),
                (cols[1], cols[2]),
            );
        }
        let keys = definition();
        assert_eq!(
            rows.keys().copied().collect::<Vec<_>>(),
            keys.keys().map(String::as_str).collect::<Vec<_>>(),
            "README table keys"
        );
        for (key, (flag, default)) in &keys {
            let (flag_col, default_col) = rows[key.as_str()];
            match flag {
                Some(f) => assert!(flag_col.contains(&format!("`{f}")), "{key}: {flag_col}"),
                None => assert_eq!(flag_col, "–", "{key}"),
            }
            let shown = match default {
                Some(toml::Value::String(s)) => format!("`{s}`"),
                Some(v) => format!("`{v}`"),
                None if default_col.starts_with("`{}`") => "`{}`".to_owned(),
                None => "unset".to_owned(),
            };
            assert!(
                default_col.starts_with(&shown),
                "{key}: {default_col} vs {shown}"
            );
        }
    }

    #[test]
    fn example_file_names_every_key() {
        let mut seen = BTreeSet::new();
        let mut section = String::new();
        for line in EXAMPLE.lines() {
            if let Some(name) = line.strip_prefix('[').and_then(|l| l.strip_suffix(']')) {
                section = name.to_owned();
                continue;
            }
            let text = line.trim_start_matches("# ");
            if let Some(table) = text.strip_prefix('[').and_then(|l| l.strip_suffix(']')) {
                seen.insert(table.to_owned());
            } else if let Some((key, _)) = text.split_once(" = ") {
                seen.insert(format!("{section}.{key}"));
            }
        }
        for key in definition().keys() {
            assert!(seen.contains(key), "{key} missing from ghnetd.example.toml");
        }
    }

    #[test]
    fn clap_and_serde_agree_on_every_default() {
        assert_eq!(load(&[]).unwrap(), Config::from_toml("").unwrap());
        let c = Config::default();
        assert_eq!(
            c.ipc.max_subscribers,
            ghnet_client::SERVICE_SETTINGS.max_subscribers
        );
        assert_eq!(c.model.name, ghnet_inference::DEFAULT_MODEL);
        assert_eq!(c.zenoh.listen, vec!["tcp/127.0.0.1:7447"]);
        assert!(c.sources.discovery && c.zenoh.enabled && !c.zenoh.gossip);
    }

    #[test]
    fn source_platform_flags_add_to_the_files_table() {
        let text = "[model]\nplatform = \"car\"\n[model.platforms]\na = \"robot\"\nb = \"car\"\n";
        let (_dir, p) = config_file(text);
        let p = p.as_str();
        let c = load(&[
            "-c",
            p,
            "--source-platform",
            "b=robot",
            "--source-platform",
            "c=auto",
        ]);
        let c = c.unwrap();
        assert_eq!(c.model.platform_of("a"), Some(Platform::Robot));
        assert_eq!(
            c.model.platform_of("b"),
            Some(Platform::Robot),
            "the flag wins"
        );
        assert_eq!(c.model.platform_of("c"), Some(Platform::Auto));
        assert_eq!(c.model.platform_of("z"), Some(Platform::Car));
        let c = load(&[
            "--zenoh",
            "false",
            "--discovery",
            "false",
            "--max-speed",
            "70",
        ])
        .unwrap();
        assert!(!c.zenoh.enabled && !c.sources.discovery);
        assert_eq!(c.model.max_speed, 70.0);
    }

    #[test]
    fn missing_file_error_names_the_file() {
        let err = load(&["-c", "/nonexistent/ghnetd.toml"]).unwrap_err();
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
        let c = load(&[
            "--zenoh",
            "false",
            "--zenoh-mode",
            "client",
            "--zenoh-listen",
            "tcp/127.0.0.1:0",
            "--zenoh-connect",
            "tcp/127.0.0.1:7448",
        ])
        .unwrap();
        assert!(!c.zenoh.enabled);
        assert_eq!(c.zenoh.mode, "client");
        assert_eq!(c.zenoh.listen, vec!["tcp/127.0.0.1:0"]);
        assert_eq!(c.zenoh.connect, vec!["tcp/127.0.0.1:7448"]);
    }

    #[test]
    fn ipc_limits_reach_the_client_settings() {
        let c = load(&[
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
        ])
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
            ghnet_inference::StatusPolicy::default()
        );
    }
}
