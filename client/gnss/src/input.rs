//! Where receiver bytes come from: [`Input`] (file, serial device, raw TCP, gpsd)
//! and [`Connection`], which reads with a short timeout (so a stop request is seen
//! at once) and reconnects live inputs with backoff.

use std::fmt;
use std::io::{self, Read, Write};
use std::net::{TcpStream, ToSocketAddrs};
use std::os::unix::fs::FileTypeExt;
use std::path::PathBuf;
use std::time::Duration;

use anyhow::{bail, Context};
use ghnet_receivers::gpsd::WATCH_COMMAND;

/// How long one read may block: the longest a stop request waits.
pub const READ_TIMEOUT: Duration = Duration::from_millis(100);
/// How long connecting to a TCP peer may take before it counts as a failed attempt.
const CONNECT_TIMEOUT: Duration = Duration::from_secs(2);
/// gpsd's port when `gpsd://HOST` names none.
pub const GPSD_PORT: u16 = 2947;
/// Serial speed when `--baud` is not given: the default of u-blox M8 UARTs and of
/// most NMEA receivers (older ones use 4800). USB CDC devices ignore it.
pub const DEFAULT_BAUD: u32 = 9600;

/// The receiver's byte stream, as named on the command line.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Input {
    /// A recorded log, replayed (at its recorded pace, or faster).
    File(PathBuf),
    /// A serial device (`/dev/ttyACM0`, `/dev/serial/by-id/...`, a pseudo-terminal).
    Serial {
        /// Device path; a symlink is followed at every (re)open.
        path: PathBuf,
        /// Line speed in bit/s.
        baud: u32,
    },
    /// `tcp://HOST:PORT`: a raw UBX or NMEA stream (ser2net, a receiver's TCP port).
    Tcp(String),
    /// `gpsd://HOST[:PORT]`: gpsd's JSON, started with `?WATCH`.
    Gpsd(String),
}

impl Input {
    /// Reads an `INPUT` argument. A path is a serial device when `baud` is given,
    /// when it names a character device, or when it is under `/dev/` (a device that
    /// is unplugged at start); otherwise a file.
    pub fn parse(text: &str, baud: Option<u32>) -> anyhow::Result<Input> {
        if let Some(addr) = text.strip_prefix("tcp://") {
            check_host_port(addr).with_context(|| format!("`{text}`"))?;
            return Ok(Input::Tcp(addr.to_owned()));
        }
        if let Some(addr) = text.strip_prefix("gpsd://") {
            let addr = if addr.contains(':') {
                addr.to_owned()
            } else {
                format!("{addr}:{GPSD_PORT}")
            };
            check_host_port(&addr).with_context(|| format!("`{text}`"))?;
            return Ok(Input::Gpsd(addr));
        }
        if text.contains("://") {
            bail!(
                "`{text}`: unknown scheme (expected a path, tcp://HOST:PORT or gpsd://HOST:PORT)"
            );
        }
        let path = PathBuf::from(text);
        let char_device = std::fs::metadata(&path).is_ok_and(|m| m.file_type().is_char_device());
        if baud.is_some() || char_device || path.starts_with("/dev") {
            let baud = baud.unwrap_or(DEFAULT_BAUD);
            return Ok(Input::Serial { path, baud });
        }
        Ok(Input::File(path))
    }

    /// A live source (not a file): no pacing, reconnects when it goes away.
    pub fn is_live(&self) -> bool {
        !matches!(self, Input::File(_))
    }

    /// Opens the stream once.
    pub fn open(&self) -> io::Result<Box<dyn Read>> {
        match self {
            Input::File(path) => Ok(Box::new(std::fs::File::open(path)?)),
            Input::Serial { path, baud } => {
                let port = serialport::new(path.to_string_lossy(), *baud)
                    .timeout(READ_TIMEOUT)
                    .open()
                    .map_err(io::Error::from)?;
                Ok(Box::new(port))
            }
            Input::Tcp(addr) => Ok(Box::new(tcp(addr)?)),
            Input::Gpsd(addr) => {
                let mut stream = tcp(addr)?;
                stream.write_all(WATCH_COMMAND)?;
                Ok(Box::new(stream))
            }
        }
    }
}

impl fmt::Display for Input {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Input::File(p) => write!(f, "file {}", p.display()),
            Input::Serial { path, baud } => write!(f, "serial {} at {baud} bit/s", path.display()),
            Input::Tcp(a) => write!(f, "tcp://{a}"),
            Input::Gpsd(a) => write!(f, "gpsd://{a}"),
        }
    }
}

fn check_host_port(addr: &str) -> anyhow::Result<()> {
    let (host, port) = addr.rsplit_once(':').context("expected HOST:PORT")?;
    if host.is_empty() {
        bail!("no host");
    }
    port.parse::<u16>().context("bad port")?;
    Ok(())
}

fn tcp(addr: &str) -> io::Result<TcpStream> {
    let mut last = io::Error::new(io::ErrorKind::NotFound, format!("{addr}: no address"));
    for sock in addr.to_socket_addrs()? {
        match TcpStream::connect_timeout(&sock, CONNECT_TIMEOUT) {
            Ok(stream) => {
                stream.set_read_timeout(Some(READ_TIMEOUT))?;
                stream.set_nodelay(true)?;
                return Ok(stream);
            }
            Err(e) => last = e,
        }
    }
    Err(last)
}

/// Exponential backoff between reconnection attempts.
#[derive(Debug, Clone, Copy)]
pub struct Backoff {
    /// First wait after a loss.
    pub initial: Duration,
    /// Longest wait between attempts.
    pub max: Duration,
}

impl Default for Backoff {
    fn default() -> Self {
        Backoff {
            initial: Duration::from_millis(100),
            max: Duration::from_secs(5),
        }
    }
}

/// What one [`Connection::read`] gave.
#[derive(Debug)]
pub enum Got {
    /// Bytes were read into the buffer.
    Data(usize),
    /// Nothing within [`READ_TIMEOUT`]; ask again.
    Idle,
    /// A file ended.
    End,
}

/// An open [`Input`] that survives its peer: a live input that ends or fails is
/// reopened with backoff, each loss logged and counted.
pub struct Connection {
    input: Input,
    stream: Option<Box<dyn Read>>,
    backoff: Backoff,
    reconnects: u64,
}

impl Connection {
    /// Opens `input`. A file that cannot be opened is an error; a live input that
    /// is not there yet is retried like a lost one (see [`read`](Self::read)).
    pub fn open(input: Input, backoff: Backoff) -> anyhow::Result<Self> {
        let stream = match input.open() {
            Ok(s) => Some(s),
            Err(e) if input.is_live() => {
                tracing::warn!(%input, error = %e, "cannot open the receiver yet; retrying");
                None
            }
            Err(e) => return Err(e).with_context(|| format!("{input}")),
        };
        Ok(Connection {
            input,
            stream,
            backoff,
            reconnects: 0,
        })
    }

    /// Connections lost (and attempted again) so far.
    pub fn reconnects(&self) -> u64 {
        self.reconnects
    }

    /// Whether the stream is open now (false while waiting to reconnect).
    pub fn is_open(&self) -> bool {
        self.stream.is_some()
    }

    /// Reads into `buf`. A live input that is closed tries to reopen first, waiting
    /// out its backoff in [`READ_TIMEOUT`] steps while `stop` is false; a lost one
    /// is closed and `Ok(Idle)` returned, so the caller can finish what it decoded.
    pub fn read(&mut self, buf: &mut [u8], stop: &dyn Fn() -> bool) -> anyhow::Result<Got> {
        let Some(stream) = self.stream.as_mut() else {
            self.reopen(stop);
            return Ok(Got::Idle);
        };
        match stream.read(buf) {
            Ok(0) if !self.input.is_live() => Ok(Got::End),
            Ok(0) => {
                self.lost("end of stream".into());
                Ok(Got::Idle)
            }
            Ok(n) => Ok(Got::Data(n)),
            Err(e) if is_timeout(&e) => Ok(Got::Idle),
            Err(e) if self.input.is_live() => {
                self.lost(e.to_string());
                Ok(Got::Idle)
            }
            Err(e) => Err(e).with_context(|| format!("reading {}", self.input)),
        }
    }

    fn lost(&mut self, why: String) {
        self.stream = None;
        self.reconnects += 1;
        tracing::warn!(input = %self.input, reason = %why, reconnects = self.reconnects, "receiver lost; reconnecting");
    }

    /// Tries to reopen, backing off exponentially between failed attempts.
    fn reopen(&mut self, stop: &dyn Fn() -> bool) {
        let mut wait = self.backoff.initial;
        for attempt in 1u64.. {
            if !sleep_unless(wait, stop) {
                return;
            }
            match self.input.open() {
                Ok(s) => {
                    tracing::info!(input = %self.input, attempt, "receiver connected");
                    self.stream = Some(s);
                    return;
                }
                Err(e) => {
                    wait = (wait * 2).min(self.backoff.max);
                    // A receiver unplugged for hours: a warning now and then, not
                    // one per attempt.
                    if attempt <= 3 || attempt % 12 == 0 {
                        tracing::warn!(input = %self.input, error = %e, attempt, retry_in = ?wait, "cannot open the receiver");
                    } else {
                        tracing::debug!(input = %self.input, error = %e, attempt, "cannot open the receiver");
                    }
                }
            }
        }
    }
}

fn is_timeout(e: &io::Error) -> bool {
    matches!(
        e.kind(),
        io::ErrorKind::TimedOut | io::ErrorKind::WouldBlock | io::ErrorKind::Interrupted
    )
}

/// Sleeps `total` in [`READ_TIMEOUT`] steps; `false` if `stop` became true.
pub fn sleep_unless(total: Duration, stop: &dyn Fn() -> bool) -> bool {
    let deadline = std::time::Instant::now() + total;
    loop {
        if stop() {
            return false;
        }
        let left = deadline.saturating_duration_since(std::time::Instant::now());
        if left.is_zero() {
            return true;
        }
        std::thread::sleep(left.min(READ_TIMEOUT));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn inputs_parse() {
        assert_eq!(
            Input::parse("tcp://localhost:5000", None).unwrap(),
            Input::Tcp("localhost:5000".into())
        );
        assert_eq!(
            Input::parse("gpsd://127.0.0.1", None).unwrap(),
            Input::Gpsd("127.0.0.1:2947".into())
        );
        assert_eq!(
            Input::parse("/dev/ttyACM0", None).unwrap(),
            Input::Serial {
                path: "/dev/ttyACM0".into(),
                baud: 9600
            }
        );
        assert_eq!(
            Input::parse("gps.log", Some(4800)).unwrap(),
            Input::Serial {
                path: "gps.log".into(),
                baud: 4800
            }
        );
        assert_eq!(
            Input::parse("drive.ubx", None).unwrap(),
            Input::File("drive.ubx".into())
        );
        assert!(Input::parse("tcp://nohost", None).is_err());
        assert!(Input::parse("tcp://:12", None).is_err());
        assert!(Input::parse("udp://x:1", None).is_err());
    }
}
