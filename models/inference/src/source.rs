//! One source's sample rules, without I/O: [`SourceStream`] decides what happens to
//! each sample of a source before and after the model, and counts it. ghnetd drives
//! one per served source, `ghnet infer` one per track, so live and offline answers are
//! the same by construction.
//!
//! # The rules, in order
//!
//! 1. **Sequence.** A sequence number higher than the previous sample's is the normal
//!    case (a jump adds the missing numbers to `gaps`); the same or lower counts as a
//!    duplicate. A lower one means the publisher restarted: the history starts afresh
//!    (`resets_restart`, when it had something in it).
//! 2. **Time.** A sample whose time (seconds, as the model sees it) is earlier than the
//!    previous sample's is answered `Invalid` without reaching the model, counted in
//!    `backwards`, and the history is cleared (`resets_backwards`, when it had
//!    something in it). The next sample's time is compared with this one's: one
//!    outlier costs at most one more flagged sample.
//! 3. **Validity**, checked here once: a sample the receiver flagged, a velocity
//!    component or time that is not finite, a speed accuracy that is negative or
//!    infinite (NaN means unknown), or a 3-D speed over the policy's `max_speed` is
//!    answered `Invalid` and leaves the history as it was.
//! 4. **Repeat.** A sample with the previous sample's sequence number again, for a
//!    stateful model, gets the answer its first copy got without advancing the history,
//!    so a duplicate cannot count twice in the filter.
//! 5. **Gap.** The history clears itself when a time step is longer than its gap limit
//!    ([`History`]); counted in `resets_gap`.
//!
//! Per-epoch models keep no history: rules 1 to 3 apply, 4 and 5 do not.

use crate::prediction::{Prediction, Status};
use crate::stream::{Epoch, History, Reset};

/// One sample of a source, as the rules see it: what the wire or a log row carries.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    /// The publisher's sequence number (a log has none: its row count does).
    pub seq: u64,
    /// Time, seconds (any origin; only differences and order matter).
    pub t_s: f64,
    /// North velocity, m/s.
    pub v_north: f32,
    /// East velocity, m/s.
    pub v_east: f32,
    /// Down velocity, m/s (0 when unknown).
    pub v_down: f32,
    /// Receiver speed accuracy (1σ, m/s); NaN when unknown.
    pub speed_acc: f32,
    /// The receiver flagged the fix invalid.
    pub flagged: bool,
}

impl Sample {
    /// The model's view of the sample.
    pub fn epoch(&self) -> Epoch {
        Epoch {
            t_s: self.t_s,
            v_north: self.v_north,
            v_east: self.v_east,
            speed_acc: self.speed_acc,
        }
    }

    /// Whether the sample may reach a model with speed limit `max_speed` (rule 3).
    pub fn is_valid(&self, max_speed: f32) -> bool {
        let (vn, ve, vd) = (self.v_north, self.v_east, self.v_down);
        let acc = self.speed_acc;
        !self.flagged
            && vn.is_finite()
            && ve.is_finite()
            && vd.is_finite()
            && self.t_s.is_finite()
            // NaN = unknown is fine; negative or infinite is a broken receiver.
            && (acc.is_nan() || (acc >= 0.0 && acc.is_finite()))
            && (vn * vn + ve * ve + vd * vd).sqrt() <= max_speed
    }
}

/// What the rules count for one source: what ghnetd reports per source in its stats
/// and `ghnet infer` could report per track.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SampleCounts {
    /// Samples taken.
    pub received: u64,
    /// Samples answered `Invalid` (any reason, including `backwards`).
    pub invalid: u64,
    /// Missing sequence numbers: a jump from 4 to 7 adds 2.
    pub gaps: u64,
    /// Samples whose sequence number was not greater than the previous one.
    pub duplicates: u64,
    /// Samples whose time was earlier than the previous sample's.
    pub backwards: u64,
    /// Histories cleared because a time step was longer than the gap limit.
    pub resets_gap: u64,
    /// Histories cleared because time went backwards.
    pub resets_backwards: u64,
    /// Histories cleared because the publisher restarted.
    pub resets_restart: u64,
}

/// What [`SourceStream::admit`] decided about a sample.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Admission {
    /// Answered by the rules (invalid, backwards, a repeat): the model must not see it.
    Answered(Prediction),
    /// For the model: run it on the source's history (or per epoch), then hand the
    /// answer to [`SourceStream::record`].
    Model(Epoch),
}

/// One source's rules and state: the previous sample, the model's history (stateful
/// models), the answer a repeat gets, the counts. Sans-I/O: the caller feeds samples
/// and runs the model, so the daemon, `ghnet infer` and tests drive the same type.
#[derive(Debug, Clone)]
pub struct SourceStream {
    /// Sequence number and time of the previous sample (any kind).
    last: Option<(u64, f64)>,
    history: Option<History>,
    /// Sequence number and answer of the last sample the model saw.
    repeat: Option<(u64, Prediction)>,
    counts: SampleCounts,
    max_speed: f32,
}

impl SourceStream {
    /// A source answered by a model with speed limit `max_speed` (the status
    /// policy's), through `history` for a stateful model (`None`: per-epoch).
    pub fn new(history: Option<History>, max_speed: f32) -> Self {
        Self {
            last: None,
            history,
            repeat: None,
            counts: SampleCounts::default(),
            max_speed,
        }
    }

    /// The same source continuing earlier counts (a source that comes back keeps its
    /// totals; its sequence and history start afresh).
    pub fn resume(mut self, counts: SampleCounts) -> Self {
        self.counts = counts;
        self
    }

    /// The counts so far.
    pub fn counts(&self) -> &SampleCounts {
        &self.counts
    }

    /// The model's history of this source (`None` for a per-epoch model).
    pub fn history(&self) -> Option<&History> {
        self.history.as_ref()
    }

    /// The history, for the model's step (crate-internal: only [`crate::Runner`]
    /// advances it, between [`admit`](Self::admit) and [`record`](Self::record)).
    pub(crate) fn history_mut(&mut self) -> Option<&mut History> {
        self.history.as_mut()
    }

    /// The source's publisher is new (it restarted, or the source was dropped and
    /// comes back): the history starts afresh, counted in `resets_restart` when it had
    /// something in it.
    pub fn restart(&mut self) {
        self.repeat = None;
        if let Some(h) = self.history.as_mut().filter(|h| !h.is_empty()) {
            h.reset();
            self.counts.resets_restart += 1;
        }
    }

    /// Rules 1 to 4 for sample `s` (module docs): its answer, or its epoch for the model.
    pub fn admit(&mut self, s: &Sample) -> Admission {
        self.counts.received += 1;
        let (mut lower, mut repeat, mut backwards) = (false, false, false);
        let mut t = s.t_s;
        if let Some((last_seq, last_t)) = self.last {
            if s.seq > last_seq {
                // Saturating: a publisher may jump to u64::MAX and back.
                self.counts.gaps = self.counts.gaps.saturating_add(s.seq - last_seq - 1);
            } else {
                self.counts.duplicates += 1;
            }
            (lower, repeat) = (s.seq < last_seq, s.seq == last_seq);
            backwards = s.t_s < last_t;
            if t.is_nan() {
                // A time that does not parse (a log): the next compares with the last.
                t = last_t;
            }
        }
        self.last = Some((s.seq, t));
        if lower {
            self.restart();
        } else if backwards {
            if let Some(h) = self.history.as_mut().filter(|h| !h.is_empty()) {
                h.reset_because(Reset::Backwards);
                self.counts.resets_backwards += 1;
            }
        }
        if backwards {
            self.counts.backwards += 1;
        }
        if backwards || !s.is_valid(self.max_speed) {
            self.counts.invalid += 1;
            return Admission::Answered(invalid(s));
        }
        match self.repeat {
            Some((seq, p)) if repeat && seq == s.seq && self.history.is_some() => {
                Admission::Answered(p)
            }
            _ => Admission::Model(s.epoch()),
        }
    }

    /// After the model answered sample `seq` with `p`: counts the reset the history
    /// made and an `Invalid` answer, keeps the answer for a repeat; returns `p`.
    pub fn record(&mut self, seq: u64, p: Prediction) -> Prediction {
        match self.history.as_ref().and_then(History::last_reset) {
            Some(Reset::Gap) => self.counts.resets_gap += 1,
            Some(Reset::Backwards) => self.counts.resets_backwards += 1,
            Some(Reset::Explicit) => self.counts.resets_restart += 1,
            None => {}
        }
        if p.status == Status::Invalid {
            self.counts.invalid += 1;
        }
        self.repeat = Some((seq, p));
        p
    }
}

/// The `Invalid` answer to `s`: the horizontal speed when both components are finite
/// (it tells why e.g. a glitch above `max_speed` was refused), NaN otherwise.
fn invalid(s: &Sample) -> Prediction {
    let finite = s.v_north.is_finite() && s.v_east.is_finite();
    Prediction {
        speed: if finite {
            s.v_north.hypot(s.v_east)
        } else {
            f32::NAN
        },
        ..Prediction::INVALID
    }
}
