//! Weights on disk: safetensors with PyTorch `state_dict` names, plus ghnet metadata.
//!
//! A network trained in PyTorch as
//! `conv{i} = nn.Conv1d(c_in, c_out, 1)`, `bn{i} = nn.BatchNorm1d(c_out)`,
//! `fc{i} = nn.Linear(f_in, f_out)` and saved with `safetensors.torch.save_file(
//! model.state_dict(), path, metadata)` loads unchanged (`num_batches_tracked` buffers are
//! accepted and ignored). Every tensor is F32, little-endian, row-major, with the PyTorch
//! shape. The metadata (a string → string map in the safetensors header) carries what the
//! weights alone cannot: the architecture, the output head, the input scaling, the
//! heading range, σ calibration, the training data and the measured metrics. The format
//! is documented in `models/README.md`.

use std::collections::HashMap;
use std::path::Path;

use safetensors::{Dtype, SafeTensors};
use serde::{Deserialize, Serialize};

use crate::head::Head;
use crate::params::{Arch, ParamSet};

fn nan() -> f32 {
    f32::NAN
}

/// JSON has no NaN: write it as `null` and read `null` back as NaN.
mod nan_as_null {
    use serde::{Deserialize, Deserializer, Serializer};
    pub fn serialize<S: Serializer>(v: &f32, s: S) -> Result<S::Ok, S::Error> {
        if v.is_finite() {
            s.serialize_f32(*v)
        } else {
            s.serialize_none()
        }
    }
    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<f32, D::Error> {
        Ok(Option::<f32>::deserialize(d)?.unwrap_or(f32::NAN))
    }
}

/// Value of the `format` metadata key this version writes and reads.
pub const FORMAT: &str = "ghnet/1";

/// How a model runs: which engine answers and whether it keeps a history.
///
/// Stored under the metadata key `kind`; files without it (every file written before
/// temporal models existed) are per-epoch models.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case", deny_unknown_fields)]
#[allow(clippy::large_enum_variant)] // one per model, read once per epoch by reference
pub enum ModelKind {
    /// One epoch in, one heading out (the paper's network): no history.
    #[default]
    Epoch,
    /// The network over a causal window of the source's recent epochs, correcting the
    /// mode filter (`crate::modes`) on its own previous output (`crate::stream`).
    Temporal {
        /// A time step longer than this (s) clears the history: after a long fix gap
        /// the vehicle may have turned anywhere.
        max_gap_s: f32,
        /// The tuned `kf`'s random-walk heading noise, °/√s (kept for reference: the
        /// mode filter has its own process model).
        q_deg_per_sqrt_s: f32,
        /// The tuned `kf`'s velocity noise, m/s: until an epoch passes its measurement
        /// gate, the model answers as `kf` does (the start convention).
        sigma_v_mps: f32,
        /// The mode filter's constants (defaults when absent).
        #[serde(default)]
        modes: crate::modes::ModeParams,
        /// Calibration of the reported σ per vehicle class, fitted on validation
        /// tracks (identity when absent).
        #[serde(default)]
        sigma_map: crate::modes::SigmaMaps,
    },
    /// The model-free circular Kalman filter on atan2 (`crate::stream::Kf`): the baseline
    /// a temporal network must beat, shipped so it can be selected like any model.
    Kf {
        /// Random-walk heading noise, degrees per √s.
        q_deg_per_sqrt_s: f32,
        /// Velocity noise per axis (m/s) behind the measurement σ `σ_v/ŝ`.
        sigma_v_mps: f32,
        /// A time step longer than this (s) clears the filter.
        max_gap_s: f32,
    },
}

impl ModelKind {
    /// The history limit of stateful models; `None` for per-epoch models.
    pub fn max_gap_s(&self) -> Option<f32> {
        match *self {
            ModelKind::Epoch => None,
            ModelKind::Temporal { max_gap_s, .. } | ModelKind::Kf { max_gap_s, .. } => {
                Some(max_gap_s)
            }
        }
    }

    /// The platform a source of this model has unless configured otherwise: the
    /// temporal model's recorded one, `auto` for the others (they do not use it).
    pub fn default_platform(&self) -> crate::modes::Platform {
        match self {
            ModelKind::Temporal { modes, .. } => modes.platform,
            _ => crate::modes::Platform::Auto,
        }
    }
}

/// What a model file says about itself.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModelMeta {
    /// Format tag, [`FORMAT`].
    pub format: String,
    /// Model name, e.g. `ghnet-epoch`.
    pub name: String,
    /// Layer sizes.
    pub architecture: Arch,
    /// Activation after each batch norm; only `gelu_tanh` is implemented.
    pub activation: String,
    /// How outputs become a heading.
    pub head: Head,
    /// Velocities are divided by this (m/s) before entering the network.
    pub input_scale_mps: f32,
    /// Heading range the model was trained on, degrees `[lo, hi]`.
    pub heading_range_deg: [f32; 2],
    /// Multiplier on the network's σ, fitted on validation data so that 68.3% of errors
    /// fall within 1σ.
    pub sigma_scale: f32,
    /// For full-circle models, the factor `k` in the σ derived from the receiver's speed
    /// accuracy, `σ_ψ = k·sAcc/speed` (radians), fitted on validation data like
    /// `sigma_scale`; `null` (NaN) when the model does not use sAcc. Optional in files.
    #[serde(default = "nan", with = "nan_as_null")]
    pub accuracy_sigma_scale: f32,
    /// Free-form description of the training data (simulator and parameters).
    pub training_data: serde_json::Value,
    /// Training hyper-parameters and outcome.
    pub training: serde_json::Value,
    /// Headline metrics measured on held-out data when the model was made.
    pub metrics: serde_json::Value,
    /// Per-epoch, temporal or Kalman filter (key `kind`, optional: per-epoch when absent).
    #[serde(default)]
    pub kind: ModelKind,
}

impl ModelMeta {
    /// Metadata for a model made in code rather than trained on a data set (`kf`, a
    /// temporal network before its training fills in the record): full-circle range,
    /// unit input scale and σ scale, no speed-accuracy σ, empty provenance. The caller
    /// sets what differs.
    pub fn new(name: &str, architecture: Arch, head: Head, kind: ModelKind) -> Self {
        ModelMeta {
            format: FORMAT.into(),
            name: name.into(),
            architecture,
            activation: "gelu_tanh".into(),
            head,
            input_scale_mps: 1.0,
            heading_range_deg: [0.0, 360.0],
            sigma_scale: 1.0,
            accuracy_sigma_scale: f32::NAN,
            training_data: serde_json::Value::Null,
            training: serde_json::Value::Null,
            metrics: serde_json::Value::Null,
            kind,
        }
    }
}

/// Why a model could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum WeightsError {
    /// The file could not be read.
    #[error("cannot read model file {path}: {source}")]
    Io {
        /// Path tried.
        path: String,
        /// OS error.
        source: std::io::Error,
    },
    /// The bytes are not a safetensors file.
    #[error("not a safetensors file: {0}")]
    Format(String),
    /// A tensor the architecture needs is absent.
    #[error("missing tensor `{name}` (expected shape {expected:?})")]
    MissingTensor {
        /// PyTorch name.
        name: String,
        /// Shape the architecture needs.
        expected: Vec<usize>,
    },
    /// A tensor has the wrong shape.
    #[error("tensor `{name}` has shape {found:?}, expected {expected:?}")]
    WrongShape {
        /// PyTorch name.
        name: String,
        /// Shape the architecture needs.
        expected: Vec<usize>,
        /// Shape in the file.
        found: Vec<usize>,
    },
    /// A tensor is not F32.
    #[error("tensor `{name}` has dtype {found}, expected F32")]
    WrongDtype {
        /// PyTorch name.
        name: String,
        /// Dtype in the file.
        found: String,
    },
    /// A tensor holds NaN or infinity.
    #[error("tensor `{name}` contains non-finite values")]
    NonFinite {
        /// PyTorch name.
        name: String,
    },
    /// A metadata key is absent.
    #[error("missing metadata key `{0}` (a ghnet model file needs it; see models/README.md)")]
    MissingMetadata(String),
    /// A metadata value does not parse or is inconsistent.
    #[error("bad metadata `{key}`: {reason}")]
    BadMetadata {
        /// Key.
        key: String,
        /// What is wrong.
        reason: String,
    },
}

/// Metadata keys whose values are JSON (the others are plain strings or numbers).
const JSON_KEYS: [&str; 7] = [
    "kind",
    "architecture",
    "head",
    "heading_range_deg",
    "training_data",
    "training",
    "metrics",
];

/// Metadata keys whose values are JSON numbers.
const NUMBER_KEYS: [&str; 3] = ["input_scale_mps", "sigma_scale", "accuracy_sigma_scale"];

/// Metadata keys a file may omit.
const OPTIONAL_KEYS: [&str; 2] = ["accuracy_sigma_scale", "kind"];

/// Serialise weights and metadata to safetensors bytes.
pub fn to_bytes(params: &ParamSet, meta: &ModelMeta) -> Vec<u8> {
    let mut views = Vec::new();
    for (i, spec) in params.specs().iter().enumerate() {
        let bytes: Vec<u8> = params.data()[params.range(i)]
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        views.push((spec.name.clone(), spec.shape.clone(), bytes));
    }
    let tensors: Vec<(String, safetensors::tensor::TensorView<'_>)> = views
        .iter()
        .map(|(n, s, b)| {
            (
                n.clone(),
                safetensors::tensor::TensorView::new(Dtype::F32, s.clone(), b)
                    .expect("shape matches data"),
            )
        })
        .collect();
    let value = serde_json::to_value(meta).expect("metadata serialises");
    let mut md = HashMap::new();
    for (k, v) in value.as_object().expect("struct is an object") {
        let s = match v {
            serde_json::Value::String(s) if !JSON_KEYS.contains(&k.as_str()) => s.clone(),
            other => other.to_string(),
        };
        md.insert(k.clone(), s);
    }
    let bytes = safetensors::serialize(tensors, Some(md)).expect("safetensors serialisation");
    with_sorted_header(bytes)
}

/// The same file with its header's keys in sorted order. `safetensors` writes the
/// metadata from a `HashMap`, whose order changes from one process to the next, so
/// equal models made unequal files (a restamp that changed nothing still changed the
/// shipped weights in git, and comparing two models took parsing both). The sorted
/// header is the same JSON reordered, so its length, the padding after it and every
/// tensor's offsets stay as they were.
fn with_sorted_header(mut bytes: Vec<u8>) -> Vec<u8> {
    let mut len = [0u8; 8];
    len.copy_from_slice(&bytes[..8]);
    let end = 8 + u64::from_le_bytes(len) as usize;
    // `serde_json`'s maps are ordered by key (the `preserve_order` feature is off).
    let header: serde_json::Value =
        serde_json::from_slice(&bytes[8..end]).expect("safetensors writes a JSON header");
    let sorted = serde_json::to_vec(&header).expect("JSON serialises");
    assert!(8 + sorted.len() <= end, "a reordered header is no longer");
    bytes[8..8 + sorted.len()].copy_from_slice(&sorted);
    bytes[8 + sorted.len()..end].fill(b' ');
    bytes
}

/// Parse safetensors bytes into weights and metadata, validating every tensor against the
/// architecture the metadata names.
pub fn from_bytes(bytes: &[u8]) -> Result<(ParamSet, ModelMeta), WeightsError> {
    let (_, header) =
        SafeTensors::read_metadata(bytes).map_err(|e| WeightsError::Format(e.to_string()))?;
    let st = SafeTensors::deserialize(bytes).map_err(|e| WeightsError::Format(e.to_string()))?;
    let md = header.metadata().clone().unwrap_or_default();
    let meta = parse_meta(&md)?;
    if meta.format != FORMAT {
        return Err(WeightsError::BadMetadata {
            key: "format".into(),
            reason: format!("`{}` is not `{FORMAT}`", meta.format),
        });
    }
    if meta.activation != "gelu_tanh" {
        return Err(WeightsError::BadMetadata {
            key: "activation".into(),
            reason: format!("`{}` is not implemented (only gelu_tanh)", meta.activation),
        });
    }
    check_arch(&meta.architecture, &meta.kind, &meta.head)?;
    if !(meta.sigma_scale.is_finite() && meta.sigma_scale > 0.0) {
        return Err(WeightsError::BadMetadata {
            key: "sigma_scale".into(),
            reason: format!("{} must be a positive number", meta.sigma_scale),
        });
    }
    let k = meta.accuracy_sigma_scale;
    if !(k.is_nan() || (k.is_finite() && k > 0.0)) {
        return Err(WeightsError::BadMetadata {
            key: "accuracy_sigma_scale".into(),
            reason: format!("{k} must be null (unused) or a positive number"),
        });
    }
    let is_kf = matches!(meta.kind, ModelKind::Kf { .. });
    if !is_kf && meta.architecture.output != meta.head.outputs() {
        return Err(WeightsError::BadMetadata {
            key: "architecture".into(),
            reason: format!(
                "output {} does not match head {:?} ({} outputs)",
                meta.architecture.output,
                meta.head,
                meta.head.outputs()
            ),
        });
    }
    if !(meta.input_scale_mps.is_finite() && meta.input_scale_mps > 0.0) {
        return Err(WeightsError::BadMetadata {
            key: "input_scale_mps".into(),
            reason: "must be a positive number".into(),
        });
    }
    let params = read_tensors(&st, &meta.architecture)?;
    Ok((params, meta))
}

/// Every tensor `arch` needs, checked for presence, dtype, shape and finite values.
fn read_tensors(st: &SafeTensors<'_>, arch: &Arch) -> Result<ParamSet, WeightsError> {
    let mut params = ParamSet::zeros(arch);
    for i in 0..params.specs().len() {
        let spec = params.specs()[i].clone();
        let view = st
            .tensor(&spec.name)
            .map_err(|_| WeightsError::MissingTensor {
                name: spec.name.clone(),
                expected: spec.shape.clone(),
            })?;
        if view.dtype() != Dtype::F32 {
            return Err(WeightsError::WrongDtype {
                name: spec.name.clone(),
                found: format!("{:?}", view.dtype()),
            });
        }
        if view.shape() != spec.shape.as_slice() {
            return Err(WeightsError::WrongShape {
                name: spec.name.clone(),
                expected: spec.shape.clone(),
                found: view.shape().to_vec(),
            });
        }
        let r = params.range(i);
        for (dst, chunk) in params.data_mut()[r]
            .iter_mut()
            .zip(view.data().chunks_exact(4))
        {
            *dst = f32::from_le_bytes([chunk[0], chunk[1], chunk[2], chunk[3]]);
            if !dst.is_finite() {
                return Err(WeightsError::NonFinite {
                    name: spec.name.clone(),
                });
            }
        }
    }
    Ok(params)
}

/// Largest layer width a model file may declare. The shipped networks are at most 192
/// wide; the bound keeps a hostile or corrupt `architecture` from making the loader
/// allocate gigabytes (or overflow a size) before the tensors are even looked at.
pub const MAX_LAYER_WIDTH: usize = 4096;

/// Most layers (conv + fc) a model file may declare, for the same reason.
pub const MAX_LAYERS: usize = 64;

/// Longest window a temporal model file may declare (each source's history holds this
/// many feature vectors).
pub const MAX_WINDOW: usize = 64;

/// Per-epoch inputs of a temporal network: what `crate::stream::inputs` computes (and
/// re-exports as `stream::INPUTS`); a temporal model file must declare exactly this.
pub const TEMPORAL_INPUTS: usize = 20;

/// The filter parameters of a `kind` (noise densities, the gap limit) divide and take
/// roots, so each must be a positive finite number; `model` names the kind in the error.
fn check_positive(model: &str, params: &[f32]) -> Result<(), WeightsError> {
    if params.iter().all(|&v| v.is_finite() && v > 0.0) {
        return Ok(());
    }
    Err(WeightsError::BadMetadata {
        key: "kind".into(),
        reason: format!("{model} parameters must be positive numbers"),
    })
}

/// Checks what the inference code assumes of an architecture from a file: two inputs
/// (v_N, v_E), at least one convolution, sizes in `1..=MAX_LAYER_WIDTH`, at most
/// [`MAX_LAYERS`] layers. Without this a bad file would panic or abort at load or at
/// the first prediction instead of being an error.
fn check_arch(a: &Arch, kind: &ModelKind, head: &Head) -> Result<(), WeightsError> {
    let bad = |reason: String| {
        Err(WeightsError::BadMetadata {
            key: "architecture".into(),
            reason,
        })
    };
    match *kind {
        ModelKind::Kf {
            q_deg_per_sqrt_s,
            sigma_v_mps,
            max_gap_s,
        } => {
            check_positive("kf", &[q_deg_per_sqrt_s, sigma_v_mps, max_gap_s])?;
            if !(a.conv.is_empty() && a.fc.is_empty() && a.output == 0) {
                return bad("a kf model has no network (no conv, fc or output)".into());
            }
            return Ok(());
        }
        ModelKind::Temporal {
            max_gap_s,
            q_deg_per_sqrt_s,
            sigma_v_mps,
            ..
        } => {
            check_positive("temporal", &[max_gap_s, q_deg_per_sqrt_s, sigma_v_mps])?;
            if a.input != TEMPORAL_INPUTS || !(2..=MAX_WINDOW).contains(&a.window) {
                return bad(format!(
                    "a temporal model needs input {} and window 2..={MAX_WINDOW} (got {}, {})",
                    TEMPORAL_INPUTS, a.input, a.window
                ));
            }
            if *head != Head::Filter {
                return bad("a temporal model needs the filter head".into());
            }
        }
        ModelKind::Epoch => {
            if a.input != 2 || a.window != 1 {
                return bad(format!(
                    "input {} window {}: a per-epoch model has input 2 (v_north, v_east) and window 1",
                    a.input, a.window
                ));
            }
            if *head == Head::Filter {
                return bad("the filter head needs a temporal model".into());
            }
        }
    }
    if a.conv.is_empty() {
        return bad("no conv layer (the network needs at least one)".into());
    }
    if a.conv.len() + a.fc.len() > MAX_LAYERS {
        return bad(format!(
            "{} layers, more than {MAX_LAYERS}",
            a.conv.len() + a.fc.len()
        ));
    }
    let sizes = a.conv.iter().chain(&a.fc).chain(std::iter::once(&a.output));
    if let Some(n) = sizes.copied().find(|n| !(1..=MAX_LAYER_WIDTH).contains(n)) {
        return bad(format!("layer size {n} is outside 1..={MAX_LAYER_WIDTH}"));
    }
    Ok(())
}

fn parse_meta(md: &HashMap<String, String>) -> Result<ModelMeta, WeightsError> {
    let mut obj = serde_json::Map::new();
    for key in [
        "format",
        "name",
        "architecture",
        "activation",
        "head",
        "input_scale_mps",
        "heading_range_deg",
        "sigma_scale",
        "accuracy_sigma_scale",
        "training_data",
        "training",
        "metrics",
        "kind",
    ] {
        let Some(raw) = md.get(key) else {
            if OPTIONAL_KEYS.contains(&key) {
                continue;
            }
            return Err(WeightsError::MissingMetadata(key.into()));
        };
        let value = if JSON_KEYS.contains(&key) || NUMBER_KEYS.contains(&key) {
            serde_json::from_str(raw).map_err(|e| WeightsError::BadMetadata {
                key: key.into(),
                reason: e.to_string(),
            })?
        } else {
            serde_json::Value::String(raw.clone())
        };
        obj.insert(key.into(), value);
    }
    serde_json::from_value(serde_json::Value::Object(obj)).map_err(|e| WeightsError::BadMetadata {
        key: "(metadata)".into(),
        reason: e.to_string(),
    })
}

/// Read a model file.
pub fn read(path: &Path) -> Result<(ParamSet, ModelMeta), WeightsError> {
    let bytes = std::fs::read(path).map_err(|source| WeightsError::Io {
        path: path.display().to_string(),
        source,
    })?;
    from_bytes(&bytes)
}

/// Write a model file.
pub fn write(path: &Path, params: &ParamSet, meta: &ModelMeta) -> std::io::Result<()> {
    std::fs::write(path, to_bytes(params, meta))
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    fn sample() -> (ParamSet, ModelMeta) {
        let arch = Arch::paper(4);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let params = ParamSet::init(&arch, |b| rng.random_range(-b..b));
        let meta = ModelMeta {
            format: FORMAT.into(),
            name: "test".into(),
            architecture: arch,
            activation: "gelu_tanh".into(),
            head: Head::Residual {
                range_deg: [0.0, 360.0],
            },
            input_scale_mps: 5.0,
            heading_range_deg: [0.0, 360.0],
            sigma_scale: 1.25,
            accuracy_sigma_scale: 1.1,
            training_data: serde_json::json!({"sim": "none"}),
            training: serde_json::json!({}),
            metrics: serde_json::json!({"mae": 1.5}),
            kind: ModelKind::Epoch,
        };
        (params, meta)
    }

    #[test]
    fn round_trip_is_exact() {
        let (p, m) = sample();
        let bytes = to_bytes(&p, &m);
        let (p2, m2) = from_bytes(&bytes).unwrap();
        assert_eq!(p.data(), p2.data());
        assert_eq!(m, m2);
    }

    /// Equal models make equal files: each `HashMap` the metadata passes through
    /// iterates in its own order, so without sorting, two writes differ.
    #[test]
    fn a_model_writes_the_same_bytes_every_time() {
        let (p, m) = sample();
        let first = to_bytes(&p, &m);
        for _ in 0..4 {
            assert_eq!(to_bytes(&p, &m), first);
        }
        let (_, header) = SafeTensors::read_metadata(&first).unwrap();
        assert!(header.metadata().as_ref().is_some_and(|md| md.len() > 5));
    }

    fn rewrite(
        p: &ParamSet,
        m: &ModelMeta,
        edit: impl Fn(&mut Vec<(String, Vec<usize>, Vec<u8>)>),
    ) -> Vec<u8> {
        let mut t: Vec<(String, Vec<usize>, Vec<u8>)> = p
            .specs()
            .iter()
            .enumerate()
            .map(|(i, s)| {
                (
                    s.name.clone(),
                    s.shape.clone(),
                    p.data()[p.range(i)]
                        .iter()
                        .flat_map(|v| v.to_le_bytes())
                        .collect(),
                )
            })
            .collect();
        edit(&mut t);
        let views: Vec<_> = t
            .iter()
            .map(|(n, s, b)| {
                let dtype = if b.len() == s.iter().product::<usize>() * 8 {
                    Dtype::F64
                } else {
                    Dtype::F32
                };
                (
                    n.clone(),
                    safetensors::tensor::TensorView::new(dtype, s.clone(), b).unwrap(),
                )
            })
            .collect();
        let full = to_bytes(p, m);
        let (_, header) = SafeTensors::read_metadata(&full).unwrap();
        safetensors::serialize(views, header.metadata().clone()).unwrap()
    }

    #[test]
    fn malformed_files_name_the_tensor_and_shape() {
        let (p, m) = sample();
        let missing = rewrite(&p, &m, |t| t.retain(|(n, _, _)| n != "conv3.weight"));
        let err = from_bytes(&missing).unwrap_err().to_string();
        assert!(
            err.contains("conv3.weight") && err.contains("[96, 48, 1]"),
            "{err}"
        );

        let wrong = rewrite(&p, &m, |t| {
            let e = t.iter_mut().find(|(n, _, _)| n == "fc2.weight").unwrap();
            e.1 = vec![e.1[1], e.1[0]];
        });
        let err = from_bytes(&wrong).unwrap_err().to_string();
        assert!(
            err.contains("fc2.weight") && err.contains("[10, 60]") && err.contains("[60, 10]"),
            "{err}"
        );

        let f64s = rewrite(&p, &m, |t| {
            let e = t.iter_mut().find(|(n, _, _)| n == "bn1.bias").unwrap();
            e.2 = vec![0u8; e.1.iter().product::<usize>() * 8];
        });
        let err = from_bytes(&f64s).unwrap_err().to_string();
        assert!(err.contains("bn1.bias") && err.contains("F64"), "{err}");

        let err = from_bytes(b"not a model").unwrap_err().to_string();
        assert!(err.contains("not a safetensors file"), "{err}");
        let mut trunc = to_bytes(&p, &m);
        trunc.truncate(trunc.len() - 10);
        assert!(from_bytes(&trunc).is_err());
    }

    #[test]
    fn missing_metadata_is_named() {
        let (p, _) = sample();
        let views: Vec<_> = p
            .specs()
            .iter()
            .enumerate()
            .map(|(i, s)| {
                let b: Vec<u8> = p.data()[p.range(i)]
                    .iter()
                    .flat_map(|v| v.to_le_bytes())
                    .collect();
                (s.name.clone(), s.shape.clone(), b)
            })
            .collect();
        let tv: Vec<_> = views
            .iter()
            .map(|(n, s, b)| {
                (
                    n.clone(),
                    safetensors::tensor::TensorView::new(Dtype::F32, s.clone(), b).unwrap(),
                )
            })
            .collect();
        let bytes = safetensors::serialize(tv, None).unwrap();
        let err = from_bytes(&bytes).unwrap_err().to_string();
        assert!(err.contains("missing metadata key `format`"), "{err}");
    }
}
