//! Where models are made: each recipe from its data to its written file.
//!
//! # Layout
//! - [`epoch`]: the per-epoch recipes (`paper-s1`, `ghnet-epoch`): simulated samples,
//!   training, σ scales, held-out metrics in the file; and the held-out evaluation
//!   `ghnet eval` repeats from a model's metadata.
//! - [`temporal`]: the temporal recipe (`ghnet-temporal` and its car-only and
//!   turn-in-place variants): simulated drives, `kf` tuned, the network trained as a
//!   learned filter step ([`crate::temporal`]), σ maps fitted, tables printed; and
//!   `ghnet calibrate`, which refits the σ maps alone.
//! - [`kf`]: the Kalman filter baseline as a model, tuned on validation tracks.
//! - [`own`]: models fitted to users' own logs (`ghnet train --data`), with the mode
//!   filter's constants fitted to them first ([`modes`]); every change judged by the
//!   gain outside the minute where it gains most ([`blocks`]).
//!
//! Every model file records in its `training_data` metadata which simulator,
//! parameters and seed produced it, so `ghnet eval --model X` regenerates exactly its
//! held-out data without shipping data.

pub mod blocks;
pub mod epoch;
pub mod kf;
pub mod modes;
pub mod own;
pub mod temporal;

pub use epoch::{train_recipe, DataSpec, Recipe};
pub use temporal::TemporalRecipe;
