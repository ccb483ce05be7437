//! A loaded model and the per-thread predictor that runs it.
//!
//! [`Model`] is immutable and shareable (`Arc<Model>`); [`Predictor`] owns the scratch
//! buffers, so the hot path (`predict`, `predict_batch`) allocates nothing.

use std::path::Path;
use std::sync::Arc;

use faer::Mat;

use crate::head::{accuracy_sigma_base, heading_deg, scale_input, Head, MAX_STD_DEG};
use crate::net::{collapse_fc, Network, Scratch};
use crate::params::ParamSet;
use crate::stream::{Epoch, History, StreamPredictor, WindowHead};
use crate::weights::{self, ModelKind, ModelMeta, WeightsError};

/// The models compiled into every binary, by name. `ghnet-temporal` is the default;
/// `kf` is the model-free Kalman filter baseline (parameters only).
pub const BUILTIN: [(&str, &[u8]); 4] = [
    (
        "ghnet-temporal",
        include_bytes!("../weights/ghnet-temporal.safetensors").as_slice(),
    ),
    (
        "ghnet-epoch",
        include_bytes!("../weights/ghnet-epoch.safetensors").as_slice(),
    ),
    (
        "paper-s1",
        include_bytes!("../weights/paper-s1.safetensors").as_slice(),
    ),
    ("kf", include_bytes!("../weights/kf.safetensors").as_slice()),
];

/// Names older configurations used, and the built-in model each now means: the
/// per-epoch full-circle model was `ghnet-full` before temporal models existed.
pub const ALIASES: [(&str, &str); 1] = [("ghnet-full", "ghnet-epoch")];

/// The built-in name `name` stands for (itself unless it is an alias).
fn resolve(name: &str) -> &str {
    ALIASES
        .iter()
        .find(|(a, _)| *a == name)
        .map_or(name, |(_, m)| *m)
}

/// Name of the default model: the built-in one most accurate on the shared real drive
/// and on held-out simulated cars (models/README.md: `ghnet-temporal` 2.94° MAE on the
/// real drive, `kf` 5.53°, atan2 39.79°). Stateful, so run it with a
/// [`StreamPredictor`] and one [`History`] per source, as ghnetd does.
pub const DEFAULT_MODEL: &str = "ghnet-temporal";

/// Why a model could not be had.
#[derive(Debug, thiserror::Error)]
pub enum ModelError {
    /// The name is neither built in nor an existing file.
    #[error("unknown model `{0}`: not a built-in model (ghnet-temporal, ghnet-epoch, paper-s1, kf) and no such file")]
    Unknown(String),
    /// The file or embedded bytes are malformed.
    /// (The cause is part of the message and deliberately not a `source()`, so a
    /// `{:#}` chain prints it once.)
    #[error("model `{name}`: {cause}")]
    Weights {
        /// Name or path.
        name: String,
        /// What is wrong.
        cause: WeightsError,
    },
    /// The path is not a model file ghnet reads: not a regular file (a FIFO, a
    /// device, a directory), or larger than [`MAX_MODEL_FILE`].
    #[error("model `{name}`: {problem}")]
    File {
        /// The path.
        name: String,
        /// What is wrong, with the size when it is the size.
        problem: String,
    },
}

/// Largest model file read, bytes: far above any real model (the largest built-in is
/// well under 1 MB), so a wrong path (`/dev/zero`, a disk image, a sparse file) is
/// refused before it is read instead of filling the memory.
pub const MAX_MODEL_FILE: u64 = 64 << 20;

/// What computes a model's answers, made once when it is loaded.
#[derive(Debug, Clone)]
pub enum Engine {
    /// A per-epoch network (the paper's).
    Epoch(Network),
    /// A temporal network: the per-epoch feature convolutions and the head over the
    /// window of cached features.
    Temporal {
        /// Batch norm folded into the convolutions; its outputs are the features.
        features: Network,
        /// The fully connected layers collapsed over the window.
        head: WindowHead,
    },
    /// The model-free circular Kalman filter (parameters in the metadata's `kind`).
    Kf,
}

/// A loaded model: folded network, head, metadata and the unfolded weights it came from.
#[derive(Debug, Clone)]
pub struct Model {
    meta: ModelMeta,
    params: ParamSet,
    engine: Engine,
    id: u32,
}

impl Model {
    /// Build from weights and metadata (folding batch norm once, here).
    pub fn new(params: ParamSet, meta: ModelMeta) -> Self {
        let engine = match meta.kind {
            ModelKind::Epoch => Engine::Epoch(Network::fold(&params)),
            ModelKind::Kf { .. } => Engine::Kf,
            ModelKind::Temporal { .. } => {
                let (w, b) = collapse_fc(&params);
                Engine::Temporal {
                    features: Network::fold(&params),
                    head: WindowHead::new(w.as_ref(), &b, params.arch().window),
                }
            }
        };
        let mut h: u32 = 0x811c_9dc5; // FNV-1a over name and weights: a stable wire id
        for b in meta
            .name
            .bytes()
            .chain(params.data().iter().flat_map(|v| v.to_le_bytes()))
        {
            h ^= b as u32;
            h = h.wrapping_mul(0x0100_0193);
        }
        Self {
            meta,
            params,
            engine,
            id: h,
        }
    }

    /// A built-in model by name.
    pub fn builtin(name: &str) -> Result<Self, ModelError> {
        let name = resolve(name);
        let bytes = BUILTIN
            .iter()
            .find(|(n, _)| *n == name)
            .map(|(_, b)| *b)
            .ok_or_else(|| ModelError::Unknown(name.into()))?;
        Self::from_bytes(name, bytes)
    }

    /// Parse safetensors bytes; `name` is only used in errors.
    pub fn from_bytes(name: &str, bytes: &[u8]) -> Result<Self, ModelError> {
        let (params, meta) = weights::from_bytes(bytes).map_err(|cause| ModelError::Weights {
            name: name.into(),
            cause,
        })?;
        Ok(Self::new(params, meta))
    }

    /// Load a safetensors file.
    pub fn load(path: &Path) -> Result<Self, ModelError> {
        let name = path.display().to_string();
        let bytes = read_model_file(path)?;
        let (params, meta) =
            weights::from_bytes(&bytes).map_err(|cause| ModelError::Weights { name, cause })?;
        Ok(Self::new(params, meta))
    }

    /// A built-in name, or else a path to a safetensors file.
    pub fn from_name_or_path(s: &str) -> Result<Self, ModelError> {
        if BUILTIN.iter().any(|(n, _)| *n == resolve(s)) {
            return Self::builtin(s);
        }
        let p = Path::new(s);
        if p.exists() {
            Self::load(p)
        } else {
            Err(ModelError::Unknown(s.into()))
        }
    }

    /// Model name from its metadata.
    pub fn name(&self) -> &str {
        &self.meta.name
    }

    /// A 32-bit FNV-1a hash of name and weights: tells consumers which weights answered.
    pub fn id(&self) -> u32 {
        self.id
    }

    /// Metadata.
    pub fn meta(&self) -> &ModelMeta {
        &self.meta
    }

    /// This model with `platform` as its sources' default ([`crate::Platform`]): how a
    /// log of a known platform is answered (`ghnet infer --platform`). Models without
    /// the temporal filter do not use it and come back unchanged.
    pub fn with_platform(&self, platform: crate::Platform) -> Model {
        let mut meta = self.meta.clone();
        if let ModelKind::Temporal { modes, .. } = &mut meta.kind {
            modes.platform = platform;
        }
        Model::new(self.params.clone(), meta)
    }

    /// The unfolded weights (what `ghnet export` writes).
    pub fn params(&self) -> &ParamSet {
        &self.params
    }

    /// The folded network: the whole network of a per-epoch model, the per-epoch
    /// feature convolutions of a temporal one, none for the Kalman filter.
    pub fn network(&self) -> Option<&Network> {
        match &self.engine {
            Engine::Epoch(n) => Some(n),
            Engine::Temporal { features, .. } => Some(features),
            Engine::Kf => None,
        }
    }

    /// What computes the answers.
    pub fn engine(&self) -> &Engine {
        &self.engine
    }

    /// Whether answers depend on the source's history (temporal models and the Kalman
    /// filter): run them with [`StreamPredictor`] and one [`History`] per source.
    pub fn is_stateful(&self) -> bool {
        !matches!(self.engine, Engine::Epoch(_))
    }

    /// The output head.
    pub fn head(&self) -> &Head {
        &self.meta.head
    }

    /// Safetensors bytes of this model.
    pub fn to_safetensors(&self) -> Vec<u8> {
        weights::to_bytes(&self.params, &self.meta)
    }
}

/// How far to trust a heading. Mirrors the wire status in `ghnet-client` (the daemon maps
/// one to the other; this crate knows nothing of the wire).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Status {
    /// Use it, with its σ.
    Ok,
    /// A heading exists but σ exceeds the policy's limit: do not feed it to a filter
    /// without inflating its variance.
    LowSpeed,
    /// Horizontal speed below the stationary threshold: heading is not observable.
    Stationary,
    /// The input was not a usable velocity (NaN, infinite, absurd): no heading.
    Invalid,
    /// Stopped, and the heading is the one held from the source's history (stateful
    /// models only); σ grows with the time stopped. Usable with its σ: a parked car
    /// keeps pointing where it stopped. One error for the whole stop: fuse it once.
    Held,
}

impl Status {
    /// Lower-case name, as written in CSV and logs.
    pub fn as_str(&self) -> &'static str {
        match self {
            Status::Ok => "ok",
            Status::LowSpeed => "low_speed",
            Status::Stationary => "stationary",
            Status::Invalid => "invalid",
            Status::Held => "held",
        }
    }
}

/// Thresholds that turn a prediction into a [`Status`].
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct StatusPolicy {
    /// Below this horizontal speed (m/s) the status is `stationary`.
    pub stationary_speed: f32,
    /// Above this σ (degrees) the status is `low_speed`.
    pub max_std_deg: f32,
    /// Above this speed (m/s) the input is `invalid`: no land vehicle does 100 m/s, a
    /// receiver glitch does.
    pub max_speed: f32,
}

impl Default for StatusPolicy {
    fn default() -> Self {
        Self {
            stationary_speed: 0.05,
            max_std_deg: 10.0,
            max_speed: 100.0,
        }
    }
}

/// One heading estimate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Prediction {
    /// Heading, degrees clockwise from north in [0, 360); NaN when invalid.
    pub heading_deg: f32,
    /// 1σ of the heading, degrees; NaN when invalid.
    pub std_deg: f32,
    /// The model-based heading atan2(v_E, v_N), degrees in [0, 360); NaN when invalid.
    pub atan2_deg: f32,
    /// Horizontal speed, m/s (NaN when a component is NaN).
    pub speed: f32,
    /// Trust.
    pub status: Status,
}

impl Prediction {
    /// The answer to invalid input: status `Invalid`, every number NaN. Also the
    /// filler for output buffers handed to `predict_batch*`, which overwrite them.
    pub const INVALID: Prediction = Prediction {
        heading_deg: f32::NAN,
        std_deg: f32::NAN,
        atan2_deg: f32::NAN,
        speed: f32::NAN,
        status: Status::Invalid,
    };
}

/// The answer of a per-epoch model from its outputs `y`: decoded heading, σ (from the
/// receiver's speed accuracy where the model uses it) and status. Shared by
/// [`Predictor`] and [`StreamPredictor`].
pub(crate) fn finish_epoch(
    model: &Model,
    policy: &StatusPolicy,
    y: &[f32],
    v_north: f32,
    v_east: f32,
    speed: f32,
    acc: f32,
) -> Prediction {
    let meta = model.meta();
    let (heading, mut std) = meta.head.decode(y, v_north, v_east, meta.sigma_scale);
    if meta.accuracy_sigma_scale.is_finite() {
        if let Some(base) = accuracy_sigma_base(v_north, v_east, acc) {
            std = (meta.accuracy_sigma_scale * base)
                .to_degrees()
                .min(MAX_STD_DEG);
        }
    }
    let status = if speed < policy.stationary_speed {
        Status::Stationary
    } else if std.is_nan() || std > policy.max_std_deg {
        Status::LowSpeed
    } else {
        Status::Ok
    };
    Prediction {
        heading_deg: heading,
        std_deg: std,
        atan2_deg: heading_deg(v_north, v_east),
        speed,
        status,
    }
}

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

    /// One sample. Never panics: bad input gives [`Status::Invalid`]. σ is the network's.
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

/// The bytes of the model file `path`: only a regular file, at most
/// [`MAX_MODEL_FILE`] bytes, checked from its metadata before reading (a FIFO would
/// block, `/dev/zero` never ends, a 2 GB sparse file would be read whole), and the
/// read bounded anyway (the file may grow between the check and the read).
fn read_model_file(path: &Path) -> Result<Vec<u8>, ModelError> {
    use std::io::Read;
    use std::os::unix::fs::{FileTypeExt, OpenOptionsExt};
    // O_NONBLOCK (Linux): opening a FIFO without a writer returns at once; the type
    // is then checked on the open file, not on a path that may change meanwhile.
    const O_NONBLOCK: i32 = 0o4000;
    let name = path.display().to_string();
    let io = |source| ModelError::Weights {
        name: name.clone(),
        cause: WeightsError::Io {
            path: name.clone(),
            source,
        },
    };
    let refuse = |problem: String| ModelError::File {
        name: name.clone(),
        problem,
    };
    let file = std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(O_NONBLOCK)
        .open(path)
        .map_err(io)?;
    let meta = file.metadata().map_err(io)?;
    let t = meta.file_type();
    if !t.is_file() {
        let what = match () {
            _ if t.is_dir() => "a directory",
            _ if t.is_fifo() => "a FIFO",
            _ if t.is_char_device() => "a character device",
            _ if t.is_block_device() => "a block device",
            _ if t.is_socket() => "a socket",
            _ => "something else",
        };
        return Err(refuse(format!("is {what}, not a regular file")));
    }
    let too_big = |size: u64| {
        format!("is {size} bytes, over the {MAX_MODEL_FILE}-byte limit for a model file")
    };
    if meta.len() > MAX_MODEL_FILE {
        return Err(refuse(too_big(meta.len())));
    }
    let mut bytes = Vec::with_capacity(meta.len() as usize);
    file.take(MAX_MODEL_FILE + 1)
        .read_to_end(&mut bytes)
        .map_err(io)?;
    if bytes.len() as u64 > MAX_MODEL_FILE {
        return Err(refuse(too_big(bytes.len() as u64)));
    }
    Ok(bytes)
}
