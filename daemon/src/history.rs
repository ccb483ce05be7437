//! Per-source history for stateful models (`kf`, `ghnet-temporal`): which model path a
//! sample takes, and the rules that keep one source's history honest.
//!
//! A stateful model answers from everything its source sent before (a Kalman filter
//! holds a stopped car's heading; a per-epoch model cannot), so every served source
//! owns one [`SourceHistory`], made when the source is opened and sized by the model,
//! and its samples go through the daemon's one [`StreamPredictor`] one at a time, in
//! arrival order. Nothing is allocated per sample: the history's ring and the
//! predictor's scratch are made once.
//!
//! The history's own rules (`ghnet_models::stream`): it is cleared when a time step
//! is longer than the gap limit (the model's `max_gap_s`, or `history.max_gap_s`), and
//! counted there. The daemon adds what only it sees, from [`Tracker::book_detailed`]:
//! - time going backwards: the sample is answered `InvalidInput` without the model, and
//!   the history cleared ([`Reset::Backwards`]) — so the model never sees it go back
//!   itself and nothing is counted twice;
//! - a sequence number lower than the previous one: the publisher restarted, the
//!   history starts afresh ([`History::reset`]); so does a source that was dropped and
//!   comes back (see `Source::open`);
//! - a repeated sample (the same `seq` again): answered with the answer its first copy
//!   got, without advancing the history, so a duplicate cannot count twice in the
//!   filter (nor shorten its time steps to zero).
//!
//! Resets are counted (`resets_gap`, `resets_backwards`, `resets_restart`) only when
//! they clear a history that had something in it.

use std::sync::Arc;

use ghnet_client::{HeadingEstimate, VelocitySample};
use ghnet_models::stream::{Epoch, History, Reset, StreamBatch, StreamPredictor};
use ghnet_models::{Model, Platform, Prediction, Predictor, StatusPolicy};

use crate::answer::{Booked, Counters, Limits, ModelTag, Sequence, Tracker};

/// Most epochs in one staged pass: one per source that woke, up to the daemon's
/// default source limit; more wait for the next pass.
pub const STREAM_BATCH: usize = 128;

/// The model as the daemon runs it.
#[derive(Debug)]
pub enum Runner {
    /// A per-epoch model: one sample, or many of several sources in one batched call
    /// (about half the cost per sample); no history. Boxed: its batch scratch is much
    /// larger than the stream predictor (one per daemon either way).
    Epoch(Box<Predictor>),
    /// A stateful model: each sample against its source's history, in order; the
    /// samples of sources that woke together may share one pass of a temporal
    /// network's convolutions (bit for bit the answers of one at a time).
    Stream {
        /// Runs the model; its scratch serves every source.
        predictor: StreamPredictor,
        /// `history.max_gap_s`, replacing the model's own gap limit.
        max_gap_s: Option<f64>,
        /// One pass's staged epochs (`None` for `kf`, which has no network). Boxed:
        /// the enum stays small.
        batch: Option<Box<StreamBatch>>,
    },
}

impl Runner {
    /// The runner `model` needs, with the status thresholds `policy` and, for a
    /// stateful model, an optional gap limit replacing the model's.
    pub fn new(model: Arc<Model>, policy: StatusPolicy, max_gap_s: Option<f64>) -> Self {
        if model.is_stateful() {
            let predictor = StreamPredictor::new(model).with_policy(policy);
            let batch = predictor.batch(STREAM_BATCH).map(Box::new);
            Runner::Stream {
                predictor,
                max_gap_s,
                batch,
            }
        } else {
            Runner::Epoch(Box::new(Predictor::new(model).with_policy(policy)))
        }
    }

    /// A fresh history for one source (`None` for a per-epoch model), on `platform`
    /// (`None`: the model's default).
    pub fn history(&self, platform: Option<Platform>) -> Option<SourceHistory> {
        match self {
            Runner::Epoch(_) => None,
            Runner::Stream {
                predictor,
                max_gap_s,
                ..
            } => {
                let h = predictor.history();
                let h = match platform {
                    Some(p) => h.with_platform(p),
                    None => h,
                };
                let h = match max_gap_s {
                    Some(g) => h.with_max_gap(*g),
                    None => h,
                };
                Some(SourceHistory {
                    history: h,
                    last: None,
                })
            }
        }
    }

    /// The gap limit histories use, seconds (`None` for a per-epoch model).
    pub fn max_gap_s(&self) -> Option<f64> {
        self.history(None).map(|h| h.history.max_gap_s())
    }

    /// Books `s` on `tracker` and answers it: through the per-epoch predictor, or
    /// through the stream predictor and `history` (which must then be the source's).
    /// `processing_ns` is left at 0.
    ///
    /// # Panics
    /// For a stateful model without a `history`.
    pub fn answer(
        &mut self,
        tracker: &mut Tracker,
        history: Option<&mut SourceHistory>,
        s: &VelocitySample,
        limits: &Limits,
        tag: &ModelTag,
    ) -> HeadingEstimate {
        match self {
            Runner::Epoch(p) => tracker.answer(s, p, limits, tag),
            Runner::Stream { predictor, .. } => {
                let history = history.expect("a stateful model needs the source's history");
                let booked = tracker.book_detailed(s, limits);
                let p = history.predict(predictor, s, booked, &mut tracker.counters);
                tracker.finish(s, p, tag)
            }
        }
    }

    /// Step 1 of a staged pass over sources that woke together (temporal models):
    /// books `s` and stages its epoch. `Ok(column)` waits for
    /// [`run_staged`](Self::run_staged) and [`complete`](Self::complete); `Err` is the
    /// final answer (not for the model, a repeat, bad input, a full pass, a model
    /// without stages). At most one sample per source per pass.
    pub fn stage(
        &mut self,
        tracker: &mut Tracker,
        history: Option<&mut SourceHistory>,
        s: &VelocitySample,
        limits: &Limits,
        tag: &ModelTag,
    ) -> Result<usize, HeadingEstimate> {
        if !self.stages() || history.is_none() {
            return Err(self.answer(tracker, history, s, limits, tag));
        }
        let (predictor, batch, history) = self.staged_parts(history).expect("checked above");
        let booked = tracker.book_detailed(s, limits);
        (history.stage(predictor, batch, s, booked, &mut tracker.counters))
            .map_err(|p| tracker.finish(s, p, tag))
    }

    /// Step 2: the convolutions of every staged epoch, one pass.
    pub fn run_staged(&mut self) {
        if let Runner::Stream {
            predictor,
            batch: Some(batch),
            ..
        } = self
        {
            predictor.run(batch);
        }
    }

    /// Step 3: the answer to `s`, staged in `column` with its source's `history`.
    pub fn complete(
        &mut self,
        tracker: &mut Tracker,
        history: Option<&mut SourceHistory>,
        s: &VelocitySample,
        column: usize,
        tag: &ModelTag,
    ) -> HeadingEstimate {
        let (predictor, batch, history) = (self.staged_parts(history))
            .expect("only a sample staged with its history is completed");
        let p = history.complete(predictor, batch, column, s, &mut tracker.counters);
        tracker.finish(s, Some(p), tag)
    }

    /// The parts a staged pass works with, if this model stages and `history` is given.
    fn staged_parts<'a>(
        &'a mut self,
        history: Option<&'a mut SourceHistory>,
    ) -> Option<(
        &'a mut StreamPredictor,
        &'a mut StreamBatch,
        &'a mut SourceHistory,
    )> {
        match (self, history) {
            (
                Runner::Stream {
                    predictor,
                    batch: Some(batch),
                    ..
                },
                Some(history),
            ) => Some((predictor, batch, history)),
            _ => None,
        }
    }

    /// Starts a staged pass: nothing staged.
    pub fn clear_staged(&mut self) {
        if let Runner::Stream {
            batch: Some(batch), ..
        } = self
        {
            batch.clear();
        }
    }

    /// Whether this model answers sources that woke together in staged passes (a
    /// temporal network; not `kf` nor a per-epoch model).
    pub fn stages(&self) -> bool {
        matches!(self, Runner::Stream { batch: Some(_), .. })
    }

    /// The per-epoch predictor, for the batched path; `None` for a stateful model,
    /// whose samples must go one at a time.
    pub fn batched(&mut self) -> Option<&mut Predictor> {
        match self {
            Runner::Epoch(p) => Some(p),
            Runner::Stream { .. } => None,
        }
    }
}

/// One source's history of a stateful model, and the answer to its last sample
/// (what a repeated sample gets again).
#[derive(Debug, Clone)]
pub struct SourceHistory {
    history: History,
    /// `seq` and answer of the last sample the model saw.
    last: Option<(u64, Prediction)>,
}

impl SourceHistory {
    /// The model's history (state, reset counts).
    pub fn history(&self) -> &History {
        &self.history
    }

    /// The source's publisher is new (a source that was dropped and comes back): its
    /// history starts afresh, counted in `resets_restart` when it is not empty.
    pub fn restart(&mut self, counters: &mut Counters) {
        self.last = None;
        if !self.history.is_empty() {
            self.history.reset();
            counters.resets_restart += 1;
        }
    }

    /// The model's answer to `s` (booked as `booked`), `None` when the model must not
    /// see it; applies and counts the daemon's reset rules (module docs).
    pub fn predict(
        &mut self,
        predictor: &mut StreamPredictor,
        s: &VelocitySample,
        booked: Booked,
        counters: &mut Counters,
    ) -> Option<Prediction> {
        if let Some(answer) = self.before_model(s, booked, counters) {
            return answer;
        }
        let p = predictor.predict(&mut self.history, &epoch(s));
        self.after_model(s.seq, p, counters);
        Some(p)
    }

    /// [`predict`](Self::predict) with the model's part staged in `batch`
    /// ([`StreamPredictor::stage`]): `Ok(column)` when the epoch waits there (finish
    /// with [`complete`](Self::complete)), `Err` with the final answer otherwise.
    pub fn stage(
        &mut self,
        predictor: &mut StreamPredictor,
        batch: &mut StreamBatch,
        s: &VelocitySample,
        booked: Booked,
        counters: &mut Counters,
    ) -> Result<usize, Option<Prediction>> {
        if let Some(answer) = self.before_model(s, booked, counters) {
            return Err(answer);
        }
        predictor
            .stage(batch, &mut self.history, &epoch(s))
            .map_err(|p| {
                self.after_model(s.seq, p, counters);
                Some(p)
            })
    }

    /// The model's answer to `s`, staged in `column` of `batch` by [`stage`](Self::stage).
    pub fn complete(
        &mut self,
        predictor: &mut StreamPredictor,
        batch: &StreamBatch,
        column: usize,
        s: &VelocitySample,
        counters: &mut Counters,
    ) -> Prediction {
        let p = predictor.complete(batch, column, &mut self.history);
        self.after_model(s.seq, p, counters);
        p
    }

    /// The daemon's rules before the model: `Some(answer)` when the model must not
    /// run (`None` inside: not for the model; a repeat gets its first answer).
    fn before_model(
        &mut self,
        s: &VelocitySample,
        booked: Booked,
        counters: &mut Counters,
    ) -> Option<Option<Prediction>> {
        if booked.sequence == Sequence::Lower {
            self.restart(counters);
        } else if booked.backwards && !self.history.is_empty() {
            self.history.reset_because(Reset::Backwards);
            counters.resets_backwards += 1;
        }
        if !booked.model {
            return Some(None);
        }
        if booked.sequence == Sequence::Repeat {
            if let Some((seq, p)) = self.last {
                if seq == s.seq {
                    return Some(Some(p));
                }
            }
        }
        None
    }

    /// After the model answered `seq` with `p`: counts the reset its history made,
    /// keeps the answer for a repeat.
    fn after_model(&mut self, seq: u64, p: Prediction, counters: &mut Counters) {
        match self.history.last_reset() {
            Some(Reset::Gap) => counters.resets_gap += 1,
            Some(Reset::Backwards) => counters.resets_backwards += 1,
            Some(Reset::Explicit) => counters.resets_restart += 1,
            None => {}
        }
        self.last = Some((seq, p));
    }
}

/// The model's view of a sample: time in seconds from `timestamp_ns` (only differences
/// matter), the horizontal velocity and the receiver's speed accuracy. Public so that a
/// test can feed an in-process [`StreamPredictor`] exactly what ghnetd feeds it.
pub fn epoch(s: &VelocitySample) -> Epoch {
    Epoch {
        t_s: s.timestamp_ns as f64 * 1e-9,
        v_north: s.v_north,
        v_east: s.v_east,
        speed_acc: s.speed_accuracy,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ghnet_client::HeadingStatus;

    fn setup(model: &str) -> (Runner, Tracker, Option<SourceHistory>, ModelTag) {
        let model = Arc::new(Model::builtin(model).expect("built-in model"));
        let tag = ModelTag {
            id: model.id(),
            name: HeadingEstimate::encode_model_name(model.name()),
        };
        let runner = Runner::new(model, StatusPolicy::default(), None);
        let history = runner.history(None);
        (runner, Tracker::default(), history, tag)
    }

    const LIMITS: Limits = Limits { max_speed: 100.0 };
    const S: u64 = 1_000_000_000;

    fn sample(seq: u64, t_s: f64, vn: f32, ve: f32) -> VelocitySample {
        VelocitySample::new(1_700_000_000 * S + (t_s * 1e9) as u64, seq, vn, ve, 0.0)
    }

    #[test]
    fn per_epoch_models_keep_no_history() {
        let (runner, ..) = setup("ghnet-epoch");
        assert!(runner.history(None).is_none() && runner.max_gap_s().is_none());
    }

    /// A car that drives east and stops (10 Hz): `Held` at its last heading, σ
    /// growing, for half a second (the shipped `kf`'s tuned random walk, 120 °/√s,
    /// reaches the uniform σ, `Stationary`, within a second).
    #[test]
    fn kf_holds_a_stopped_source() {
        let (mut r, mut t, mut h, tag) = setup("kf");
        let mut go = |s: VelocitySample| r.answer(&mut t, h.as_mut(), &s, &LIMITS, &tag);
        let first = go(sample(0, 0.0, 0.0, 0.0));
        assert_eq!(first.heading_status(), Some(HeadingStatus::Stationary));
        for i in 1..50 {
            go(sample(i, i as f64 / 10.0, 0.0, 5.0));
        }
        let mut std = 0.0;
        for i in 50..55 {
            let a = go(sample(i, i as f64 / 10.0, 0.01, 0.0));
            assert_eq!(a.heading_status(), Some(HeadingStatus::Held), "{a:?}");
            assert!((a.heading_deg - 90.0).abs() < 5.0, "{a:?}");
            assert!(a.heading_std_deg > std, "{a:?}");
            std = a.heading_std_deg;
        }
    }

    /// Gaps, time going backwards and a restarted sequence each clear the history
    /// once and are counted once; a repeated sample gets its first answer again.
    #[test]
    fn resets_are_counted_once_and_repeats_do_not_advance() {
        let (mut r, mut t, mut h, tag) = setup("kf");
        let gap = r.max_gap_s().expect("stateful");
        let mut go = |s: VelocitySample| r.answer(&mut t, h.as_mut(), &s, &LIMITS, &tag);
        for i in 0..5 {
            go(sample(i, i as f64, 3.0, 3.0));
        }
        let a = go(sample(5, 5.0, 3.0, -3.0));
        let b = go(sample(5, 5.0, 3.0, -3.0));
        assert_eq!(a, b, "a repeat is answered like its first copy");
        go(sample(6, 6.0 + gap + 1.0, 3.0, 3.0)); // gap
        let back = go(sample(7, 2.0, 3.0, 3.0)); // backwards
        assert_eq!(back.heading_status(), Some(HeadingStatus::InvalidInput));
        go(sample(8, 3.0, 3.0, 3.0)); // forward again: a fresh history
        go(sample(0, 4.0, 3.0, 3.0)); // the publisher restarted its counter
        let c = t.counters;
        assert_eq!(
            (c.resets_gap, c.resets_backwards, c.resets_restart),
            (1, 1, 1)
        );
        assert_eq!((c.backwards, c.duplicates), (1, 2));
        let resets = h.as_ref().unwrap().history().resets();
        assert_eq!((resets.gap, resets.backwards, resets.explicit), (1, 1, 1));
    }
}
