//! Per-sample logic without IPC: input checks, sequence/time bookkeeping, the model
//! call and the mapping to the wire. Kept apart from the event loop so it is tested
//! directly, and so the hot path is visibly allocation-free.

use ghnet_client::{flags, HeadingEstimate, HeadingStatus, VelocitySample, MODEL_NAME_LEN};
use ghnet_models::{Prediction, Predictor, Status};
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
}

/// The message that tells consumers a source went silent: the sequence number and
/// timestamp of `last` (the last answer, so of the last sample received), status
/// `Stale`, every measured field NaN and `processing_ns` 0, since no sample was
/// processed. Consumers that match answers to samples skip it.
pub fn stale_message(last: &HeadingEstimate) -> HeadingEstimate {
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

/// Input limits besides the model's own (which checks horizontal speed itself).
#[derive(Debug, Clone, Copy)]
pub struct Limits {
    /// Largest accepted 3-D speed, m/s (`model.max_speed`).
    pub max_speed: f32,
}

/// What the model answers with, copied once per source so the hot path does not
/// touch the model's strings.
#[derive(Debug, Clone, Copy)]
pub struct ModelTag {
    /// [`HeadingEstimate::model_id`].
    pub id: u32,
    /// [`HeadingEstimate::model_name`].
    pub name: [u8; MODEL_NAME_LEN],
}

/// How a sample's sequence number follows the previous sample's of its source.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Sequence {
    /// No previous sample (the source is new, or came back).
    First,
    /// Higher: the normal case (with a gap if it is more than one higher).
    Next,
    /// The same: a repeated sample.
    Repeat,
    /// Lower: the publisher restarted its counter (or reordered).
    Lower,
}

/// What [`Tracker::book_detailed`] found about a sample.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Booked {
    /// The model may see it (`false`: answered `InvalidInput`).
    pub model: bool,
    /// How its sequence number follows the previous one.
    pub sequence: Sequence,
    /// Its timestamp is below the previous sample's.
    pub backwards: bool,
}

/// Per-source state: the previous sample's sequence number and timestamp, and the
/// counters.
#[derive(Debug, Clone, Default)]
pub struct Tracker {
    last: Option<(u64, u64)>,
    /// The counters so far.
    pub counters: Counters,
}

impl Tracker {
    /// A tracker that continues earlier counters (a source that comes back) but
    /// forgets the previous sample (a new publisher may restart its sequence).
    pub fn resume(counters: Counters) -> Self {
        Self {
            last: None,
            counters,
        }
    }

    /// Books `s` and computes its answer. `processing_ns` is left at 0 for the caller,
    /// who measures around the whole path.
    pub fn answer(
        &mut self,
        s: &VelocitySample,
        predictor: &mut Predictor,
        limits: &Limits,
        tag: &ModelTag,
    ) -> HeadingEstimate {
        // The receiver's speed accuracy (NaN when unknown) lets full-circle models
        // report this receiver's σ rather than an average receiver's.
        let prediction = self
            .book(s, limits)
            .then(|| predictor.predict_with_accuracy(s.v_north, s.v_east, s.speed_accuracy));
        self.finish(s, prediction, tag)
    }

    /// First half of [`answer`](Self::answer), for callers that run the model on many
    /// samples in one call (`Predictor::predict_batch_with_accuracy` costs about half
    /// per sample): books `s` (counters, sequence, time) and says whether the model
    /// should see it. `false` means the answer is `InvalidInput` without a prediction.
    /// Book samples in arrival order, then [`finish`](Self::finish) each.
    pub fn book(&mut self, s: &VelocitySample, limits: &Limits) -> bool {
        self.book_detailed(s, limits).model
    }

    /// [`book`](Self::book), also telling how `s` follows the previous sample: what a
    /// source's history needs to know (a restarted publisher, a repeated sample, time
    /// going backwards).
    pub fn book_detailed(&mut self, s: &VelocitySample, limits: &Limits) -> Booked {
        self.counters.received += 1;
        let mut booked = Booked {
            model: false,
            sequence: Sequence::First,
            backwards: false,
        };
        if let Some((last_seq, last_ts)) = self.last {
            booked.sequence = match s.seq.cmp(&last_seq) {
                std::cmp::Ordering::Greater => Sequence::Next,
                std::cmp::Ordering::Equal => Sequence::Repeat,
                std::cmp::Ordering::Less => Sequence::Lower,
            };
            if s.seq > last_seq {
                // Saturating: a publisher may jump to u64::MAX and back, and a debug
                // build must not panic on what a remote process sends.
                self.counters.gaps = self.counters.gaps.saturating_add(s.seq - last_seq - 1);
            } else {
                self.counters.duplicates += 1;
            }
            booked.backwards = s.timestamp_ns < last_ts;
        }
        // Always move on to this sample: one outlier then costs at most one more
        // flagged sample instead of poisoning the rest of the stream.
        self.last = Some((s.seq, s.timestamp_ns));

        if booked.backwards {
            self.counters.backwards += 1;
        } else {
            booked.model = input_ok(s, limits);
        }
        booked
    }

    /// Second half of [`answer`](Self::answer): the answer to `s` from the model's
    /// `prediction` (`None` when [`book`](Self::book) said the model must not see it).
    /// `processing_ns` is left at 0.
    pub fn finish(
        &mut self,
        s: &VelocitySample,
        prediction: Option<Prediction>,
        tag: &ModelTag,
    ) -> HeadingEstimate {
        let (heading_deg, heading_std_deg, atan2_deg, speed, status) = match prediction {
            Some(Prediction {
                heading_deg,
                std_deg,
                atan2_deg,
                speed,
                status,
            }) if status != Status::Invalid => {
                (heading_deg, std_deg, atan2_deg, speed, wire_status(status))
            }
            _ => {
                self.counters.invalid += 1;
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
}

/// Scratch of the batch path, made once (per daemon) so answering a batch allocates
/// nothing. Per batch: [`clear`](Self::clear), fill [`samples`](Self::samples) (up to
/// the capacity given to [`Batch::new`]), then three steps, each sample on its own
/// source's tracker (the samples may come from several sources):
/// [`book`](Self::book) every sample in order, one [`predict`](Self::predict),
/// [`finish`](Self::finish) every sample.
#[derive(Debug)]
pub struct Batch {
    /// The samples to answer, in arrival order per source.
    pub samples: Vec<VelocitySample>,
    /// Per sample: its row in the model inputs, or [`Self::NO_MODEL`] (answered
    /// `InvalidInput` without a prediction).
    row: Vec<u32>,
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
    pub fn new(capacity: usize) -> Self {
        Self {
            samples: Vec::with_capacity(capacity),
            row: vec![Self::NO_MODEL; capacity],
            rows: 0,
            v_north: vec![0.0; capacity],
            v_east: vec![0.0; capacity],
            speed_acc: vec![0.0; capacity],
            predictions: vec![Prediction::INVALID; capacity],
        }
    }

    /// The most samples one batch takes.
    pub fn capacity(&self) -> usize {
        self.row.len()
    }

    /// Starts a new batch: no samples, no model inputs.
    pub fn clear(&mut self) {
        self.samples.clear();
        self.rows = 0;
    }

    /// Step 1: books `samples[i]` on its source's `tracker` (see [`Tracker::book`])
    /// and, if the model may see it, adds it to the model inputs. Call for `i = 0, 1,
    /// ...` in order.
    ///
    /// # Panics
    /// If `i` is not below the capacity or `samples[i]` does not exist.
    pub fn book(&mut self, i: usize, tracker: &mut Tracker, limits: &Limits) {
        let s = &self.samples[i];
        self.row[i] = if tracker.book(s, limits) {
            let r = self.rows;
            (self.v_north[r], self.v_east[r], self.speed_acc[r]) =
                (s.v_north, s.v_east, s.speed_accuracy);
            self.rows += 1;
            r as u32
        } else {
            Self::NO_MODEL
        };
    }

    /// Step 2: one model call for every booked sample the model may see.
    pub fn predict(&mut self, predictor: &mut Predictor) {
        let r = self.rows;
        predictor.predict_batch_with_accuracy(
            &self.v_north[..r],
            &self.v_east[..r],
            &self.speed_acc[..r],
            &mut self.predictions[..r],
        );
    }

    /// Step 3: the answer to `samples[i]`, from the tracker it was booked on (see
    /// [`Tracker::finish`]). `processing_ns` is left at 0.
    pub fn finish(&self, i: usize, tracker: &mut Tracker, tag: &ModelTag) -> HeadingEstimate {
        let row = self.row[i];
        let prediction = (row != Self::NO_MODEL).then(|| self.predictions[row as usize]);
        tracker.finish(&self.samples[i], prediction, tag)
    }
}

/// The daemon's input checks (the model additionally rejects non-finite horizontal
/// components and horizontal speed above its `max_speed`).
fn input_ok(s: &VelocitySample, limits: &Limits) -> bool {
    if s.flags & flags::INVALID != 0 {
        return false;
    }
    let down_known = s.flags & flags::V_DOWN_UNKNOWN == 0;
    let v_down = if down_known { s.v_down } else { 0.0 };
    if !(s.v_north.is_finite() && s.v_east.is_finite() && v_down.is_finite()) {
        return false;
    }
    // NaN = unknown is fine; negative or infinite is a broken receiver.
    let acc = s.speed_accuracy;
    let acc_ok = acc.is_nan() || (acc >= 0.0 && acc.is_finite());
    if !acc_ok {
        return false;
    }
    let speed3 = (s.v_north * s.v_north + s.v_east * s.v_east + v_down * v_down).sqrt();
    speed3 <= limits.max_speed
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

    fn setup() -> (Predictor, Limits, ModelTag) {
        let model = Arc::new(crate::test_model::load());
        let tag = ModelTag {
            id: model.id(),
            name: HeadingEstimate::encode_model_name(model.name()),
        };
        (Predictor::new(model), Limits { max_speed: 100.0 }, tag)
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
        let (mut p, l, tag) = setup();
        let mut t = Tracker::default();
        let h = t.answer(&sample(5, 1000, 0.0, 10.0), &mut p, &l, &tag);
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
        assert_eq!(t.counters.received, 1);
        assert_eq!(t.counters.invalid, 0);
    }

    #[test]
    fn stationary_maps_through() {
        let (mut p, l, tag) = setup();
        let h = Tracker::default().answer(&sample(0, 0, 0.0, 0.0), &mut p, &l, &tag);
        assert_eq!(h.heading_status(), Some(HeadingStatus::Stationary));
    }

    #[test]
    fn invalid_inputs_are_answered_and_counted() {
        let (mut p, l, tag) = setup();
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
            let mut t = Tracker::default();
            let h = t.answer(c, &mut p, &l, &tag);
            assert_eq!(
                h.heading_status(),
                Some(HeadingStatus::InvalidInput),
                "case {i}: {c:?}"
            );
            assert!(
                h.heading_deg.is_nan() && h.heading_std_deg.is_nan(),
                "case {i}"
            );
            assert_eq!(t.counters.invalid, 1, "case {i}");
        }
    }

    /// `speed` of an invalid answer: NaN for a non-finite horizontal component (as
    /// client/README.md says), the measured value for finite ones.
    #[test]
    fn invalid_speed_is_nan_only_for_non_finite_input() {
        let (mut p, l, tag) = setup();
        let mut speed = |vn, ve| {
            let h = Tracker::default().answer(&sample(0, 0, vn, ve), &mut p, &l, &tag);
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
        let (mut p, l, tag) = setup();
        let mut s = sample(0, 0, 3.0, 4.0);
        s.v_down = f32::NAN;
        s.flags = flags::V_DOWN_UNKNOWN | flags::SIMULATED | (1 << 20);
        assert!(s.speed_accuracy.is_nan());
        let h = Tracker::default().answer(&s, &mut p, &l, &tag);
        assert!(moving_ok(&h), "{h:?}");
    }

    #[test]
    fn gaps_duplicates_and_backwards_time() {
        let (mut p, l, tag) = setup();
        let mut t = Tracker::default();
        let mut go = |seq, ts| t.answer(&sample(seq, ts, 0.0, 5.0), &mut p, &l, &tag);
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
        let c = t.counters;
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
        let (mut p, l, tag) = setup();
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
        let (mut one, mut batched) = (Tracker::default(), Tracker::default());
        let want: Vec<_> = inputs
            .iter()
            .map(|s| one.answer(s, &mut p, &l, &tag))
            .collect();

        let mut batch = Batch::new(64);
        batch.clear();
        batch.samples.extend_from_slice(&inputs);
        for i in 0..inputs.len() {
            batch.book(i, &mut batched, &l);
        }
        batch.predict(&mut p);
        let got: Vec<_> = (0..inputs.len())
            .map(|i| batch.finish(i, &mut batched, &tag))
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
        assert_eq!(batched.counters, one.counters);
        assert_eq!(one.counters.invalid, 3);
    }

    #[test]
    fn stale_message_echoes_the_last_sample() {
        let (mut p, l, tag) = setup();
        let last = Tracker::default().answer(&sample(41, 4100, 0.0, 5.0), &mut p, &l, &tag);
        let s = stale_message(&last);
        assert_eq!((s.seq, s.timestamp_ns), (41, 4100));
        assert_eq!(s.heading_status(), Some(HeadingStatus::Stale));
        assert!(s.heading_deg.is_nan() && s.heading_std_deg.is_nan());
        assert_eq!(s.processing_ns, 0);
        assert_eq!((s.model_id, s.model_name), (tag.id, tag.name));
    }

    #[test]
    fn resume_keeps_counts_but_not_sequence() {
        let (mut p, l, tag) = setup();
        let mut t = Tracker::default();
        t.answer(&sample(100, 100, 1.0, 1.0), &mut p, &l, &tag);
        let mut t = Tracker::resume(t.counters);
        t.answer(&sample(0, 0, 1.0, 1.0), &mut p, &l, &tag);
        assert_eq!(t.counters.received, 2);
        assert_eq!(t.counters.duplicates + t.counters.backwards, 0);
    }
}
