//! The wire side of a source's samples: [`Counters`], the conversion between the
//! wire and the rules of `ghnet_inference::source` (which decide what happens to each
//! sample, the same in ghnetd and `ghnet infer`), the per-epoch batch path and the
//! `Stale` message. No IPC: kept apart from the event loop so it is tested directly,
//! and so the hot path is visibly allocation-free.

use ghnet_client::{flags, HeadingEstimate, HeadingStatus, VelocitySample, MODEL_NAME_LEN};
use ghnet_inference::{
    Admission, Prediction, Predictor, Runner, Sample, SampleCounts, SourceStream, Status,
};
use serde::Serialize;
/// Counters of one source. Every received sample is answered exactly once (unless
/// the send itself fails), so `received == answered + send_errors` at all times;
/// `Stale` messages are counted apart (`stale`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct Counters {
    /// Samples taken from the velocity service.
    pub received: u64,
    /// Estimates published on the heading service.
    pub answered: u64,
    /// Samples answered with `InvalidInput` (any reason, including `backwards`).
    pub invalid: u64,
    /// Missing sequence numbers: a jump from 4 to 7 adds 2. Also counts samples the
    /// subscriber buffer overwrote because the daemon fell behind.
    pub gaps: u64,
    /// Samples whose sequence number was not greater than the previous one (repeats,
    /// reordering, or a publisher restarting its counter).
    pub duplicates: u64,
    /// Samples whose timestamp was earlier than the previous sample's (answered as
    /// `InvalidInput`, also counted in `invalid`).
    pub backwards: u64,
    /// Answers that could not be published (loan or send failed).
    pub send_errors: u64,
    /// `Stale` messages published: times the source went silent for longer than
    /// `sources.stale_after_ms`. Not answers (no sample behind them), so not part of
    /// `answered`.
    pub stale: u64,
    /// Histories of a stateful model cleared because the time step was longer than
    /// the gap limit (the vehicle may have turned anywhere meanwhile). Always 0 for
    /// per-epoch models, which keep no history.
    pub resets_gap: u64,
    /// Histories cleared because time went backwards (the sample is also counted in
    /// `backwards`; counted here only when there was a history to clear).
    pub resets_backwards: u64,
    /// Histories cleared because the publisher restarted: its sequence numbers went
    /// down, or the source was dropped and came back.
    pub resets_restart: u64,
}

impl Counters {
    /// Field-wise sum, for totals and for sources that come back. Saturating, because
    /// `gaps` can be driven to `u64::MAX` by a single sample.
    pub fn add(&mut self, o: &Counters) {
        self.received = self.received.saturating_add(o.received);
        self.answered = self.answered.saturating_add(o.answered);
        self.invalid = self.invalid.saturating_add(o.invalid);
        self.gaps = self.gaps.saturating_add(o.gaps);
        self.duplicates = self.duplicates.saturating_add(o.duplicates);
        self.backwards = self.backwards.saturating_add(o.backwards);
        self.send_errors = self.send_errors.saturating_add(o.send_errors);
        self.stale = self.stale.saturating_add(o.stale);
        self.resets_gap = self.resets_gap.saturating_add(o.resets_gap);
        self.resets_backwards = self.resets_backwards.saturating_add(o.resets_backwards);
        self.resets_restart = self.resets_restart.saturating_add(o.resets_restart);
    }

    /// The rules' counts and the daemon's own delivery counts, as one set.
    fn of(c: &SampleCounts, d: &Delivery) -> Self {
        Counters {
            received: c.received,
            answered: d.answered,
            invalid: c.invalid,
            gaps: c.gaps,
            duplicates: c.duplicates,
            backwards: c.backwards,
            send_errors: d.send_errors,
            stale: d.stale,
            resets_gap: c.resets_gap,
            resets_backwards: c.resets_backwards,
            resets_restart: c.resets_restart,
        }
    }
}

/// The message that tells consumers a source went silent: the sequence number and
/// timestamp of `last` (the last answer, so of the last sample received), status
/// `Stale`, every measured field NaN and `processing_ns` 0, since no sample was
/// processed. Consumers that match answers to samples skip it.
pub(crate) fn stale_message(last: &HeadingEstimate) -> HeadingEstimate {
    HeadingEstimate {
        processing_ns: 0,
        heading_deg: f32::NAN,
        heading_std_deg: f32::NAN,
        atan2_deg: f32::NAN,
        speed: f32::NAN,
        status: HeadingStatus::Stale.as_u32(),
        ..*last
    }
}

/// What the model answers with, copied once per source so the hot path does not
/// touch the model's strings.
#[derive(Debug, Clone, Copy)]
pub(crate) struct ModelTag {
    /// [`HeadingEstimate::model_id`].
    pub(crate) id: u32,
    /// [`HeadingEstimate::model_name`].
    pub(crate) name: [u8; MODEL_NAME_LEN],
}

/// What only the daemon counts of a source: what became of its answers.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub(crate) struct Delivery {
    /// Answers published on every output.
    pub(crate) answered: u64,
    /// Answers some output could not take.
    pub(crate) send_errors: u64,
    /// `Stale` messages published.
    pub(crate) stale: u64,
}

/// One source's bookkeeping: its rules and history ([`SourceStream`]) and what became
/// of its answers ([`Delivery`]).
#[derive(Debug, Clone)]
pub(crate) struct Tracker {
    pub(crate) stream: SourceStream,
    pub(crate) delivery: Delivery,
}

impl Tracker {
    /// A source answered through `stream` that continues earlier `counters` (a source
    /// that comes back keeps its totals; its sequence and history start afresh).
    pub(crate) fn resume(stream: SourceStream, counters: Counters) -> Self {
        let c = counters;
        let counts = SampleCounts {
            received: c.received,
            invalid: c.invalid,
            gaps: c.gaps,
            duplicates: c.duplicates,
            backwards: c.backwards,
            resets_gap: c.resets_gap,
            resets_backwards: c.resets_backwards,
            resets_restart: c.resets_restart,
        };
        let delivery = Delivery {
            answered: c.answered,
            send_errors: c.send_errors,
            stale: c.stale,
        };
        Self {
            stream: stream.resume(counts),
            delivery,
        }
    }

    /// The counters so far.
    pub(crate) fn counters(&self) -> Counters {
        Counters::of(self.stream.counts(), &self.delivery)
    }

    /// Answers `s` with `runner`. `processing_ns` is left at 0 for the caller, who
    /// measures around the whole path.
    pub(crate) fn answer(
        &mut self,
        s: &VelocitySample,
        runner: &mut Runner,
        tag: &ModelTag,
    ) -> HeadingEstimate {
        let p = runner.answer(&mut self.stream, &sample(s));
        estimate(s, &p, tag)
    }
}

/// The rules' view of a wire sample: time in seconds from `timestamp_ns` (what the
/// model sees), the down velocity 0 when the receiver does not know it.
pub(crate) fn sample(s: &VelocitySample) -> Sample {
    let down_known = s.flags & flags::V_DOWN_UNKNOWN == 0;
    Sample {
        seq: s.seq,
        t_s: s.timestamp_ns as f64 * 1e-9,
        v_north: s.v_north,
        v_east: s.v_east,
        v_down: if down_known { s.v_down } else { 0.0 },
        speed_acc: s.speed_accuracy,
        flagged: s.flags & flags::INVALID != 0,
    }
}

/// The answer to `s` on the wire, from its prediction `p`. `processing_ns` is left
/// at 0.
pub(crate) fn estimate(s: &VelocitySample, p: &Prediction, tag: &ModelTag) -> HeadingEstimate {
    let (heading_deg, heading_std_deg, atan2_deg, speed, status) = match p.status {
        Status::Invalid => {
            let nan = f32::NAN;
            // The wire contract: NaN when a horizontal component is not finite
            // (hypot would give +inf for an infinite one); otherwise the speed,
            // which tells a consumer why e.g. a glitch above max_speed was refused.
            let finite = s.v_north.is_finite() && s.v_east.is_finite();
            let speed = if finite {
                s.v_north.hypot(s.v_east)
            } else {
                nan
            };
            (nan, nan, nan, speed, HeadingStatus::InvalidInput)
        }
        st => (
            p.heading_deg,
            p.std_deg,
            p.atan2_deg,
            p.speed,
            wire_status(st),
        ),
    };
    HeadingEstimate {
        timestamp_ns: s.timestamp_ns,
        seq: s.seq,
        processing_ns: 0,
        heading_deg,
        heading_std_deg,
        atan2_deg,
        speed,
        model_id: tag.id,
        status: status.as_u32(),
        model_name: tag.name,
    }
}

/// Scratch of the per-epoch batch path, made once (per daemon) so answering a batch
/// allocates nothing. Per batch: [`clear`](Self::clear), fill
/// [`samples`](Self::samples) (up to the capacity given to [`Batch::new`]), then three
/// steps, each sample on its own source's tracker (the samples may come from several
/// sources): [`book`](Self::book) every sample in order, one
/// [`predict`](Self::predict), [`finish`](Self::finish) every sample.
#[derive(Debug)]
pub(crate) struct Batch {
    /// The samples to answer, in arrival order per source.
    pub(crate) samples: Vec<VelocitySample>,
    /// Per sample: its row in the model inputs, or [`Self::NO_MODEL`] (answered by
    /// the rules, in `ruled`).
    row: Vec<u32>,
    /// Per sample the rules answered: that answer.
    ruled: Vec<Prediction>,
    /// Rows used in the model inputs.
    rows: usize,
    v_north: Vec<f32>,
    v_east: Vec<f32>,
    speed_acc: Vec<f32>,
    predictions: Vec<Prediction>,
}

impl Batch {
    const NO_MODEL: u32 = u32::MAX;

    /// Scratch for batches of up to `capacity` samples.
    pub(crate) fn new(capacity: usize) -> Self {
        Self {
            samples: Vec::with_capacity(capacity),
            row: vec![Self::NO_MODEL; capacity],
            ruled: vec![Prediction::INVALID; capacity],
            rows: 0,
            v_north: vec![0.0; capacity],
            v_east: vec![0.0; capacity],
            speed_acc: vec![0.0; capacity],
            predictions: vec![Prediction::INVALID; capacity],
        }
    }

    /// The most samples one batch takes.
    pub(crate) fn capacity(&self) -> usize {
        self.row.len()
    }

    /// Starts a new batch: no samples, no model inputs.
    pub(crate) fn clear(&mut self) {
        self.samples.clear();
        self.rows = 0;
    }

    /// Step 1: `samples[i]` through its source's rules (`stream`) and, if the model
    /// may see it, into the model inputs. Call for `i = 0, 1, ...` in order.
    ///
    /// # Panics
    /// If `i` is not below the capacity or `samples[i]` does not exist.
    pub(crate) fn book(&mut self, i: usize, stream: &mut SourceStream) {
        self.row[i] = match stream.admit(&sample(&self.samples[i])) {
            Admission::Answered(p) => {
                self.ruled[i] = p;
                Self::NO_MODEL
            }
            Admission::Model(e) => {
                let r = self.rows;
                (self.v_north[r], self.v_east[r], self.speed_acc[r]) =
                    (e.v_north, e.v_east, e.speed_acc);
                self.rows += 1;
                r as u32
            }
        };
    }

    /// Step 2: one model call for every booked sample the model may see.
    pub(crate) fn predict(&mut self, predictor: &mut Predictor) {
        let r = self.rows;
        predictor.predict_batch_with_accuracy(
            &self.v_north[..r],
            &self.v_east[..r],
            &self.speed_acc[..r],
            &mut self.predictions[..r],
        );
    }

    /// Step 3: the answer to `samples[i]`, recorded on the stream it was booked on.
    /// `processing_ns` is left at 0.
    pub(crate) fn finish(
        &self,
        i: usize,
        stream: &mut SourceStream,
        tag: &ModelTag,
    ) -> HeadingEstimate {
        let s = &self.samples[i];
        let p = match self.row[i] {
            Self::NO_MODEL => self.ruled[i],
            row => stream.record(s.seq, self.predictions[row as usize]),
        };
        estimate(s, &p, tag)
    }
}

/// models::Status → wire status. `Invalid` is handled by the caller.
fn wire_status(s: Status) -> HeadingStatus {
    match s {
        Status::Ok => HeadingStatus::Ok,
        Status::LowSpeed => HeadingStatus::LowSpeed,
        Status::Stationary => HeadingStatus::Stationary,
        Status::Invalid => HeadingStatus::InvalidInput,
        Status::Held => HeadingStatus::Held,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Arc;

    fn setup() -> (Runner, ModelTag) {
        let model = Arc::new(crate::test_model::load());
        let tag = ModelTag {
            id: model.id(),
            name: HeadingEstimate::encode_model_name(model.name()),
        };
        (Runner::new(model, Default::default(), None), tag)
    }

    fn tracker(r: &Runner) -> Tracker {
        Tracker::resume(r.stream(None), Counters::default())
    }

    /// A valid moving sample gets Ok or LowSpeed, depending on the model's σ.
    fn moving_ok(h: &HeadingEstimate) -> bool {
        matches!(
            h.heading_status(),
            Some(HeadingStatus::Ok | HeadingStatus::LowSpeed)
        )
    }

    fn sample(seq: u64, ts: u64, vn: f32, ve: f32) -> VelocitySample {
        VelocitySample::new(ts, seq, vn, ve, 0.0)
    }

    #[test]
    fn valid_sample_is_answered_with_echo_and_heading() {
        let (mut p, tag) = setup();
        let mut t = tracker(&p);
        let h = t.answer(&sample(5, 1000, 0.0, 10.0), &mut p, &tag);
        assert_eq!((h.seq, h.timestamp_ns), (5, 1000));
        assert!(moving_ok(&h), "{h:?}");
        assert!(
            (h.atan2_deg - 90.0).abs() < 1e-3,
            "east is 90°: {}",
            h.atan2_deg
        );
        assert!((0.0..360.0).contains(&h.heading_deg), "{}", h.heading_deg);
        assert!(h.heading_std_deg > 0.0);
        assert!((h.speed - 10.0).abs() < 1e-5);
        assert_eq!(h.model_id, tag.id);
        assert_eq!(h.model_name_str(), crate::test_model::TEST_MODEL);
        assert_eq!(t.counters().received, 1);
        assert_eq!(t.counters().invalid, 0);
    }

    #[test]
    fn stationary_maps_through() {
        let (mut p, tag) = setup();
        let h = tracker(&p).answer(&sample(0, 0, 0.0, 0.0), &mut p, &tag);
        assert_eq!(h.heading_status(), Some(HeadingStatus::Stationary));
    }

    #[test]
    fn invalid_inputs_are_answered_and_counted() {
        let (mut p, tag) = setup();
        let mut cases = vec![
            sample(0, 0, f32::NAN, 1.0),
            sample(0, 0, 1.0, f32::INFINITY),
            sample(0, 0, 80.0, 80.0), // 113 m/s horizontal
        ];
        let mut s = sample(0, 0, 1.0, 1.0);
        s.v_down = 100.0; // horizontal fine, 3-D speed above the limit
        cases.push(s);
        s = sample(0, 0, 1.0, 1.0);
        s.v_down = f32::NAN;
        cases.push(s);
        s = sample(0, 0, 1.0, 1.0);
        s.speed_accuracy = -0.1;
        cases.push(s);
        s.speed_accuracy = f32::INFINITY;
        cases.push(s);
        s = sample(0, 0, 1.0, 1.0);
        s.flags = flags::INVALID;
        cases.push(s);
        for (i, c) in cases.iter().enumerate() {
            let mut t = tracker(&p);
            let h = t.answer(c, &mut p, &tag);
            assert_eq!(
                h.heading_status(),
                Some(HeadingStatus::InvalidInput),
                "case {i}: {c:?}"
            );
            assert!(
                h.heading_deg.is_nan() && h.heading_std_deg.is_nan(),
                "case {i}"
            );
            assert_eq!(t.counters().invalid, 1, "case {i}");
        }
    }

    /// `speed` of an invalid answer: NaN for a non-finite horizontal component (as
    /// client/README.md says), the measured value for finite ones.
    #[test]
    fn invalid_speed_is_nan_only_for_non_finite_input() {
        let (mut p, tag) = setup();
        let mut speed = |vn, ve| {
            let h = tracker(&p).answer(&sample(0, 0, vn, ve), &mut p, &tag);
            assert_eq!(h.heading_status(), Some(HeadingStatus::InvalidInput));
            h.speed
        };
        for (vn, ve) in [
            (f32::INFINITY, 0.0),
            (0.0, f32::NEG_INFINITY),
            (f32::INFINITY, f32::NAN),
            (f32::NAN, 1.0),
        ] {
            assert!(speed(vn, ve).is_nan(), "{vn}, {ve}");
        }
        assert_eq!(
            speed(90.0, 120.0),
            150.0,
            "above max_speed: refused, speed given"
        );
    }

    #[test]
    fn unknown_down_and_unknown_accuracy_are_fine() {
        let (mut p, tag) = setup();
        let mut s = sample(0, 0, 3.0, 4.0);
        s.v_down = f32::NAN;
        s.flags = flags::V_DOWN_UNKNOWN | flags::SIMULATED | (1 << 20);
        assert!(s.speed_accuracy.is_nan());
        let h = tracker(&p).answer(&s, &mut p, &tag);
        assert!(moving_ok(&h), "{h:?}");
    }

    #[test]
    fn gaps_duplicates_and_backwards_time() {
        let (mut p, tag) = setup();
        let mut t = tracker(&p);
        let mut go = |seq, ts| t.answer(&sample(seq, ts, 0.0, 5.0), &mut p, &tag);
        go(10, 100);
        go(11, 110);
        go(14, 140); // gap of 2
        go(14, 140); // duplicate, same time is not backwards
        let h = go(15, 120); // backwards
        assert_eq!(h.heading_status(), Some(HeadingStatus::InvalidInput));
        let h = go(16, 130); // forward again from the last sample
        assert!(moving_ok(&h), "{h:?}");
        go(0, 200); // publisher restarted its counter
        go(1, 210);
        let c = t.counters();
        assert_eq!(c.received, 8);
        assert_eq!(c.gaps, 2);
        assert_eq!(c.duplicates, 2);
        assert_eq!(c.backwards, 1);
        assert_eq!(c.invalid, 1);
    }

    /// The batch steps (book each, one batch model call, finish each) answer like
    /// `answer` one by one, valid, invalid, backwards and stationary samples mixed:
    /// the same statuses and counters, values equal up to the batch kernel's rounding.
    #[test]
    fn batch_steps_answer_like_answer() {
        let (mut p, tag) = setup();
        let mut inputs: Vec<VelocitySample> = (0..40)
            .map(|i| {
                let mut s = sample(i, 10 * i, 0.3 * i as f32 - 6.0, 2.0 - 0.1 * i as f32);
                s.speed_accuracy = if i % 2 == 0 { f32::NAN } else { 0.2 };
                s
            })
            .collect();
        inputs[3].v_north = f32::NAN; // invalid input
        inputs[5].timestamp_ns = 0; // backwards in time
        inputs[7].flags = flags::INVALID;
        inputs[9] = sample(9, 90, 0.0, 0.0); // stationary
        let (mut one, mut batched) = (tracker(&p), tracker(&p));
        let want: Vec<_> = inputs.iter().map(|s| one.answer(s, &mut p, &tag)).collect();

        let mut batch = Batch::new(64);
        batch.clear();
        batch.samples.extend_from_slice(&inputs);
        for i in 0..inputs.len() {
            batch.book(i, &mut batched.stream);
        }
        batch.predict(p.batched().expect("per-epoch model"));
        let got: Vec<_> = (0..inputs.len())
            .map(|i| batch.finish(i, &mut batched.stream, &tag))
            .collect();
        for ((s, got), w) in inputs.iter().zip(&got).zip(&want) {
            assert_eq!((got.seq, got.status), (w.seq, w.status), "{s:?}");
            for (a, b) in [
                (got.heading_deg, w.heading_deg),
                (got.heading_std_deg, w.heading_std_deg),
                (got.speed, w.speed),
            ] {
                assert!(
                    a == b || (a.is_nan() && b.is_nan()) || (a - b).abs() < 1e-3,
                    "{s:?}: {a} vs {b}"
                );
            }
        }
        assert_eq!(batched.counters(), one.counters());
        assert_eq!(one.counters().invalid, 3);
    }

    #[test]
    fn stale_message_echoes_the_last_sample() {
        let (mut p, tag) = setup();
        let last = tracker(&p).answer(&sample(41, 4100, 0.0, 5.0), &mut p, &tag);
        let s = stale_message(&last);
        assert_eq!((s.seq, s.timestamp_ns), (41, 4100));
        assert_eq!(s.heading_status(), Some(HeadingStatus::Stale));
        assert!(s.heading_deg.is_nan() && s.heading_std_deg.is_nan());
        assert_eq!(s.processing_ns, 0);
        assert_eq!((s.model_id, s.model_name), (tag.id, tag.name));
    }

    #[test]
    fn resume_keeps_counts_but_not_sequence() {
        let (mut p, tag) = setup();
        let mut t = tracker(&p);
        t.answer(&sample(100, 100, 1.0, 1.0), &mut p, &tag);
        let mut t = Tracker::resume(p.stream(None), t.counters());
        t.answer(&sample(0, 0, 1.0, 1.0), &mut p, &tag);
        assert_eq!(t.counters().received, 2);
        assert_eq!(t.counters().duplicates + t.counters().backwards, 0);
    }

    /// Stateful models: each source's history, its resets and repeats.
    mod stateful {
        use crate::answer::{Counters, ModelTag, Tracker};
        use ghnet_client::{HeadingEstimate, HeadingStatus, VelocitySample};
        use ghnet_inference::{Model, Runner, StatusPolicy};
        use std::sync::Arc;

        fn setup(model: &str) -> (Runner, Tracker, ModelTag) {
            let model = Arc::new(Model::builtin(model).expect("built-in model"));
            let tag = ModelTag {
                id: model.id(),
                name: HeadingEstimate::encode_model_name(model.name()),
            };
            let runner = Runner::new(model, StatusPolicy::default(), None);
            let tracker = Tracker::resume(runner.stream(None), Counters::default());
            (runner, tracker, tag)
        }

        const S: u64 = 1_000_000_000;

        fn at(seq: u64, t_s: f64, vn: f32, ve: f32) -> VelocitySample {
            VelocitySample::new(1_700_000_000 * S + (t_s * 1e9) as u64, seq, vn, ve, 0.0)
        }

        #[test]
        fn per_epoch_models_keep_no_history() {
            let (runner, t, _) = setup("ghnet-epoch");
            assert!(t.stream.history().is_none() && runner.max_gap_s().is_none());
        }

        /// A car that drives east and stops (10 Hz): `Held` at its last heading, σ
        /// growing, for half a second (the shipped `kf`'s tuned random walk, 120 °/√s,
        /// reaches the uniform σ, `Stationary`, within a second).
        #[test]
        fn kf_holds_a_stopped_source() {
            let (mut r, mut t, tag) = setup("kf");
            let mut go = |s: VelocitySample| t.answer(&s, &mut r, &tag);
            let first = go(at(0, 0.0, 0.0, 0.0));
            assert_eq!(first.heading_status(), Some(HeadingStatus::Stationary));
            for i in 1..50 {
                go(at(i, i as f64 / 10.0, 0.0, 5.0));
            }
            let mut std = 0.0;
            for i in 50..55 {
                let a = go(at(i, i as f64 / 10.0, 0.01, 0.0));
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
            let (mut r, mut t, tag) = setup("kf");
            let gap = r.max_gap_s().expect("stateful");
            let mut go = |s: VelocitySample| t.answer(&s, &mut r, &tag);
            for i in 0..5 {
                go(at(i, i as f64, 3.0, 3.0));
            }
            let a = go(at(5, 5.0, 3.0, -3.0));
            let b = go(at(5, 5.0, 3.0, -3.0));
            assert_eq!(a, b, "a repeat is answered like its first copy");
            go(at(6, 6.0 + gap + 1.0, 3.0, 3.0)); // gap
            let back = go(at(7, 2.0, 3.0, 3.0)); // backwards
            assert_eq!(back.heading_status(), Some(HeadingStatus::InvalidInput));
            go(at(8, 3.0, 3.0, 3.0)); // forward again: a fresh history
            go(at(0, 4.0, 3.0, 3.0)); // the publisher restarted its counter
            let c = t.counters();
            assert_eq!(
                (c.resets_gap, c.resets_backwards, c.resets_restart),
                (1, 1, 1)
            );
            assert_eq!((c.backwards, c.duplicates), (1, 2));
            let resets = t.stream.history().unwrap().resets();
            assert_eq!((resets.gap, resets.backwards, resets.explicit), (1, 1, 1));
        }
    }
}
