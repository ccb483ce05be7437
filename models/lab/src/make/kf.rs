//! The Kalman filter baseline as a model: its parameters, and its tuning by grid search
//! on validation tracks (never on the tracks of a table it is compared in).

use std::sync::Arc;

use ghnet_inference::head::Head;
use ghnet_inference::params::{Arch, ParamSet};
use ghnet_inference::weights::{ModelKind, ModelMeta};
use ghnet_inference::Model;

use crate::logs::LogTrack;
use crate::streval::{mae, run_model};

/// The Kalman filter has no network: no layers, and a window of the current epoch.
const NO_NETWORK: Arch = Arch {
    input: 0,
    conv: Vec::new(),
    fc: Vec::new(),
    output: 0,
    window: 1,
};

/// A model-free Kalman filter model with these parameters (what `kf` ships as).
pub fn kf_model(q_deg_per_sqrt_s: f32, sigma_v_mps: f32, max_gap_s: f32) -> Model {
    let arch = NO_NETWORK;
    let kind = ModelKind::Kf {
        q_deg_per_sqrt_s,
        sigma_v_mps,
        max_gap_s,
    };
    let head = Head::Residual {
        range_deg: [0.0, 360.0],
    };
    let meta = ModelMeta::new("kf", arch.clone(), head, kind);
    Model::new(ParamSet::zeros(&arch), meta)
}

/// The grid [`tune_kf`] searches: `q` (°/√s) and `σ_v` (m/s).
const Q_GRID: [f32; 13] = [
    0.5, 1.0, 2.0, 3.0, 5.0, 8.0, 12.0, 20.0, 30.0, 45.0, 60.0, 90.0, 120.0,
];
const SIGMA_V_GRID: [f32; 11] = [0.03, 0.05, 0.1, 0.2, 0.3, 0.5, 0.8, 1.2, 2.0, 3.0, 4.0];

/// The Kalman filter tuned on `tracks` by grid search over `q` and `σ_v` (streamed MAE):
/// the baseline's parameters, chosen on validation data only. The grid's points run on
/// every core (a 10 Hz log of 100 drives streams 143 times); the best is the first of
/// the grid's order at the lowest MAE, whatever the number of cores.
pub fn tune_kf(tracks: &[LogTrack], max_gap_s: f32) -> (f32, f32, f64) {
    let points: Vec<(f32, f32)> = Q_GRID
        .iter()
        .flat_map(|&q| SIGMA_V_GRID.iter().map(move |&sv| (q, sv)))
        .collect();
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    let chunk = points.len().div_ceil(threads);
    let maes: Vec<f64> = std::thread::scope(|s| {
        let handles: Vec<_> = points
            .chunks(chunk)
            .map(|part| {
                s.spawn(move || {
                    part.iter()
                        .map(|&(q, sv)| {
                            let m = Arc::new(kf_model(q, sv, max_gap_s));
                            mae(&run_model(&m, tracks, "kf"), tracks)
                        })
                        .collect::<Vec<f64>>()
                })
            })
            .collect();
        handles
            .into_iter()
            .flat_map(|h| h.join().expect("a kf grid thread panicked"))
            .collect()
    });
    let mut best = (0.0, 0.0, f64::INFINITY);
    for (&(q, sv), &e) in points.iter().zip(&maes) {
        if e < best.2 {
            best = (q, sv, e);
        }
    }
    best
}

/// The Kalman filter tuned on `val`, as a model.
pub fn tuned_kf(val: &[LogTrack], max_gap_s: f32) -> (Model, f64) {
    let (q, sv, mae) = tune_kf(val, max_gap_s);
    let mut m = kf_model(q, sv, max_gap_s);
    let meta = {
        let mut meta = m.meta().clone();
        meta.training = serde_json::json!({
            "tuned_on": "validation tracks of the ghnet-temporal recipe (simulated drives)",
            "val_mae_deg": mae,
            "grid": "q in 0.5..120 deg/sqrt(s), sigma_v in 0.03..4 m/s",
        });
        meta
    };
    m = Model::new(m.params().clone(), meta);
    (m, mae)
}
