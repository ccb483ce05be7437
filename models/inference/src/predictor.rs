//! [`Predictor`]: runs a model one sample (or one batch) at a time without history; it
//! owns the scratch buffers, so the hot path (`predict`, `predict_batch`) allocates
//! nothing.

use std::sync::Arc;

use faer::Mat;

use crate::head::scale_input;
use crate::model::{Engine, Model};
use crate::net::Scratch;
use crate::prediction::{finish_epoch, Prediction, StatusPolicy};
use crate::stream::{Epoch, History, StreamPredictor};

/// Runs a model one sample at a time with no history; owns the scratch so calls
/// allocate nothing. One per thread.
///
/// For per-epoch models this is the whole story. A stateful model (temporal, `kf`) run
/// here sees every sample as the first of its history, which is what it answers after a
/// reset: atan2 with a σ, never `Held`. Use [`StreamPredictor`] with one [`History`]
/// per source to get what history buys.
#[derive(Debug)]
pub struct Predictor {
    model: Arc<Model>,
    policy: StatusPolicy,
    scratch: Option<Scratch>,
    out: Vec<f32>,
    xb: Mat<f32>,
    yb: Mat<f32>,
    stream: Option<(StreamPredictor, History)>,
}

/// Batch size the predictor's scratch is sized for; larger batches run in chunks.
const BATCH_CHUNK: usize = 256;

impl Predictor {
    /// A predictor for `model` with the default [`StatusPolicy`].
    pub fn new(model: Arc<Model>) -> Self {
        let (net, stream) = match model.engine() {
            Engine::Epoch(net) => (Some(net), None),
            _ => {
                let sp = StreamPredictor::new(model.clone());
                let h = sp.history();
                (None, Some((sp, h)))
            }
        };
        let k = net.map_or(1, |n| n.outputs());
        let cols = if net.is_some() { BATCH_CHUNK } else { 0 };
        Self {
            scratch: net.map(|n| n.scratch(BATCH_CHUNK)),
            out: vec![0.0; k],
            xb: Mat::zeros(2, cols),
            yb: Mat::zeros(k, cols),
            policy: StatusPolicy::default(),
            stream,
            model,
        }
    }

    /// Replace the status thresholds.
    pub fn with_policy(mut self, policy: StatusPolicy) -> Self {
        self.policy = policy;
        if let Some((sp, h)) = self.stream.take() {
            self.stream = Some((sp.with_policy(policy), h));
        }
        self
    }

    /// The model.
    pub fn model(&self) -> &Arc<Model> {
        &self.model
    }

    /// The thresholds in use.
    pub fn policy(&self) -> &StatusPolicy {
        &self.policy
    }

    #[inline]
    fn validate(&self, v_north: f32, v_east: f32) -> Option<f32> {
        let speed = v_north.hypot(v_east);
        (v_north.is_finite() && v_east.is_finite() && speed <= self.policy.max_speed)
            .then_some(speed)
    }

    /// A stateful model's answer to one sample as the first of a fresh history.
    fn stateless(&mut self, v_north: f32, v_east: f32, speed_acc: f32) -> Option<Prediction> {
        let (sp, h) = self.stream.as_mut()?;
        h.clear_uncounted();
        Some(sp.predict(
            h,
            &Epoch {
                t_s: 0.0,
                v_north,
                v_east,
                speed_acc,
            },
        ))
    }

    /// One sample. Never panics: bad input gives [`crate::Status::Invalid`]. σ is the network's.
    pub fn predict(&mut self, v_north: f32, v_east: f32) -> Prediction {
        self.predict_with_accuracy(v_north, v_east, f32::NAN)
    }

    /// One sample with the receiver's speed accuracy (1σ, m/s; NaN or negative when
    /// unknown). For full-circle models σ then follows the receiver's own noise
    /// (`k·sAcc/speed`), which one velocity sample cannot reveal; otherwise as
    /// [`Predictor::predict`].
    pub fn predict_with_accuracy(
        &mut self,
        v_north: f32,
        v_east: f32,
        speed_acc: f32,
    ) -> Prediction {
        if let Some(p) = self.stateless(v_north, v_east, speed_acc) {
            return p;
        }
        let Some(speed) = self.validate(v_north, v_east) else {
            return Prediction {
                speed: v_north.hypot(v_east),
                ..Prediction::INVALID
            };
        };
        let x = scale_input(v_north, v_east, self.model.meta().input_scale_mps);
        let Engine::Epoch(net) = self.model.engine() else {
            unreachable!("stateful models answered above")
        };
        let scratch = self.scratch.as_mut().expect("per-epoch scratch");
        net.forward_one(&x, &mut self.out, scratch);
        finish_epoch(
            &self.model,
            &self.policy,
            &self.out,
            v_north,
            v_east,
            speed,
            speed_acc,
        )
    }

    /// Many samples through the batch path; `out[i]` answers `(v_north[i], v_east[i])`.
    /// Invalid inputs are fed to the network as zeros and answered as invalid.
    pub fn predict_batch(&mut self, v_north: &[f32], v_east: &[f32], out: &mut [Prediction]) {
        self.batch(v_north, v_east, None, out)
    }

    /// [`Predictor::predict_batch`] with each sample's speed accuracy (see
    /// [`Predictor::predict_with_accuracy`]).
    pub fn predict_batch_with_accuracy(
        &mut self,
        v_north: &[f32],
        v_east: &[f32],
        speed_acc: &[f32],
        out: &mut [Prediction],
    ) {
        assert_eq!(
            speed_acc.len(),
            out.len(),
            "predict_batch: slices must have equal length"
        );
        self.batch(v_north, v_east, Some(speed_acc), out)
    }

    fn batch(
        &mut self,
        v_north: &[f32],
        v_east: &[f32],
        speed_acc: Option<&[f32]>,
        out: &mut [Prediction],
    ) {
        assert!(
            v_north.len() == v_east.len() && v_east.len() == out.len(),
            "predict_batch: slices must have equal length"
        );
        if self.stream.is_some() {
            for (i, o) in out.iter_mut().enumerate() {
                let acc = speed_acc.map_or(f32::NAN, |a| a[i]);
                *o = self
                    .stateless(v_north[i], v_east[i], acc)
                    .expect("stateful model");
            }
            return;
        }
        let model = self.model.clone();
        let Engine::Epoch(net) = model.engine() else {
            unreachable!("stateful models answered above")
        };
        let scale = model.meta().input_scale_mps;
        let k = net.outputs();
        let mut y = [0.0f32; 8];
        let mut start = 0;
        while start < out.len() {
            let len = (out.len() - start).min(BATCH_CHUNK);
            for j in 0..len {
                let (vn, ve) = (v_north[start + j], v_east[start + j]);
                let x = if self.validate(vn, ve).is_some() {
                    scale_input(vn, ve, scale)
                } else {
                    [0.0, 0.0]
                };
                self.xb[(0, j)] = x[0];
                self.xb[(1, j)] = x[1];
            }
            net.forward(
                self.xb.as_ref().subcols(0, len),
                self.yb.as_mut().subcols_mut(0, len),
                self.scratch.as_mut().expect("per-epoch scratch"),
            );
            for j in 0..len {
                let (vn, ve) = (v_north[start + j], v_east[start + j]);
                out[start + j] = match self.validate(vn, ve) {
                    Some(speed) => {
                        for (kk, yk) in y.iter_mut().enumerate().take(k) {
                            *yk = self.yb[(kk, j)];
                        }
                        let acc = speed_acc.map_or(f32::NAN, |a| a[start + j]);
                        finish_epoch(&model, &self.policy, &y[..k], vn, ve, speed, acc)
                    }
                    None => Prediction {
                        speed: vn.hypot(ve),
                        ..Prediction::INVALID
                    },
                };
            }
            start += len;
        }
    }
}
