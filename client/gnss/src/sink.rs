//! Where samples go: [`Sink::Publish`] (ghnetd's velocity service, plus its answers
//! when the bridge must wait for them) or [`Sink::Print`] (CSV on stdout, to look at
//! a receiver without ghnetd).

use std::io::{BufWriter, Stdout, Write};
use std::time::{Duration, Instant};

use anyhow::Context;
use ghnet_client::{
    HeadingStatus, HeadingSubscriber, IpcConfig, VelocityPublisher, VelocitySample,
};
use ghnet_receivers::Epoch;

use crate::input::{sleep_unless, READ_TIMEOUT};

/// The header of `--print` output, one row per sample.
pub const CSV_HEADER: &str =
    "seq,timestamp_ns,v_north,v_east,v_down,speed_accuracy,flags,receiver_course_deg,receiver_course_acc_deg";

/// The destination of the bridge's samples.
pub enum Sink {
    /// Published on `<prefix>/<source>/velocity`.
    Publish(Box<Publisher>),
    /// Printed as CSV (`--print`).
    Print(BufWriter<Stdout>),
}

impl Sink {
    /// Sends one sample. `epoch` gives `--print` the receiver's own course.
    pub fn send(&mut self, sample: VelocitySample, epoch: &Epoch) -> anyhow::Result<()> {
        match self {
            Sink::Publish(p) => p.send(sample),
            Sink::Print(out) => {
                let s = sample;
                writeln!(
                    out,
                    "{},{},{},{},{},{},{},{},{}",
                    s.seq,
                    s.timestamp_ns,
                    s.v_north,
                    s.v_east,
                    s.v_down,
                    s.speed_accuracy,
                    s.flags,
                    epoch.course_deg,
                    epoch.course_accuracy_deg
                )
                .context("writing to stdout")
            }
        }
    }
}

/// The velocity publisher of one source and, for replays, a subscriber to ghnetd's
/// answers: a replay waits for ghnetd before its first sample (services keep no
/// history), at `--replay-speed 0` for each answer, and at the end for the last.
pub struct Publisher {
    velocity: VelocityPublisher,
    answers: Option<HeadingSubscriber>,
    tally: Answers,
    last_answered: Option<u64>,
}

/// ghnetd's answers received during a replay, by status.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Answers {
    /// `Ok`: a heading to use.
    pub ok: u64,
    /// `LowSpeed`: moving, heading uncertain.
    pub low_speed: u64,
    /// `Stationary`: heading not observable.
    pub stationary: u64,
    /// `InvalidInput`: rejected (e.g. the receiver's `INVALID` flag).
    pub invalid: u64,
    /// Any status this bridge does not know (a newer ghnetd).
    pub other: u64,
}

impl Answers {
    /// All answers.
    pub fn total(&self) -> u64 {
        self.ok + self.low_speed + self.stationary + self.invalid + self.other
    }

    fn count(&mut self, status: Option<HeadingStatus>) {
        match status {
            Some(HeadingStatus::Ok) => self.ok += 1,
            Some(HeadingStatus::LowSpeed) => self.low_speed += 1,
            Some(HeadingStatus::Stationary) => self.stationary += 1,
            Some(HeadingStatus::InvalidInput) => self.invalid += 1,
            _ => self.other += 1,
        }
    }
}

impl std::fmt::Display for Answers {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "answered {} (ok {}, low_speed {}, stationary {}, invalid {}",
            self.total(),
            self.ok,
            self.low_speed,
            self.stationary,
            self.invalid
        )?;
        if self.other > 0 {
            write!(f, ", other {}", self.other)?;
        }
        f.write_str(")")
    }
}

impl Publisher {
    /// Opens the velocity service of `source` (and its heading service when
    /// `with_answers`).
    pub fn open(ipc: &IpcConfig, source: &str, with_answers: bool) -> anyhow::Result<Self> {
        let velocity =
            VelocityPublisher::new(ipc, source).context("opening the velocity service")?;
        let answers = with_answers
            .then(|| HeadingSubscriber::new(ipc, source))
            .transpose()
            .context("opening the heading service")?;
        Ok(Publisher {
            velocity,
            answers,
            tally: Answers::default(),
            last_answered: None,
        })
    }

    /// The velocity service name, for logs.
    pub fn service_name(&self) -> &str {
        self.velocity.service_name()
    }

    fn send(&mut self, sample: VelocitySample) -> anyhow::Result<()> {
        self.velocity.send(sample).context("publishing a sample")?;
        self.take_answers(Duration::ZERO)?;
        Ok(())
    }

    /// Answers received by status (when listening for them).
    pub fn answered(&self) -> Option<Answers> {
        self.answers.as_ref().map(|_| self.tally)
    }

    /// Counts the answers already there, waiting up to `wait` for the first.
    fn take_answers(&mut self, wait: Duration) -> anyhow::Result<()> {
        let Some(answers) = &self.answers else {
            return Ok(());
        };
        let mut next = if wait.is_zero() {
            answers.try_recv()
        } else {
            answers.recv_timeout(wait)
        };
        while let Some(h) = next.context("receiving answers")? {
            // `Stale` is ghnetd saying the source went quiet, not an answer.
            let status = h.heading_status();
            if status != Some(HeadingStatus::Stale) {
                self.tally.count(status);
                self.last_answered = Some(h.seq);
            }
            next = answers.try_recv();
        }
        Ok(())
    }

    /// Waits until ghnetd answered `seq` (or a later sample), at most `timeout`.
    /// `false` on timeout or stop.
    pub fn await_answer(
        &mut self,
        seq: u64,
        timeout: Duration,
        stop: &dyn Fn() -> bool,
    ) -> anyhow::Result<bool> {
        let deadline = Instant::now() + timeout;
        while self.last_answered.is_none_or(|a| a < seq) {
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() || stop() || self.answers.is_none() {
                return Ok(false);
            }
            self.take_answers(left.min(READ_TIMEOUT))?;
        }
        Ok(true)
    }

    /// Waits until a subscriber (ghnetd) is attached, at most `patience`. `false`
    /// on timeout or stop.
    pub fn wait_for_daemon(&self, patience: Duration, stop: &dyn Fn() -> bool) -> bool {
        let deadline = Instant::now() + patience;
        let mut logged = false;
        // Our own answer subscriber does not count: it is on the heading service.
        while self.velocity.subscriber_count() == 0 {
            if !logged {
                tracing::info!(
                    service = self.service_name(),
                    "waiting for ghnetd to subscribe"
                );
                logged = true;
            }
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() || !sleep_unless(left.min(Duration::from_millis(20)), stop) {
                return false;
            }
        }
        true
    }
}
