//! `ghnet_lab`: where GHNet models are made and judged. Simulation, training,
//! evaluation, plots, offline replay of logs and the `ghnet` command-line tool, on top
//! of the inference crate `ghnet_inference` (which never imports from here).
//!
//! # Layout
//! - [`sim`]: the paper's S1 grid and a realistic receiver over the full circle.
//! - [`drive`]: whole simulated tracks of cars (stops, parking, reversing) and
//!   turn-in-place platforms, seen by 1–10 Hz receivers with lag, gaps and three styles.
//! - [`logs`]: tracks of epochs with truth, from the simulator or from users' CSV logs.
//! - [`noisy`]: a real log seen by a noisier receiver (receiver noise added, truth
//!   kept), to judge the models on receivers unlike their training ones.
//! - [`loss`]: the losses that train the output heads, with their gradients.
//! - [`make`]: where models are made: each recipe (per-epoch, temporal, the Kalman
//!   filter, users' own logs) from data through training and σ maps to the written
//!   file.
//! - [`train`]: forward/backward of every layer, AdamW, early stopping, σ calibration.
//! - [`temporal`]: training the temporal model as a learned filter step on its own
//!   recorded outputs, and fitting its σ maps.
//! - [`streval`]: streamed evaluation on tracks: tables per speed band with stops as
//!   their own band, per platform, against the baselines (atan2, the tuned Kalman
//!   filter, the receiver's course), with σ calibration.
//! - [`bayes`]: the Bayes-optimal estimate for the S1 prior (the physical limit).
//! - [`eval`]: per-speed-bin tables, baselines and σ calibration; [`plot`]: the plots.
//! - [`table`]: the table engine both kinds of table count and print with.
//! - [`replay`]: streaming CSV inference for offline replay of logs (`ghnet infer`);
//!   [`receiver_log`]: UBX, NMEA and gpsd receiver logs as its input.
//!
//! This crate knows nothing about IPC: the daemon wires the models to the transports.
#![warn(missing_docs)]

pub mod bayes;
pub mod drive;
pub mod eval;
pub mod logs;
pub mod loss;
pub mod make;
pub mod noisy;
pub mod plot;
pub mod receiver_log;
pub mod replay;
pub mod sim;
pub mod streval;
pub mod table;
pub mod temporal;
pub mod train;
