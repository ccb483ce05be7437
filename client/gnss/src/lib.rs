//! `ghnet_gnss`: the receiver bridge. Reads a u-blox, NMEA or gpsd stream from a
//! file, a serial device or TCP, decodes it with `ghnet-receivers` and publishes one
//! `VelocitySample` per epoch to ghnetd.
//!
//! # Layout
//!
//! - [`cli`] — [`Args`](cli::Args), the command line (its doc comments are
//!   `--help`), turned into a [`Config`].
//! - [`input`] — [`Input`] (file, serial, `tcp://`, `gpsd://`) and
//!   [`Connection`]: short-timeout reads, reconnection with
//!   backoff, logged and counted.
//! - [`stamp`] — [`Stamper`]: sequence numbers and timestamps that
//!   never go backwards; [`to_sample`], the epoch → wire mapping.
//! - [`pace`] — [`Pacer`]: replay at the recorded pace or faster.
//! - [`sink`] — [`Sink`]: publish to ghnetd (waiting for its answers
//!   where a replay needs them) or print CSV.
//! - this file — [`run`], the loop: read → decode → stamp → pace → send; and
//!   [`Summary`], the counters of a run.
//!
//! `run` takes the stop request as a parameter; the binary passes iceoryx2's
//! SIGINT/SIGTERM flag, tests their own.

#![warn(missing_docs)]

pub mod cli;
pub mod input;
pub mod pace;
pub mod sink;
pub mod stamp;

use std::fmt;
use std::time::Duration;

use anyhow::Context;
use ghnet_client::IpcConfig;
use ghnet_receivers::{Decoder, Epoch, Format, Stats};

pub use input::{Backoff, Input};

use input::{Connection, Got};
use pace::Pacer;
use sink::{Publisher, Sink, CSV_HEADER};
use stamp::{to_sample, Stamper};

/// Bytes read per call: a few epochs of any protocol.
const READ_CHUNK: usize = 4096;

/// Where the samples go.
#[derive(Debug, Clone)]
pub enum Output {
    /// To ghnetd, on `<prefix>/<source>/velocity` of this iceoryx2 namespace.
    Publish(Box<IpcConfig>),
    /// To stdout as CSV ([`sink::CSV_HEADER`]), without iceoryx2.
    Print,
}

/// Everything a run needs; [`cli::Args`] builds it from the command line.
#[derive(Debug, Clone)]
pub struct Config {
    /// Source name: the `<source>` level of the service name.
    pub source: String,
    /// The receiver's stream.
    pub input: Input,
    /// The protocol, or `None` to detect it from the stream.
    pub format: Option<Format>,
    /// Replay pace for files: 1 = as recorded, 10 = ten times faster, 0 = each
    /// sample as soon as ghnetd answered the one before.
    pub replay_speed: f64,
    /// 1σ speed accuracy (m/s) for NMEA and gpsd epochs, which carry none.
    pub speed_accuracy: Option<f32>,
    /// Publish or print.
    pub output: Output,
    /// How long a replay waits for ghnetd to subscribe before sending anyway.
    pub wait_for_daemon: Duration,
    /// How long a replay waits for an answer (at speed 0, and for the last sample).
    pub answer_timeout: Duration,
    /// Reconnection backoff for live inputs.
    pub backoff: Backoff,
}

impl Config {
    /// A config with the defaults of the command line: detect the format, replay at
    /// the recorded pace, publish with the default prefix.
    pub fn new(source: &str, input: Input) -> Self {
        Config {
            source: source.to_owned(),
            input,
            format: None,
            replay_speed: 1.0,
            speed_accuracy: None,
            output: Output::Publish(Box::default()),
            wait_for_daemon: Duration::from_secs(30),
            answer_timeout: Duration::from_secs(5),
            backoff: Backoff::default(),
        }
    }
}

/// What a run did; its [`Display`](fmt::Display) is the summary line.
#[derive(Debug, Clone)]
pub struct Summary {
    /// The source name.
    pub source: String,
    /// The format decoded (`None` if nothing was recognised).
    pub format: Option<Format>,
    /// Samples sent, one per epoch.
    pub published: u64,
    /// Of those, flagged `INVALID`.
    pub invalid: u64,
    /// ghnetd's answers by status, when the run listened for them (replays).
    pub answered: Option<sink::Answers>,
    /// Connections lost and retried.
    pub reconnects: u64,
    /// Epochs whose receiver time went backwards and were held at the last
    /// timestamp.
    pub held_back: u64,
    /// The decoder's counters: bytes and skips by reason.
    pub decoder: Stats,
}

impl fmt::Display for Summary {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let format = self.format.map_or("unknown format", Format::name);
        write!(
            f,
            "source {} ({format}): published {} samples ({} invalid)",
            self.source, self.published, self.invalid
        )?;
        if let Some(a) = self.answered {
            write!(f, ", {a}")?;
        }
        write!(
            f,
            "; reconnects {}, timestamps held back {}; decoder {}",
            self.reconnects, self.held_back, self.decoder
        )
    }
}

/// Runs the bridge until the input ends (a file) or `stop` returns true.
pub fn run(config: &Config, stop: &dyn Fn() -> bool) -> anyhow::Result<Summary> {
    let replay = !config.input.is_live();
    let mut sink = open_sink(config, replay)?;
    let mut conn = Connection::open(config.input.clone(), config.backoff)?;
    tracing::info!(input = %config.input, source = %config.source, "ghnet-gnss started");
    if let (Sink::Publish(p), true) = (&sink, replay) {
        if !p.wait_for_daemon(config.wait_for_daemon, stop) && !stop() {
            tracing::warn!(
                service = p.service_name(),
                "no ghnetd subscribed; sending anyway"
            );
        }
    }
    let mut bridge = Bridge {
        config,
        decoder: Decoder::with_speed_accuracy(format_of(config), config.speed_accuracy),
        stamper: Stamper::new(!replay),
        pacer: Pacer::new(if replay { config.replay_speed } else { 0.0 }),
        epochs: Vec::with_capacity(64),
        invalid: 0,
        replay,
    };
    bridge.pump(&mut conn, &mut sink, stop)?;
    bridge.finish(&mut sink, stop)?;
    let answered = match &sink {
        Sink::Publish(p) => p.answered(),
        Sink::Print(_) => None,
    };
    let summary = Summary {
        source: config.source.clone(),
        format: bridge.decoder.format(),
        published: bridge.stamper.count(),
        invalid: bridge.invalid,
        answered,
        reconnects: conn.reconnects(),
        held_back: bridge.stamper.held_back(),
        decoder: bridge.decoder.stats().clone(),
    };
    tracing::info!("{summary}");
    Ok(summary)
}

/// The format to decode: as configured, gpsd's for a `gpsd://` input, else detected.
fn format_of(config: &Config) -> Option<Format> {
    match (&config.format, &config.input) {
        (Some(f), _) => Some(*f),
        (None, Input::Gpsd(_)) => Some(Format::Gpsd),
        (None, _) => None,
    }
}

fn open_sink(config: &Config, replay: bool) -> anyhow::Result<Sink> {
    match &config.output {
        Output::Publish(ipc) => {
            let p = Publisher::open(ipc, &config.source, replay)
                .with_context(|| format!("source `{}`", config.source))?;
            Ok(Sink::Publish(Box::new(p)))
        }
        Output::Print => {
            let mut out = std::io::BufWriter::new(std::io::stdout());
            std::io::Write::write_all(&mut out, format!("{CSV_HEADER}\n").as_bytes())?;
            Ok(Sink::Print(out))
        }
    }
}

/// The state of one run between reads.
struct Bridge<'a> {
    config: &'a Config,
    decoder: Decoder,
    stamper: Stamper,
    pacer: Pacer,
    /// Epochs decoded from the last read; reused, so steady state allocates nothing.
    epochs: Vec<Epoch>,
    invalid: u64,
    replay: bool,
}

impl Bridge<'_> {
    /// Reads and forwards until the file ends or `stop`.
    fn pump(
        &mut self,
        conn: &mut Connection,
        sink: &mut Sink,
        stop: &dyn Fn() -> bool,
    ) -> anyhow::Result<()> {
        let mut buf = [0u8; READ_CHUNK];
        let mut was_open = conn.is_open();
        while !stop() {
            let got = conn.read(&mut buf, stop)?;
            if was_open && !conn.is_open() {
                // Lost: what was half-read is gone; count it, start afresh.
                self.decoder.finish(&mut self.epochs);
            }
            was_open = conn.is_open();
            match got {
                Got::Data(n) => self.decoder.push(&buf[..n], &mut self.epochs),
                Got::Idle => {}
                Got::End => return Ok(()),
            }
            self.forward(sink, stop)?;
        }
        Ok(())
    }

    /// Sends the decoded epochs: stamp, pace, send, and at replay speed 0 wait for
    /// each answer.
    fn forward(&mut self, sink: &mut Sink, stop: &dyn Fn() -> bool) -> anyhow::Result<()> {
        for i in 0..self.epochs.len() {
            let epoch = self.epochs[i];
            if !self.pacer.wait(epoch.time_ns, stop) {
                break; // stopping: the rest is not sent
            }
            let (seq, ts) = self.stamper.next(epoch.time_ns);
            self.invalid += u64::from(!epoch.valid);
            sink.send(to_sample(&epoch, seq, ts, self.replay), &epoch)?;
            if let (Sink::Publish(p), true) =
                (&mut *sink, self.replay && self.config.replay_speed <= 0.0)
            {
                if !p.await_answer(seq, self.config.answer_timeout, stop)? && !stop() {
                    tracing::warn!(seq, "no answer from ghnetd in time; going on");
                }
            }
        }
        if !self.epochs.is_empty() {
            // Rows reach a pipe (`| tee`, a test) as they are decoded, not per 8 KiB.
            if let Sink::Print(out) = sink {
                std::io::Write::flush(out).context("writing to stdout")?;
            }
        }
        self.epochs.clear();
        Ok(())
    }

    /// End of input: count a truncated tail, send what detection still held, and
    /// give ghnetd time to answer the last sample before the publisher goes away.
    fn finish(&mut self, sink: &mut Sink, stop: &dyn Fn() -> bool) -> anyhow::Result<()> {
        self.decoder.finish(&mut self.epochs);
        if !stop() {
            self.forward(sink, stop)?;
        }
        match sink {
            Sink::Print(out) => std::io::Write::flush(out).context("writing to stdout")?,
            Sink::Publish(p) if self.replay && self.stamper.count() > 0 => {
                let last = self.stamper.count() - 1;
                if !p.await_answer(last, self.config.answer_timeout, stop)? && !stop() {
                    tracing::warn!(seq = last, "ghnetd did not answer the last sample in time");
                }
            }
            Sink::Publish(_) => {}
        }
        Ok(())
    }
}
