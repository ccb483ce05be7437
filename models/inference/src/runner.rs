//! [`Runner`]: a model as a server of many sources runs it, answering each source's
//! samples through that source's [`SourceStream`] (its rules and history).
//!
//! A per-epoch model answers one sample, or the samples of many sources in one batched
//! call ([`Runner::batched`]). A stateful model answers each source's samples in order
//! against its history; the samples of sources that arrived together may share one
//! pass through a temporal network's convolutions ([`Runner::stage`],
//! [`run_staged`](Runner::run_staged), [`complete`](Runner::complete)), which reads the
//! weights once for all of them; the answers are bit for bit those of one at a time.

use std::sync::Arc;

use crate::model::Model;
use crate::prediction::{Prediction, StatusPolicy};
use crate::predictor::Predictor;
use crate::source::{Admission, Sample, SourceStream};
use crate::stream::{model_max_gap_s, Platform, Staged, StreamBatch, StreamPredictor};

/// Most epochs in one staged pass: one per source that woke, up to ghnetd's default
/// source limit; more wait for the next pass.
pub const STREAM_BATCH: usize = 128;

/// The model as a server runs it: one per server (its scratch serves every source).
#[derive(Debug)]
pub enum Runner {
    /// A per-epoch model; no history. Boxed: its batch scratch is much larger than the
    /// stream predictor (one per server either way).
    Epoch(Box<Predictor>),
    /// A stateful model: each sample against its source's history, in order.
    Stream {
        /// Runs the model.
        predictor: StreamPredictor,
        /// A gap limit replacing the model's own.
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

    /// A new source's stream, its history (stateful models) on `platform` (`None`: the
    /// model's default).
    pub fn stream(&self, platform: Option<Platform>) -> SourceStream {
        match self {
            Runner::Epoch(p) => SourceStream::new(None, p.policy().max_speed),
            Runner::Stream {
                predictor,
                max_gap_s,
                ..
            } => {
                let mut h = predictor.history();
                if let Some(p) = platform {
                    h = h.with_platform(p);
                }
                if let Some(g) = max_gap_s {
                    h = h.with_max_gap(*g);
                }
                SourceStream::new(Some(h), predictor.policy().max_speed)
            }
        }
    }

    /// The gap limit histories use, seconds (`None` for a per-epoch model): the
    /// replacement given to [`new`](Self::new), else the model's own.
    pub fn max_gap_s(&self) -> Option<f64> {
        match self {
            Runner::Epoch(_) => None,
            Runner::Stream {
                predictor,
                max_gap_s,
                ..
            } => Some(max_gap_s.unwrap_or_else(|| model_max_gap_s(predictor.model()))),
        }
    }

    /// Sample `s` of the source whose stream is `src`, answered.
    pub fn answer(&mut self, src: &mut SourceStream, s: &Sample) -> Prediction {
        let e = match src.admit(s) {
            Admission::Answered(p) => return p,
            Admission::Model(e) => e,
        };
        let p = match (self, src.history_mut()) {
            (Runner::Stream { predictor, .. }, Some(h)) => predictor.predict(h, &e),
            (Runner::Epoch(p), _) => p.predict_with_accuracy(e.v_north, e.v_east, e.speed_acc),
            (Runner::Stream { .. }, None) => {
                unreachable!("a stateful model's stream has a history")
            }
        };
        src.record(s.seq, p)
    }

    /// Step 1 of a staged pass over sources that arrived together: sample `s` of
    /// `src`, answered or waiting. At most one sample per source per pass, and every
    /// waiting one completed.
    pub fn stage(&mut self, src: &mut SourceStream, s: &Sample) -> Staged {
        let Runner::Stream {
            predictor,
            batch: Some(batch),
            ..
        } = self
        else {
            return Staged::Answered(self.answer(src, s));
        };
        let e = match src.admit(s) {
            Admission::Answered(p) => return Staged::Answered(p),
            Admission::Model(e) => e,
        };
        let h = src
            .history_mut()
            .expect("a stateful model's stream has a history");
        match predictor.stage(batch, h, &e) {
            Staged::Answered(p) => Staged::Answered(src.record(s.seq, p)),
            waiting => waiting,
        }
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

    /// Step 3: the answer to `s`, staged in `column` with its source's stream `src`.
    pub fn complete(&mut self, src: &mut SourceStream, s: &Sample, column: usize) -> Prediction {
        let (
            Runner::Stream {
                predictor,
                batch: Some(batch),
                ..
            },
            Some(h),
        ) = (self, src.history_mut())
        else {
            panic!("only a sample staged with its source's stream is completed")
        };
        let p = predictor.complete(batch, column, h);
        src.record(s.seq, p)
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

    /// Whether this model answers sources that arrived together in staged passes (a
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
