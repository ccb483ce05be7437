//! The command line. The doc comments below are `ghnet-ros2 --help`.

use anyhow::Context;
use clap::Parser;
use ghnet_client::cli::IpcArgs;

use crate::names::{check_domain_id, check_frame_id, TopicMap};
use crate::{Config, Rmw};

/// Publishes ghnetd's headings to ROS 2: each answer as sensor_msgs/msg/Imu on
/// /ghnet/<source>/heading (node `ghnet`), and diagnostic_msgs/msg/DiagnosticArray
/// on /diagnostics once a second. Source names that are not ROS names map by a
/// fixed rule ('-' → '_', runs of '_' → one, a leading digit gets "s_").
/// Stop with Ctrl-C (SIGINT) or SIGTERM. --service-prefix does not change the ROS
/// topics.
#[derive(Debug, Parser)]
#[command(name = "ghnet-ros2", version)]
pub struct Args {
    /// A source to relay (repeatable). Without it, every source ghnetd serves,
    /// found while running.
    #[arg(long = "source", value_name = "NAME")]
    pub sources: Vec<String>,

    /// ROS domain id, 0 to 232.
    #[arg(long, env = "ROS_DOMAIN_ID", default_value_t = 0, value_name = "N")]
    pub domain_id: u32,

    /// header.frame_id of every Imu: the antenna's tf2 frame.
    #[arg(long, default_value = "gnss", value_name = "ID")]
    pub frame_id: String,

    /// The ROS middleware to speak: dds (rmw_fastrtps_cpp, rmw_cyclonedds_cpp) or
    /// zenoh (rmw_zenoh_cpp, through a router).
    #[arg(long, value_enum, default_value = "dds")]
    pub rmw: Rmw,

    /// The Zenoh router (--rmw zenoh), as rmw_zenoh's default.
    #[arg(long, default_value = "tcp/localhost:7447", value_name = "ENDPOINT")]
    pub zenoh_router: String,

    /// Where ghnetd's services are (`--service-prefix`, the iceoryx2 overrides).
    #[command(flatten)]
    pub ipc: IpcArgs,
}

impl Args {
    /// The run's [`Config`]; errors name the flag at fault.
    pub fn to_config(&self) -> anyhow::Result<Config> {
        let mut topics = TopicMap::default();
        for s in &self.sources {
            ghnet_client::validate_source_name(s).context("--source")?;
            topics.insert(s).context("--source")?;
        }
        check_frame_id(&self.frame_id).context("--frame-id")?;
        Ok(Config {
            sources: self.sources.clone(),
            domain_id: check_domain_id(self.domain_id).context("--domain-id")?,
            frame_id: self.frame_id.clone(),
            rmw: self.rmw,
            zenoh_router: self.zenoh_router.clone(),
            ipc: self.ipc.ipc()?,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn args(line: &[&str]) -> anyhow::Result<Config> {
        Args::try_parse_from([&["ghnet-ros2"], line].concat())?.to_config()
    }

    #[test]
    fn flags_make_a_config() {
        let c = args(&["--source", "a", "--source", "b-1", "--domain-id", "42"]).unwrap();
        assert_eq!(c.sources, ["a", "b-1"]);
        assert_eq!(
            (c.domain_id, c.frame_id.as_str(), c.rmw),
            (42, "gnss", Rmw::Dds)
        );
        assert_eq!(c.zenoh_router, "tcp/localhost:7447");
        let c = args(&["--rmw", "zenoh", "--frame-id", "gnss_antenna"]).unwrap();
        assert!(c.sources.is_empty() && c.rmw == Rmw::Zenoh);
        let err = |line: &[&str]| format!("{:#}", args(line).unwrap_err());
        assert!(err(&["--domain-id", "233"]).starts_with("--domain-id: domain id 233"));
        assert!(err(&["--frame-id", "/gnss"]).starts_with("--frame-id: frame id `/gnss`"));
        assert!(err(&["--source", "a-b", "--source", "a_b"]).contains("both map to"));
        assert!(err(&["--source", "a/b"]).starts_with("--source"));
    }
}
