//! GHNet: heading from one GNSS velocity sample, with a small network on faer.
//!
//! # Layout
//! - [`params`]: named tensors in PyTorch `state_dict` order and the architecture (Table I).
//! - [`gelu`]: the tanh-form GELU the paper uses, vectorisable.
//! - [`net`]: the inference network, batch norm folded and linear head collapsed.
//! - [`simd`]: the run-time choice of AVX-512 / AVX2+FMA / portable kernels, and the peak
//!   FMA loop benches compare against.
//! - [`head`]: how outputs become a heading and σ, and the losses that train them.
//! - [`weights`]: safetensors files with PyTorch names and ghnet metadata.
//! - [`model`]: [`Model`] (loaded, shareable) and [`Predictor`] (per thread, no allocation).
//! - [`train`]: forward/backward of every layer, AdamW, early stopping, σ calibration.
//! - [`sim`]: the paper's S1 grid and a realistic receiver over the full circle.
//! - [`bayes`]: the Bayes-optimal estimate for the S1 prior (the physical limit).
//! - [`eval`]: per-speed-bin tables, baselines and σ calibration; [`plot`]: the MAE plot.
//! - [`recipes`]: how the shipped models are trained and judged.
//! - [`infer`]: streaming CSV inference for offline replay of logs.
//!
//! This crate knows nothing about IPC: the daemon wires it to the transports.
#![warn(missing_docs)]

pub mod bayes;
pub mod eval;
pub mod gelu;
pub mod head;
pub mod infer;
pub mod model;
pub mod net;
pub mod params;
pub mod plot;
pub mod recipes;
pub mod sim;
pub mod simd;
pub mod train;
pub mod weights;

pub use model::{Model, ModelError, Prediction, Predictor, Status, StatusPolicy, DEFAULT_MODEL};
pub use params::Arch;
pub use weights::ModelMeta;
