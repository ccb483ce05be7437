//! `ghnet_inference`: GHNet inference, what `ghnetd` links. The network of the paper's
//! Table I on [faer], its weights, the output heads and the per-thread predictor, and
//! the models compiled into every binary. Nothing else: simulation, training,
//! evaluation and the `ghnet` tool are the lab (`ghnet-lab`), which depends on this
//! crate and never the other way round, so the daemon links no plotting, CSV or
//! random-number code.
//!
//! # Layout
//! - [`params`]: named tensors in PyTorch `state_dict` order and the architecture (Table I).
//! - [`gelu`]: the tanh-form GELU the paper uses, vectorisable.
//! - [`net`]: the inference network, batch norm folded and linear head collapsed.
//! - [`simd`]: the run-time choice of AVX-512 / AVX2+FMA / portable kernels, and the peak
//!   FMA loop benches compare against.
//! - [`head`]: how outputs become a heading and σ (decoding only; the lab has the losses).
//! - [`weights`]: safetensors files with PyTorch names and ghnet metadata.
//! - [`model`]: [`Model`] (loaded, shareable) and the embedded models
//!   ([`model::BUILTIN`], [`DEFAULT_MODEL`]).
//! - [`prediction`]: [`Prediction`], [`Status`] and [`StatusPolicy`]: what every engine answers.
//! - [`predictor`]: [`Predictor`] (per thread, no allocation, no history).
//! - [`window`]: the temporal head over the last epochs' features.
//! - [`step`]: the per-epoch math of the stateful engines (inputs, Kalman step, σ).
//! - [`stream`]: [`StreamPredictor`] and the per-source [`History`]: temporal models and
//!   the Kalman filter `kf`, answered one epoch at a time with bounded state, the history
//!   rules (gap, time backwards, explicit reset) and the `Held` status.
//! - [`source`]: [`SourceStream`], one source's sample rules without I/O (sequence, time,
//!   validity, resets, repeats, counts): what ghnetd and `ghnet infer` both drive.
//! - [`runner`]: [`Runner`], a model as a server of many sources runs it (one sample,
//!   a per-epoch batch, or staged passes of a temporal network).
//!
//! This crate knows nothing about IPC: the daemon wires it to the transports.
//!
//! [faer]: https://docs.rs/faer
#![warn(missing_docs)]

pub mod gelu;
pub mod head;
pub mod model;
pub mod modes;
pub mod net;
pub mod params;
pub mod prediction;
pub mod predictor;
pub mod runner;
pub mod simd;
pub mod source;
pub mod step;
pub mod stream;
pub mod weights;
pub mod window;

pub use model::{Model, ModelError, DEFAULT_MODEL};
pub use params::Arch;
pub use prediction::{Prediction, Status, StatusPolicy};
pub use predictor::Predictor;
pub use runner::{Runner, STREAM_BATCH};
pub use source::{Admission, Sample, SampleCounts, SourceStream};
pub use stream::{
    Epoch, History, Platform, Reset, ResetCounts, Staged, StreamBatch, StreamPredictor,
};
pub use weights::ModelMeta;
