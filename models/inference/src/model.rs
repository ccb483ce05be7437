//! A loaded model: [`Model`] is immutable and shareable (`Arc<Model>`); the predictors
//! that run it ([`crate::Predictor`], [`crate::StreamPredictor`]) own the scratch.

use std::path::Path;

use crate::head::Head;
use crate::net::{collapse_fc, Network};
use crate::params::ParamSet;
use crate::weights::{self, ModelKind, ModelMeta, WeightsError};
use crate::window::WindowHead;

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
/// and on held-out simulated cars (its figures against atan2 and `kf`:
/// models/reports/car-nagoya.md and ghnet-temporal.md). Stateful, so run it with a
/// [`crate::StreamPredictor`] and one [`crate::History`] per source, as ghnetd does.
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
    /// filter): run them with [`crate::StreamPredictor`] and one [`crate::History`] per source.
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
