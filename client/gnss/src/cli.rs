//! The command line. The doc comments below are `ghnet-gnss --help`.

use std::time::Duration;

use anyhow::Context;
use clap::Parser;
use ghnet_client::cli::IpcArgs;
use ghnet_receivers::Format;

use crate::{Backoff, Config, Input, Output};

/// Feeds a GNSS receiver to ghnetd: one velocity sample per receiver epoch.
///
/// INPUT is a recorded log (replayed), a serial device (/dev/ttyACM0, /dev/ttyUSB0,
/// /dev/serial/by-id/...), tcp://HOST:PORT (a raw UBX or NMEA stream) or
/// gpsd://HOST:PORT (gpsd's JSON; the port defaults to 2947). The protocol (u-blox UBX NAV-PVT, NMEA 0183
/// RMC/VTG, gpsd TPV) is detected unless --format says it. Live inputs that go away
/// are reopened with backoff. Stop with Ctrl-C (SIGINT) or SIGTERM; a summary line
/// (samples published, input skipped by reason) is logged at the end.
#[derive(Debug, Parser)]
#[command(name = "ghnet-gnss", version)]
pub struct Args {
    /// Source name: the services are <SERVICE_PREFIX>/<SOURCE>/velocity (in) and
    /// .../heading (ghnetd's answers). Letters, digits, '_' and '-'.
    #[arg(long)]
    pub source: String,

    /// The receiver: a file, a serial device, tcp://HOST:PORT or gpsd://HOST:PORT.
    pub input: String,

    /// Protocol of the input; detected from the first epoch when not given.
    #[arg(long, value_name = "ubx|nmea|gpsd")]
    pub format: Option<Format>,

    /// Serial line speed in bit/s (makes INPUT a serial device). Default 9600;
    /// u-blox F9 UARTs default to 38400, old NMEA receivers to 4800; USB devices
    /// ignore it.
    #[arg(long)]
    pub baud: Option<u32>,

    /// Replay pace of a file: 1 = as recorded, 10 = ten times faster, 0 = each sample
    /// as soon as ghnetd answered the previous one.
    #[arg(long, default_value_t = 1.0, value_name = "X")]
    pub replay_speed: f64,

    /// 1-sigma speed accuracy in m/s to send with NMEA and gpsd epochs, which carry
    /// none (u-blox NAV-PVT sends its own sAcc). Default: unknown (NaN).
    #[arg(long, value_name = "M_PER_S")]
    pub speed_accuracy: Option<f32>,

    /// Print the samples as CSV on stdout instead of publishing them (to check a
    /// receiver without ghnetd).
    #[arg(long)]
    pub print: bool,

    /// Where ghnetd's services are (`--service-prefix`, the iceoryx2 overrides).
    #[command(flatten)]
    pub ipc: IpcArgs,

    /// Seconds a replay waits for ghnetd to subscribe before sending anyway.
    #[arg(long, default_value_t = 30.0, value_name = "SECONDS")]
    pub wait_for_daemon: f64,

    /// Seconds a replay waits for ghnetd's answer (each one at --replay-speed 0, the
    /// last one otherwise) before going on.
    #[arg(long, default_value_t = 5.0, value_name = "SECONDS")]
    pub answer_timeout: f64,

    /// Longest wait in seconds between attempts to reopen a lost receiver (waits
    /// start at 0.1 s and double).
    #[arg(long, default_value_t = 5.0, value_name = "SECONDS")]
    pub max_backoff: f64,
}

impl Args {
    /// The run's [`Config`]; errors name the flag at fault.
    pub fn to_config(&self) -> anyhow::Result<Config> {
        ghnet_client::validate_source_name(&self.source).context("--source")?;
        let input = Input::parse(&self.input, self.baud).context("INPUT")?;
        let seconds = |v: f64, flag: &str| {
            Duration::try_from_secs_f64(v)
                .with_context(|| format!("{flag}: {v} is not a number of seconds"))
        };
        if !(self.replay_speed >= 0.0 && self.replay_speed.is_finite()) {
            anyhow::bail!("--replay-speed: {} (expected 0 or more)", self.replay_speed);
        }
        if let Some(a) = self.speed_accuracy.filter(|a| !(*a > 0.0 && a.is_finite())) {
            anyhow::bail!("--speed-accuracy: {a} (expected a positive number of m/s)");
        }
        let backoff = Backoff {
            max: seconds(self.max_backoff, "--max-backoff")?,
            ..Backoff::default()
        };
        Ok(Config {
            source: self.source.clone(),
            input,
            format: self.format,
            replay_speed: self.replay_speed,
            speed_accuracy: self.speed_accuracy,
            output: if self.print {
                Output::Print
            } else {
                Output::Publish(Box::new(self.ipc.ipc()?))
            },
            wait_for_daemon: seconds(self.wait_for_daemon, "--wait-for-daemon")?,
            answer_timeout: seconds(self.answer_timeout, "--answer-timeout")?,
            backoff,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn args(line: &[&str]) -> anyhow::Result<Config> {
        Args::try_parse_from([&["ghnet-gnss"], line].concat())?.to_config()
    }

    #[test]
    fn flags_make_a_config() {
        let c = args(&[
            "--source",
            "gnss0",
            "--format",
            "nmea",
            "--baud",
            "4800",
            "/dev/ttyUSB0",
        ])
        .unwrap();
        assert_eq!(c.format, Some(Format::Nmea));
        assert_eq!(
            c.input,
            Input::Serial {
                path: "/dev/ttyUSB0".into(),
                baud: 4800
            }
        );
        let c = args(&["--source", "g", "--print", "--replay-speed", "0", "x.ubx"]).unwrap();
        assert!(matches!(c.output, Output::Print) && c.replay_speed == 0.0);
        assert!(args(&["--source", "a/b", "x"]).is_err());
        assert!(args(&["--source", "a", "--replay-speed", "-1", "x"]).is_err());
        assert!(args(&["--source", "a", "--speed-accuracy", "0", "x"]).is_err());
        assert!(args(&["--source", "a", "--format", "sirf", "x"]).is_err());
    }
}
