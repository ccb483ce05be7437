//! Training the temporal model: the learned filter step, taught on its own outputs.
//!
//! At inference the network reads its own previous heading (through the per-epoch
//! inputs, [`ghnet_models::stream::inputs`]) and the cached features of the last `W`
//! epochs. Back-propagating through that recurrence over whole drives is what this
//! avoids: each training epoch first **runs the current model recurrently** over every
//! training track, exactly as ghnetd would ([`record`]: the same `StreamPredictor`,
//! history rules and inputs), and records each epoch's inputs, previous heading and how
//! many window slots were filled. Those recorded priors are then fixed inputs, and the
//! network learns one filter step from them by ordinary mini-batches (teacher forcing on
//! its own outputs, refreshed every epoch, so what it learns to correct is the error
//! process it actually has: no exposure bias beyond one epoch's drift). The first
//! epochs, when the network's own priors are noise, take the Kalman filter's priors
//! instead, and a share of tracks keeps them throughout; a small rate of random jumps of
//! the prior (`p_perturb`) teaches recovery from a confidently wrong heading, which is
//! what a platform that spun in place leaves behind.
//!
//! A mini-batch is `tiles` runs of `tile_len + W − 1` consecutive epochs of one track:
//! the convolution stack runs once per epoch (features of one epoch feed the `W`
//! windows that contain it), the fully connected head once per target epoch, and the
//! head's gradient is scattered back onto the features of every slot.

use std::sync::Arc;

use anyhow::{bail, Result};
use faer::Mat;
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use ghnet_models::head::{wrap_rad, Head, KalmanBase};
use ghnet_models::params::{Arch, ParamSet};
use ghnet_models::stream::{inputs, kalman_base, Epoch, StepState, StreamPredictor, INPUTS};
use ghnet_models::weights::{ModelKind, ModelMeta, FORMAT};
use ghnet_models::Model;

use crate::logs::LogTrack;
use crate::train::{fc_backward, fc_forward, fit_sigma_scale, AdamW, ConvStack, Mode};

/// Hyper-parameters of a temporal training run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TemporalConfig {
    /// Epochs in the window the head sees.
    pub window: usize,
    /// History gap limit written into the model, s.
    pub max_gap_s: f32,
    /// Maximum passes over the training tracks.
    pub epochs: usize,
    /// Runs of consecutive epochs per mini-batch.
    pub tiles: usize,
    /// Target epochs per run.
    pub tile_len: usize,
    /// Peak learning rate (one-epoch warm-up, cosine decay to 1%).
    pub lr: f32,
    /// AdamW weight decay on weight matrices.
    pub weight_decay: f32,
    /// Dropout after the last convolution (the paper's 0.1).
    pub dropout: f32,
    /// Weight of the σ likelihood in the loss.
    pub sigma_weight: f32,
    /// Stop after this many epochs without a better validation MAE.
    pub patience: usize,
    /// Epochs that learn from the Kalman filter's priors before switching to the
    /// network's own.
    pub kf_epochs: usize,
    /// Share of tracks that keep the Kalman filter's priors afterwards.
    pub kf_share: f64,
    /// Probability per epoch of the recorded run that the prior jumps to a random
    /// heading (its σ unchanged).
    pub p_perturb: f64,
    /// Seed of initialisation, tiling, dropout and perturbations.
    pub seed: u64,
}

impl Default for TemporalConfig {
    fn default() -> Self {
        Self {
            window: 8,
            max_gap_s: 10.0,
            epochs: 6,
            tiles: 16,
            tile_len: 64,
            lr: 2e-3,
            weight_decay: 1e-4,
            dropout: 0.1,
            sigma_weight: 0.1,
            patience: 8,
            kf_epochs: 2,
            kf_share: 0.2,
            p_perturb: 0.002,
            seed: 1,
        }
    }
}

/// What a recurrent run recorded, per epoch of every track, concatenated.
#[derive(Debug, Clone, Default)]
pub struct Recorded {
    /// The network's per-epoch inputs.
    pub x: Vec<[f32; INPUTS]>,
    /// Course atan2(v_E, v_N), radians.
    pub course: Vec<f32>,
    /// Previous heading the step starts from (the course on a history's first epoch).
    pub prior: Vec<f32>,
    /// The Kalman step the network corrects.
    pub base: Vec<KalmanBase>,
    /// True heading, degrees.
    pub truth: Vec<f32>,
    /// Window slots holding this history's epochs (1 on a history's first epoch).
    pub filled: Vec<u8>,
    /// Whether the course is opposite to the true heading, when clear
    /// ([`crate::loss::reverse_label`]).
    pub reverse: Vec<Option<bool>>,
    /// Start offset of each track; the last entry is the total.
    pub starts: Vec<usize>,
}

/// Run `model` over `tracks` as a stream, recording what each step saw, with the Kalman
/// step of `kind` (the model's own kind when `None`: a run of the Kalman filter records
/// for the temporal model it teaches). With `perturb`, the previous heading jumps to a
/// random one with that probability per epoch.
pub fn record(
    model: &Arc<Model>,
    tracks: &[LogTrack],
    window: usize,
    max_gap_s: f32,
    kind: Option<ModelKind>,
    mut perturb: Option<(&mut ChaCha8Rng, f64)>,
) -> Recorded {
    let mut rec = Recorded::default();
    let mut sp = StreamPredictor::new(model.clone());
    let kind = &kind.unwrap_or(model.meta().kind);
    for t in tracks {
        rec.starts.push(rec.x.len());
        let mut h = sp.history().with_max_gap(max_gap_s as f64);
        let mut pos = 0usize;
        let mut t_prev = f64::NAN;
        for i in 0..t.len() {
            if let Some((rng, p)) = perturb.as_mut() {
                if rng.random::<f64>() < *p && h.state().has_prior {
                    let mut s = *h.state();
                    s.psi += rng.random_range(-std::f32::consts::PI..std::f32::consts::PI);
                    h.set_state(s);
                }
            }
            let before = *h.state();
            let e = Epoch {
                t_s: t.t_s[i],
                v_north: t.v_north[i],
                v_east: t.v_east[i],
                speed_acc: t.speed_acc[i],
            };
            sp.predict(&mut h, &e);
            let fresh = h.last_reset().is_some() || i == 0;
            let (state, dt) = if fresh {
                pos = 0;
                (StepState::EMPTY, 0.0)
            } else {
                pos += 1;
                (before, (e.t_s - t_prev) as f32)
            };
            t_prev = e.t_s;
            let acc = if e.speed_acc.is_finite() && e.speed_acc > 0.0 {
                e.speed_acc
            } else {
                f32::NAN
            };
            let course = e.v_east.atan2(e.v_north);
            let base = kalman_base(kind, &state, e.v_north, e.v_east, dt);
            rec.base.push(base);
            rec.x
                .push(inputs(&state, e.v_north, e.v_east, acc, dt, &base));
            rec.course.push(course);
            rec.prior
                .push(if state.has_prior { state.psi } else { course });
            rec.truth.push(t.truth_deg[i]);
            rec.reverse.push(crate::loss::reverse_label(
                e.v_north,
                e.v_east,
                t.truth_deg[i],
            ));
            rec.filled.push((pos + 1).min(window) as u8);
        }
    }
    rec.starts.push(rec.x.len());
    rec
}

/// Wrapped errors (radians) and raw σ (radians) of `model` streamed over `tracks`.
pub fn stream_errors(model: &Arc<Model>, tracks: &[LogTrack]) -> (Vec<f32>, Vec<f32>) {
    let mut sp = StreamPredictor::new(model.clone());
    let (mut errs, mut sig) = (Vec::new(), Vec::new());
    for t in tracks {
        let mut h = sp.history();
        for i in 0..t.len() {
            let e = Epoch {
                t_s: t.t_s[i],
                v_north: t.v_north[i],
                v_east: t.v_east[i],
                speed_acc: t.speed_acc[i],
            };
            let p = sp.predict(&mut h, &e);
            errs.push(wrap_rad((p.heading_deg - t.truth_deg[i]).to_radians()));
            // The reported σ over the model's calibration: the raw σ to calibrate.
            sig.push((p.std_deg / model.meta().sigma_scale).to_radians());
        }
    }
    (errs, sig)
}

/// The model file's metadata for a temporal network.
pub fn temporal_meta(name: &str, arch: Arch, cfg: &TemporalConfig, kf: &Model) -> ModelMeta {
    let ModelKind::Kf {
        q_deg_per_sqrt_s,
        sigma_v_mps,
        ..
    } = kf.meta().kind
    else {
        panic!("the Kalman step comes from a kf model")
    };
    ModelMeta {
        format: FORMAT.into(),
        name: name.into(),
        architecture: arch,
        activation: "gelu_tanh".into(),
        head: Head::Filter,
        input_scale_mps: 1.0,
        heading_range_deg: [0.0, 360.0],
        sigma_scale: 1.0,
        accuracy_sigma_scale: f32::NAN,
        training_data: serde_json::Value::Null,
        training: serde_json::Value::Null,
        metrics: serde_json::Value::Null,
        kind: ModelKind::Temporal {
            max_gap_s: cfg.max_gap_s,
            q_deg_per_sqrt_s,
            sigma_v_mps,
        },
    }
}

/// One run of consecutive epochs `[c0, c0 + cols)` of the recording and its targets.
#[derive(Debug, Clone, Copy)]
struct Tile {
    c0: usize,
    first: bool,
}

/// Tiles over every track: stride `tile_len`, a random offset per track, each epoch a
/// target of exactly one tile (except the few before the offset).
fn tiles(rec: &Recorded, cols: usize, tile_len: usize, rng: &mut ChaCha8Rng) -> Vec<Tile> {
    let mut out = Vec::new();
    for w in rec.starts.windows(2) {
        let (s, e) = (w[0], w[1]);
        if e - s < cols {
            continue;
        }
        let mut c0 = s + rng.random_range(0..tile_len.min(e - s - cols + 1));
        let mut first = true;
        while c0 + cols <= e {
            out.push(Tile { c0, first });
            first = false;
            c0 += tile_len;
        }
    }
    out.shuffle(rng);
    out
}

/// Buffers of one mini-batch of the temporal graph.
struct Batch {
    stack: ConvStack,
    /// (column in the batch, recording index, filled slots) of each target.
    targets: Vec<(usize, usize, usize)>,
    g: Mat<f32>,
    fc: Vec<Mat<f32>>,
    dfc: Vec<Mat<f32>>,
    dg: Mat<f32>,
    dy: Mat<f32>,
}

impl Batch {
    fn new(arch: &Arch, cols: usize) -> Self {
        let fc: Vec<Mat<f32>> = arch
            .fc_dims()
            .iter()
            .map(|&(_, o)| Mat::zeros(o, cols))
            .collect();
        let gin = arch.fc_dims()[0].0;
        Self {
            stack: ConvStack::new(arch, cols),
            targets: Vec::with_capacity(cols),
            g: Mat::zeros(gin, cols),
            dfc: fc.iter().map(|m| Mat::zeros(m.nrows(), cols)).collect(),
            fc,
            dg: Mat::zeros(gin, cols),
            dy: Mat::zeros(arch.output, cols),
        }
    }
}

/// One mini-batch: forward, loss, backward into `grads`. Returns (loss sum, targets).
fn step(
    b: &mut Batch,
    params: &mut ParamSet,
    rec: &Recorded,
    tiles: &[Tile],
    cfg: &TemporalConfig,
    grads: &mut [f32],
) -> (f64, usize) {
    let cols = cfg.tile_len + cfg.window - 1;
    let w = cfg.window;
    b.targets.clear();
    {
        let mut x = b.stack.input_mut();
        for (k, t) in tiles.iter().enumerate() {
            for j in 0..cols {
                let i = t.c0 + j;
                for (r, v) in rec.x[i].iter().enumerate() {
                    x[(r, k * cols + j)] = *v;
                }
                let f = rec.filled[i] as usize;
                if i + 1 >= t.c0 + f && (t.first || j + 1 >= w) {
                    b.targets.push((k * cols + j, i, f));
                }
            }
        }
    }
    b.stack.forward(params, Mode::Train);
    let nt = b.targets.len();
    let feats = b.stack.features();
    let c = feats.nrows();
    for (n, &(col, _, f)) in b.targets.iter().enumerate() {
        for k in 0..w {
            for ch in 0..c {
                b.g[(k * c + ch, n)] = if k < f { feats[(ch, col - k)] } else { 0.0 };
            }
        }
    }
    for l in 0..b.fc.len() {
        let (done, todo) = b.fc.split_at_mut(l);
        let input = if l == 0 {
            b.g.as_ref()
        } else {
            done[l - 1].as_ref()
        };
        fc_forward(
            params,
            l + 1,
            input.subcols(0, nt),
            todo[0].as_mut().subcols_mut(0, nt),
        );
    }
    let mut loss = 0.0f64;
    let out = b.fc.last().expect("fc");
    let mut dy = [0.0f32; 3];
    for (n, &(_, i, _)) in b.targets.iter().enumerate() {
        let y = [out[(0, n)], out[(1, n)], out[(2, n)]];
        let (l, _, _) = crate::loss::filter_loss(
            &y,
            rec.course[i],
            rec.prior[i],
            &rec.base[i],
            rec.truth[i],
            rec.reverse[i],
            cfg.sigma_weight,
            &mut dy,
        );
        loss += l as f64;
        for (k, d) in dy.iter().enumerate() {
            b.dy[(k, n)] = d / nt as f32;
        }
    }
    backward(b, params, nt, w, c, grads);
    (loss, nt)
}

/// Back through the fc layers, the gather, and the convolution stack.
fn backward(b: &mut Batch, params: &ParamSet, nt: usize, w: usize, c: usize, grads: &mut [f32]) {
    let n_fc = b.fc.len();
    b.dfc[n_fc - 1]
        .as_mut()
        .subcols_mut(0, nt)
        .copy_from(b.dy.as_ref().subcols(0, nt));
    for l in (0..n_fc).rev() {
        let (dprev, dcur) = b.dfc.split_at_mut(l);
        let (input, dx) = if l == 0 {
            (b.g.as_ref(), b.dg.as_mut())
        } else {
            (b.fc[l - 1].as_ref(), dprev[l - 1].as_mut())
        };
        fc_backward(
            params,
            l + 1,
            input.subcols(0, nt),
            dcur[0].as_ref().subcols(0, nt),
            grads,
            dx.subcols_mut(0, nt),
        );
    }
    let mut df = b.stack.d_features_mut();
    df.fill(0.0);
    for (n, &(col, _, f)) in b.targets.iter().enumerate() {
        for k in 0..f.min(w) {
            for ch in 0..c {
                df[(ch, col - k)] += b.dg[(k * c + ch, n)];
            }
        }
    }
    b.stack.backward(params, grads);
}

/// What [`train`] returns.
#[derive(Debug, Clone)]
pub struct TrainedTemporal {
    /// The model with the best validation MAE (σ calibrated on validation).
    pub model: Model,
    /// Its epoch.
    pub best_epoch: usize,
    /// Its validation MAE, degrees (streamed, on its own outputs).
    pub best_val_mae_deg: f32,
    /// Epochs run.
    pub epochs_run: usize,
}

/// Learning rate at `step` of `total` (warm-up over `warmup`, cosine to 1%).
fn schedule(lr: f32, step: usize, warmup: usize, total: usize) -> f32 {
    if step < warmup {
        lr * (step + 1) as f32 / warmup as f32
    } else {
        let p = (step - warmup) as f32 / (total - warmup).max(1) as f32;
        lr * (0.01 + 0.99 * 0.5 * (1.0 + (std::f32::consts::PI * p.min(1.0)).cos()))
    }
}

/// Train (or, with `init`, fine-tune) a temporal model named `name` on `train` tracks,
/// selecting on streamed validation MAE over `val` tracks. `kf` gives the priors of the
/// first epochs. `progress` sees (epoch, train loss, validation MAE °, best MAE °).
pub fn train(
    name: &str,
    train: &[LogTrack],
    val: &[LogTrack],
    kf: &Arc<Model>,
    init: Option<&Model>,
    cfg: &TemporalConfig,
    mut progress: impl FnMut(usize, f32, f32, f32),
) -> Result<TrainedTemporal> {
    let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed);
    let arch = Arch::temporal(INPUTS, cfg.window, 3);
    let mut params = initial_params(init, &arch, cfg, &mut rng)?;
    let cols = cfg.tile_len + cfg.window - 1;
    let meta = temporal_meta(name, arch.clone(), cfg, kf);
    let kf_rec = record(kf, train, cfg.window, cfg.max_gap_s, Some(meta.kind), None);
    if tiles(&kf_rec, cols, cfg.tile_len, &mut rng.clone()).len() < cfg.tiles {
        bail!(
            "too little training data: fewer than {} runs of {cols} epochs",
            cfg.tiles
        );
    }
    let mut batch = Batch::new(&arch, cfg.tiles * cols);
    let mut grads = vec![0.0f32; params.data().len()];
    let mut opt = AdamW::new(&params, cfg.weight_decay);
    let steps_per_epoch = tiles(&kf_rec, cols, cfg.tile_len, &mut rng.clone()).len() / cfg.tiles;
    let total = steps_per_epoch * cfg.epochs;
    let (mut best, mut best_epoch, mut best_mae, mut epochs_run) = (None, 0, f32::INFINITY, 0);
    let mut step_no = 0;
    for epoch in 1..=cfg.epochs {
        epochs_run = epoch;
        let rec = if epoch <= cfg.kf_epochs && init.is_none() {
            kf_rec.clone()
        } else {
            let model = Arc::new(Model::new(params.clone(), meta.clone()));
            own_priors(&model, train, &kf_rec, cfg, &mut rng)
        };
        let all = tiles(&rec, cols, cfg.tile_len, &mut rng);
        let mut loss = (0.0f64, 0usize);
        for chunk in all.chunks_exact(cfg.tiles) {
            batch.stack.sample_dropout(cfg.dropout, &mut rng);
            let (l, n) = step(&mut batch, &mut params, &rec, chunk, cfg, &mut grads);
            loss = (loss.0 + l, loss.1 + n);
            opt.step(
                params.data_mut(),
                &grads,
                schedule(cfg.lr, step_no, steps_per_epoch, total),
            );
            step_no += 1;
        }
        let model = Arc::new(Model::new(params.clone(), meta.clone()));
        let (errs, _) = stream_errors(&model, val);
        let mae = mean_abs_deg(&errs);
        if mae < best_mae {
            (best, best_epoch, best_mae) = (Some(params.clone()), epoch, mae);
        }
        progress(epoch, (loss.0 / loss.1.max(1) as f64) as f32, mae, best_mae);
        if epoch - best_epoch >= cfg.patience {
            break;
        }
    }
    Ok(TrainedTemporal {
        model: calibrated(best.expect("at least one epoch"), meta, val),
        best_epoch,
        best_val_mae_deg: best_mae,
        epochs_run,
    })
}

/// The model with σ scaled so that 68.3% of its streamed validation errors fall within
/// 1σ.
fn calibrated(params: ParamSet, mut meta: ModelMeta, val: &[LogTrack]) -> Model {
    let raw = Arc::new(Model::new(params.clone(), meta.clone()));
    let (errs, sig) = stream_errors(&raw, val);
    meta.sigma_scale = fit_sigma_scale(&errs, &sig);
    Model::new(params, meta)
}

/// The network's own recorded priors (with perturbations), a share of tracks swapped
/// for the Kalman filter's.
fn own_priors(
    model: &Arc<Model>,
    train: &[LogTrack],
    kf_rec: &Recorded,
    cfg: &TemporalConfig,
    rng: &mut ChaCha8Rng,
) -> Recorded {
    let own = record(
        model,
        train,
        cfg.window,
        cfg.max_gap_s,
        None,
        Some((&mut *rng, cfg.p_perturb)),
    );
    mix(kf_rec, &own, cfg.kf_share, rng)
}

/// Weights to start from: `init`'s (fine-tuning), or random ones with a zero output
/// layer, so that the untrained model is exactly the Kalman filter and training moves
/// away from it only where that lowers the error.
fn initial_params(
    init: Option<&Model>,
    arch: &Arch,
    cfg: &TemporalConfig,
    rng: &mut ChaCha8Rng,
) -> Result<ParamSet> {
    Ok(match init {
        Some(m) if m.params().arch() == arch => m.params().clone(),
        Some(m) => bail!(
            "--init {}: not a temporal model with window {}",
            m.name(),
            cfg.window
        ),
        None => {
            let mut p = ParamSet::init(arch, |b| rng.random_range(-b..b));
            p.get_mut("fc4.bias")
                .copy_from_slice(&crate::loss::initial_bias(&Head::Filter));
            p.get_mut("fc4.weight").fill(0.0);
            p
        }
    })
}

/// Per track, the Kalman filter's recording with probability `kf_share`, else the
/// network's.
fn mix(kf: &Recorded, own: &Recorded, kf_share: f64, rng: &mut ChaCha8Rng) -> Recorded {
    let mut out = own.clone();
    for w in kf.starts.windows(2) {
        if rng.random::<f64>() < kf_share {
            for i in w[0]..w[1] {
                out.x[i] = kf.x[i];
                out.prior[i] = kf.prior[i];
                out.base[i] = kf.base[i];
                out.filled[i] = kf.filled[i];
            }
        }
    }
    out
}

/// Mean absolute error of radians, in degrees.
pub fn mean_abs_deg(errs: &[f32]) -> f32 {
    (errs.iter().map(|e| e.abs() as f64).sum::<f64>() / errs.len().max(1) as f64).to_degrees()
        as f32
}
