//! Training in Rust: forward and backward passes of every layer, AdamW, dropout,
//! batch-norm running statistics, validation with early stopping, σ calibration.
//!
//! Everything is single-threaded (`Par::Seq`) and seeded, so the same data, config and
//! seed give bit-identical weights on the same machine. The layers' forward and backward
//! passes are the layer kernels of the `layers` module, re-exported here.

use faer::Mat;
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use ghnet_inference::head::{accuracy_sigma_base, scale_input, Head};
use ghnet_inference::net::Network;
use ghnet_inference::params::{Arch, ParamSet, Role};

mod layers;
pub use layers::{
    apply_mask, bn_backward_train, bn_forward_train, dense_backward, dense_forward, fc_backward,
    fc_forward, gelu_forward, ConvStack, Graph, Mode,
};

/// Hyper-parameters of one training run.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct TrainConfig {
    /// Maximum number of passes over the training set.
    pub epochs: usize,
    /// Mini-batch size.
    pub batch: usize,
    /// Peak learning rate (after a one-epoch warm-up, cosine decay to `lr·0.01`).
    pub lr: f32,
    /// AdamW decoupled weight decay, applied to weight matrices only.
    pub weight_decay: f32,
    /// Dropout probability after the last convolution (the paper's 0.1).
    pub dropout: f32,
    /// Weight of the σ likelihood term in the loss.
    pub sigma_weight: f32,
    /// Stop when validation MAE has not improved for this many epochs.
    pub patience: usize,
    /// Seed for initialisation, shuffling and dropout.
    pub seed: u64,
}

impl Default for TrainConfig {
    fn default() -> Self {
        Self {
            epochs: 200,
            batch: 256,
            lr: 2e-3,
            weight_decay: 1e-4,
            dropout: 0.1,
            sigma_weight: 0.1,
            patience: 30,
            seed: 1,
        }
    }
}

/// Training or validation samples: raw velocities (m/s) and true headings (degrees).
#[derive(Debug, Clone, Default)]
pub struct Dataset {
    /// North velocity, m/s.
    pub v_north: Vec<f32>,
    /// East velocity, m/s.
    pub v_east: Vec<f32>,
    /// True heading, degrees clockwise from north.
    pub heading_deg: Vec<f32>,
    /// Receiver-reported speed accuracy (1σ, m/s), NaN when unknown. Not a network input;
    /// used to fit the accuracy-derived σ.
    pub speed_acc: Vec<f32>,
}

impl Dataset {
    /// Number of samples.
    pub fn len(&self) -> usize {
        self.v_north.len()
    }
    /// True when empty.
    pub fn is_empty(&self) -> bool {
        self.v_north.is_empty()
    }
    /// Append one sample.
    pub fn push(&mut self, v_north: f32, v_east: f32, heading_deg: f32, speed_acc: f32) {
        self.v_north.push(v_north);
        self.v_east.push(v_east);
        self.heading_deg.push(heading_deg);
        self.speed_acc.push(speed_acc);
    }
}

/// What one epoch did, for the progress bar and the log.
#[derive(Debug, Clone, Copy)]
pub struct EpochReport {
    /// Epoch number from 1.
    pub epoch: usize,
    /// Mean training loss.
    pub train_loss: f32,
    /// Validation objective (MAE in radians plus weighted σ negative log-likelihood):
    /// what early stopping selects on.
    pub val_loss: f32,
    /// Validation MAE of the wrapped heading error, degrees.
    pub val_mae_deg: f32,
    /// Validation MAE of the best epoch so far, degrees.
    pub best_val_mae_deg: f32,
    /// Learning rate used in this epoch.
    pub lr: f32,
}

/// The result of training.
#[derive(Debug, Clone)]
pub struct Trained {
    /// Best weights by validation MAE.
    pub params: ParamSet,
    /// σ scale fitted on the validation set (68.3% of errors within 1σ).
    pub sigma_scale: f32,
    /// Scale of the sAcc-derived σ, fitted the same way on validation samples that report
    /// a speed accuracy; NaN for heads that do not use it (restricted ranges, where the
    /// prior, not the receiver noise, bounds the error at low speed).
    pub accuracy_sigma_scale: f32,
    /// Epoch of the best weights (lowest validation objective).
    pub best_epoch: usize,
    /// Validation MAE of the best weights, degrees.
    pub best_val_mae_deg: f32,
    /// Epochs run.
    pub epochs_run: usize,
}

/// AdamW state: first and second moments for every element of the ParamSet.
pub struct AdamW {
    m: Vec<f32>,
    v: Vec<f32>,
    t: i32,
    decay_mask: Vec<bool>,
    train_mask: Vec<bool>,
    /// Decoupled weight decay.
    pub weight_decay: f32,
}

impl AdamW {
    const B1: f32 = 0.9;
    const B2: f32 = 0.999;
    const EPS: f32 = 1e-8;

    /// Optimiser state for `params`: weight decay on weight matrices only, buffers frozen.
    pub fn new(params: &ParamSet, weight_decay: f32) -> Self {
        let n = params.data().len();
        let mut decay_mask = vec![false; n];
        let mut train_mask = vec![false; n];
        for (i, s) in params.specs().iter().enumerate() {
            for k in params.range(i) {
                decay_mask[k] = s.role == Role::Weight;
                train_mask[k] = s.role != Role::Buffer;
            }
        }
        Self {
            m: vec![0.0; n],
            v: vec![0.0; n],
            t: 0,
            decay_mask,
            train_mask,
            weight_decay,
        }
    }

    /// One step with learning rate `lr`.
    pub fn step(&mut self, params: &mut [f32], grads: &[f32], lr: f32) {
        self.t += 1;
        let bc1 = 1.0 - Self::B1.powi(self.t);
        let bc2 = 1.0 - Self::B2.powi(self.t);
        for k in 0..params.len() {
            if !self.train_mask[k] {
                continue;
            }
            let g = grads[k];
            if self.decay_mask[k] {
                params[k] -= lr * self.weight_decay * params[k];
            }
            self.m[k] = Self::B1 * self.m[k] + (1.0 - Self::B1) * g;
            self.v[k] = Self::B2 * self.v[k] + (1.0 - Self::B2) * g * g;
            let mh = self.m[k] / bc1;
            let vh = self.v[k] / bc2;
            params[k] -= lr * mh / (vh.sqrt() + Self::EPS);
        }
    }
}

/// Wrapped errors (radians) of the decoded headings and raw σ (radians) of a folded
/// network over a dataset.
pub fn evaluate(
    net: &Network,
    head: &Head,
    input_scale: f32,
    data: &Dataset,
) -> (Vec<f32>, Vec<f32>) {
    let n = data.len();
    let chunk = 1024;
    let mut scratch = net.scratch(chunk);
    let mut x = Mat::<f32>::zeros(2, chunk);
    let mut y = Mat::<f32>::zeros(net.outputs(), chunk);
    let mut errs = Vec::with_capacity(n);
    let mut sigmas = Vec::with_capacity(n);
    let mut dy = vec![0.0; net.outputs()];
    let mut start = 0;
    while start < n {
        let len = chunk.min(n - start);
        for j in 0..len {
            let s = scale_input(data.v_north[start + j], data.v_east[start + j], input_scale);
            x[(0, j)] = s[0];
            x[(1, j)] = s[1];
        }
        net.forward(
            x.as_ref().subcols(0, len),
            y.as_mut().subcols_mut(0, len),
            &mut scratch,
        );
        for j in 0..len {
            let out: Vec<f32> = (0..net.outputs()).map(|k| y[(k, j)]).collect();
            let i = start + j;
            // Judge what users get: the decoded (and, for a restricted range, clamped)
            // heading, with σ before calibration.
            let (_, _, s) = crate::loss::head_loss(
                head,
                &out,
                data.v_north[i],
                data.v_east[i],
                data.heading_deg[i],
                0.0,
                &mut dy,
            );
            let (deg, _) = head.decode(&out, data.v_north[i], data.v_east[i], 1.0);
            errs.push(ghnet_inference::head::wrap_rad(
                (deg - data.heading_deg[i]).to_radians(),
            ));
            sigmas.push(s);
        }
        start += len;
    }
    (errs, sigmas)
}

/// Mean absolute value of radians, in degrees.
fn mae_deg(errs: &[f32]) -> f32 {
    (errs.iter().map(|e| e.abs() as f64).sum::<f64>() / errs.len().max(1) as f64).to_degrees()
        as f32
}

/// Mean of the training objective over validation errors and raw σ (radians).
fn val_objective(errs: &[f32], sigmas: &[f32], sigma_weight: f32) -> f32 {
    let mut sum = 0.0f64;
    for (e, s) in errs.iter().zip(sigmas) {
        let s = s.max(1e-9);
        sum += e.abs() as f64 + (sigma_weight * (0.5 * e * e / (s * s) + s.ln())) as f64;
    }
    (sum / errs.len().max(1) as f64) as f32
}

/// The scale `k` such that 68.27% of `|e|/σ` are at most `k`.
pub fn fit_sigma_scale(errs: &[f32], sigmas: &[f32]) -> f32 {
    let mut z: Vec<f32> = errs
        .iter()
        .zip(sigmas)
        .map(|(e, s)| e.abs() / s.max(1e-9))
        .filter(|z| z.is_finite())
        .collect();
    if z.is_empty() {
        return 1.0;
    }
    z.sort_by(|a, b| a.total_cmp(b));
    let k = ((z.len() as f64) * 0.6827).floor() as usize;
    z[k.min(z.len() - 1)].max(1e-6)
}

/// Train a network with `head` on `train`, selecting the best epoch on `val`.
pub fn train(
    arch: &Arch,
    head: &Head,
    input_scale: f32,
    train: &Dataset,
    val: &Dataset,
    cfg: &TrainConfig,
    mut progress: impl FnMut(&EpochReport),
) -> Trained {
    assert_eq!(
        arch.output,
        head.outputs(),
        "architecture output must match head"
    );
    assert!(
        !train.is_empty() && !val.is_empty(),
        "empty training or validation set"
    );
    let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed);
    let mut params = initial_params(arch, head, &mut rng);
    let mut opt = AdamW::new(&params, cfg.weight_decay);
    let batch = cfg.batch.min(train.len()).max(2);
    let mut stepper = Stepper::new(arch, head, input_scale, cfg, batch, params.data().len());
    let mut order: Vec<usize> = (0..train.len()).collect();
    let steps_per_epoch = train.len() / batch;
    let schedule = Schedule {
        lr: cfg.lr,
        warmup: steps_per_epoch.max(1),
        total: (steps_per_epoch * cfg.epochs).max(1),
    };
    let mut step = 0usize;
    let mut best = (f32::INFINITY, 0usize, params.clone());
    let mut best_mae = f32::INFINITY;
    let mut epochs_run = 0;
    for epoch in 1..=cfg.epochs {
        epochs_run = epoch;
        order.shuffle(&mut rng);
        let mut loss_sum = 0.0f64;
        let mut lr = cfg.lr;
        for idx in order.chunks_exact(batch) {
            loss_sum += stepper.gradients(&mut params, train, idx, &mut rng);
            lr = schedule.at(step);
            opt.step(params.data_mut(), &stepper.grads, lr);
            step += 1;
        }
        let net = Network::fold(&params);
        let (errs, sigmas) = evaluate(&net, head, input_scale, val);
        let val_mae = mae_deg(&errs);
        // Select on the training objective (heading MAE plus the σ likelihood), not on MAE
        // alone: where the heading cannot improve (full circle), σ still can.
        let val_loss = val_objective(&errs, &sigmas, cfg.sigma_weight);
        if val_loss < best.0 {
            best = (val_loss, epoch, params.clone());
            best_mae = val_mae;
        }
        progress(&EpochReport {
            epoch,
            train_loss: (loss_sum / (steps_per_epoch * batch).max(1) as f64) as f32,
            val_loss,
            val_mae_deg: val_mae,
            best_val_mae_deg: best_mae,
            lr,
        });
        if epoch - best.1 >= cfg.patience {
            break;
        }
    }
    let (_, best_epoch, params) = best;
    let (accuracy_sigma_scale, sigma_scale) = fit_sigma_scales(&params, head, input_scale, val);
    Trained {
        params,
        accuracy_sigma_scale,
        sigma_scale,
        best_epoch,
        best_val_mae_deg: best_mae,
        epochs_run,
    }
}

/// Random weights, and an output bias at the head's neutral answer (so the first
/// steps refine a sensible estimate instead of undoing a random one).
fn initial_params(arch: &Arch, head: &Head, rng: &mut ChaCha8Rng) -> ParamSet {
    let mut params = ParamSet::init(arch, |b| rng.random_range(-b..b));
    let n_out = arch.fc.len() + 1;
    params
        .get_mut(&format!("fc{n_out}.bias"))
        .copy_from_slice(&crate::loss::initial_bias(head));
    params
}

/// The learning rate: a linear warm-up over the first epoch, then a cosine decay to 1 %
/// of `lr` at the last step (large steps early, fine ones at the end).
struct Schedule {
    lr: f32,
    warmup: usize,
    total: usize,
}

impl Schedule {
    fn at(&self, step: usize) -> f32 {
        if step < self.warmup {
            self.lr * (step + 1) as f32 / self.warmup as f32
        } else {
            let p = (step - self.warmup) as f32 / (self.total - self.warmup).max(1) as f32;
            self.lr * (0.01 + 0.99 * 0.5 * (1.0 + (std::f32::consts::PI * p.min(1.0)).cos()))
        }
    }
}

/// The buffers of one mini-batch step, allocated once for the whole training.
struct Stepper<'a> {
    head: &'a Head,
    input_scale: f32,
    cfg: &'a TrainConfig,
    graph: Graph,
    dout: Mat<f32>,
    grads: Vec<f32>,
    yj: Vec<f32>,
    dyj: Vec<f32>,
}

impl<'a> Stepper<'a> {
    fn new(
        arch: &Arch,
        head: &'a Head,
        input_scale: f32,
        cfg: &'a TrainConfig,
        batch: usize,
        n_params: usize,
    ) -> Self {
        Stepper {
            head,
            input_scale,
            cfg,
            graph: Graph::new(arch, batch),
            dout: Mat::<f32>::zeros(arch.output, batch),
            grads: vec![0.0; n_params],
            yj: vec![0.0; arch.output],
            dyj: vec![0.0; arch.output],
        }
    }

    /// Forward and backward over the samples `idx` of `train`: leaves the batch's
    /// gradients in `self.grads` and returns the summed loss.
    fn gradients(
        &mut self,
        params: &mut ParamSet,
        train: &Dataset,
        idx: &[usize],
        rng: &mut ChaCha8Rng,
    ) -> f64 {
        let batch = idx.len();
        {
            let mut x = self.graph.input_mut();
            for (j, &i) in idx.iter().enumerate() {
                let s = scale_input(train.v_north[i], train.v_east[i], self.input_scale);
                x[(0, j)] = s[0];
                x[(1, j)] = s[1];
            }
        }
        self.graph.sample_dropout(self.cfg.dropout, rng);
        self.graph.forward(params, Mode::Train);
        let out = self.graph.output();
        let mut loss_sum = 0.0f64;
        for (j, &i) in idx.iter().enumerate() {
            for (k, y) in self.yj.iter_mut().enumerate() {
                *y = out[(k, j)];
            }
            let (l, _, _) = crate::loss::head_loss(
                self.head,
                &self.yj,
                train.v_north[i],
                train.v_east[i],
                train.heading_deg[i],
                self.cfg.sigma_weight,
                &mut self.dyj,
            );
            loss_sum += l as f64;
            for (k, d) in self.dyj.iter().enumerate() {
                self.dout[(k, j)] = d / batch as f32;
            }
        }
        self.graph
            .backward(params, self.dout.as_ref(), &mut self.grads);
        loss_sum
    }
}

/// The σ scales of the trained `params` fitted on `val`: the one for the speed-accuracy
/// σ (NaN where the head does not use sAcc or no sample reports it) and the one for the
/// network's own σ.
fn fit_sigma_scales(params: &ParamSet, head: &Head, input_scale: f32, val: &Dataset) -> (f32, f32) {
    let net = Network::fold(params);
    let (errs, sigmas) = evaluate(&net, head, input_scale, val);
    let accuracy = if head.uses_speed_accuracy() {
        let (e, b): (Vec<f32>, Vec<f32>) = (0..val.len())
            .filter_map(|i| {
                let base = accuracy_sigma_base(val.v_north[i], val.v_east[i], val.speed_acc[i])?;
                Some((errs[i], base))
            })
            .unzip();
        if e.is_empty() {
            f32::NAN
        } else {
            fit_sigma_scale(&e, &b)
        }
    } else {
        f32::NAN
    };
    (accuracy, fit_sigma_scale(&errs, &sigmas))
}

#[cfg(test)]
mod tests {
    use super::*;
    use faer::MatRef;

    fn rand_mat(rng: &mut ChaCha8Rng, r: usize, c: usize) -> Mat<f32> {
        Mat::from_fn(r, c, |_, _| rng.random_range(-1.0f32..1.0))
    }

    /// `Σ r ⊙ m` in f64, the linear functional the layer checks differentiate.
    fn dot(r: MatRef<'_, f32>, m: MatRef<'_, f32>) -> f64 {
        let mut s = 0.0;
        for j in 0..m.ncols() {
            for i in 0..m.nrows() {
                s += r[(i, j)] as f64 * m[(i, j)] as f64;
            }
        }
        s
    }

    fn assert_close(analytic: f32, fd: f64, what: &str) {
        assert!(
            (analytic as f64 - fd).abs() <= 2e-3 * (1.0 + fd.abs()),
            "{what}: analytic {analytic} vs finite difference {fd}"
        );
    }

    const H: f32 = 1e-2;

    /// The central difference `(loss(x + h) − loss(x − h)) / 2h` in one entry of `x`,
    /// which `nudge(x, d)` moves by `d`: what every analytic gradient here is held
    /// against.
    fn central_difference<T: Clone>(
        x: &T,
        h: f32,
        nudge: impl Fn(&mut T, f32),
        loss: impl Fn(&T) -> f64,
    ) -> f64 {
        let (mut p, mut m) = (x.clone(), x.clone());
        nudge(&mut p, h);
        nudge(&mut m, -h);
        (loss(&p) - loss(&m)) / (2.0 * h as f64)
    }

    #[test]
    fn dense_backward_matches_finite_differences() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let (cin, cout, n) = (4, 3, 5);
        let wt = rand_mat(&mut rng, cin, cout);
        let b: Vec<f32> = (0..cout).map(|_| rng.random_range(-1.0..1.0)).collect();
        let x = rand_mat(&mut rng, cin, n);
        let r = rand_mat(&mut rng, cout, n);
        let loss = |wt: &Mat<f32>, b: &[f32], x: &Mat<f32>| {
            let mut z = Mat::zeros(cout, n);
            dense_forward(wt.as_ref(), b, x.as_ref(), z.as_mut());
            dot(r.as_ref(), z.as_ref())
        };
        let mut gwt = Mat::zeros(cin, cout);
        let mut gb = vec![0.0; cout];
        let mut dx = Mat::zeros(cin, n);
        dense_backward(
            wt.as_ref(),
            x.as_ref(),
            r.as_ref(),
            gwt.as_mut(),
            &mut gb,
            Some(dx.as_mut()),
        );
        for i in 0..cin {
            for o in 0..cout {
                let fd = central_difference(&wt, H, |v, d| v[(i, o)] += d, |v| loss(v, &b, &x));
                assert_close(gwt[(i, o)], fd, "dense dW");
            }
        }
        for o in 0..cout {
            let fd = central_difference(&b, H, |v, d| v[o] += d, |v| loss(&wt, v, &x));
            assert_close(gb[o], fd, "dense db");
        }
        for i in 0..cin {
            for j in 0..n {
                let fd = central_difference(&x, H, |v, d| v[(i, j)] += d, |v| loss(&wt, &b, v));
                assert_close(dx[(i, j)], fd, "dense dx");
            }
        }
    }

    #[test]
    fn batchnorm_backward_matches_finite_differences() {
        let mut rng = ChaCha8Rng::seed_from_u64(8);
        let (c, n) = (3, 6);
        let z = rand_mat(&mut rng, c, n);
        let gamma: Vec<f32> = (0..c).map(|_| rng.random_range(0.5..1.5)).collect();
        let beta: Vec<f32> = (0..c).map(|_| rng.random_range(-1.0..1.0)).collect();
        let r = rand_mat(&mut rng, c, n);
        let fwd = |z: &Mat<f32>, gamma: &[f32], beta: &[f32]| {
            let mut xhat = Mat::zeros(c, n);
            let mut y = Mat::zeros(c, n);
            let (mut m, mut v, mut s) = (vec![0.0; c], vec![0.0; c], vec![0.0; c]);
            bn_forward_train(
                z.as_ref(),
                gamma,
                beta,
                xhat.as_mut(),
                y.as_mut(),
                &mut m,
                &mut v,
                &mut s,
            );
            (dot(r.as_ref(), y.as_ref()), xhat, s)
        };
        let (_, xhat, inv_std) = fwd(&z, &gamma, &beta);
        let mut dz = Mat::zeros(c, n);
        let (mut dg, mut db) = (vec![0.0; c], vec![0.0; c]);
        bn_backward_train(
            r.as_ref(),
            xhat.as_ref(),
            &gamma,
            &inv_std,
            dz.as_mut(),
            &mut dg,
            &mut db,
        );
        let h = 1e-3f32;
        for i in 0..c {
            for j in 0..n {
                let fd =
                    central_difference(&z, h, |v, d| v[(i, j)] += d, |v| fwd(v, &gamma, &beta).0);
                assert_close(dz[(i, j)], fd, "bn dz");
            }
            let fd = central_difference(&gamma, h, |v, d| v[i] += d, |v| fwd(&z, v, &beta).0);
            assert_close(dg[i], fd, "bn dgamma");
            let fd = central_difference(&beta, h, |v, d| v[i] += d, |v| fwd(&z, &gamma, v).0);
            assert_close(db[i], fd, "bn dbeta");
        }
    }

    #[test]
    fn gelu_and_dropout_backward_match_finite_differences() {
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let (c, n) = (3, 4);
        let a = rand_mat(&mut rng, c, n);
        let mut mask = Mat::zeros(c, n);
        for j in 0..n {
            for i in 0..c {
                mask[(i, j)] = if rng.random::<f32>() < 0.3 {
                    0.0
                } else {
                    1.0 / 0.7
                };
            }
        }
        let r = rand_mat(&mut rng, c, n);
        let f = |a: &Mat<f32>| {
            let mut y = a.clone();
            let mut g = Mat::zeros(c, n);
            gelu_forward(y.as_mut(), g.as_mut());
            apply_mask(y.as_mut(), mask.as_ref());
            (dot(r.as_ref(), y.as_ref()), g)
        };
        let (_, g) = f(&a);
        for i in 0..c {
            for j in 0..n {
                let analytic = r[(i, j)] * mask[(i, j)] * g[(i, j)];
                let h = 1e-3f32;
                let fd = central_difference(&a, h, |v, d| v[(i, j)] += d, |v| f(v).0);
                assert_close(analytic, fd, "gelu+dropout");
            }
        }
    }

    /// Whole-network check: every parameter's gradient (through all layers, batch norm in
    /// training mode, dropout with a fixed mask and the residual head's heading loss, plus
    /// a random linear term so the σ output is exercised too).
    #[test]
    fn whole_network_gradient_matches_finite_differences() {
        let arch = Arch::tiny(4);
        let head = Head::Residual {
            range_deg: [0.0, 360.0],
        };
        let mut rng = ChaCha8Rng::seed_from_u64(10);
        let params0 = ParamSet::init(&arch, |b| rng.random_range(-b..b));
        let n = 6;
        let mut graph = Graph::new(&arch, n);
        let vn: Vec<f32> = (0..n).map(|_| rng.random_range(-2.0..2.0)).collect();
        let ve: Vec<f32> = (0..n).map(|_| rng.random_range(-2.0..2.0)).collect();
        // Truth 60° away from atan2 keeps the wrapped error away from its kinks.
        let truth: Vec<f32> = (0..n)
            .map(|i| ghnet_inference::head::heading_deg(vn[i], ve[i]) + 60.0)
            .collect();
        let mut drop_rng = ChaCha8Rng::seed_from_u64(11);
        graph.sample_dropout(0.2, &mut drop_rng);
        let r = rand_mat(&mut rng, 4, n);
        let run = |p: &mut ParamSet, graph: &mut Graph, want_grad: bool| {
            {
                let mut x = graph.input_mut();
                for j in 0..n {
                    x[(0, j)] = vn[j];
                    x[(1, j)] = ve[j];
                }
            }
            graph.forward(p, Mode::Train);
            let out = graph.output().to_owned();
            let mut dout = Mat::zeros(4, n);
            let mut total = 0.0f64;
            let mut dy = [0.0f32; 4];
            for j in 0..n {
                let y = [out[(0, j)], out[(1, j)], out[(2, j)], out[(3, j)]];
                total += crate::loss::head_loss(&head, &y, vn[j], ve[j], truth[j], 0.0, &mut dy).0
                    as f64;
                for k in 0..4 {
                    total += (r[(k, j)] * y[k]) as f64;
                    dout[(k, j)] = dy[k] + r[(k, j)];
                }
            }
            let mut grads = vec![0.0; p.data().len()];
            if want_grad {
                graph.backward(p, dout.as_ref(), &mut grads);
            }
            (total, grads)
        };
        let mut p = params0.clone();
        let (_, grads) = run(&mut p, &mut graph, true);
        let h = 2e-3f32;
        let mut checked = 0;
        for (ti, spec) in params0.specs().iter().enumerate() {
            if spec.role == Role::Buffer {
                continue;
            }
            for k in params0.range(ti).step_by(3) {
                let mut pp = params0.clone();
                pp.data_mut()[k] += h;
                let lp = run(&mut pp, &mut graph, false).0;
                let mut pm = params0.clone();
                pm.data_mut()[k] -= h;
                let lm = run(&mut pm, &mut graph, false).0;
                let fd = (lp - lm) / (2.0 * h as f64);
                assert!(
                    (grads[k] as f64 - fd).abs() <= 1e-2 * (1.0 + fd.abs()),
                    "{}[{}]: analytic {} fd {}",
                    spec.name,
                    k - params0.range(ti).start,
                    grads[k],
                    fd
                );
                checked += 1;
            }
        }
        assert!(checked > 50);
    }

    #[test]
    fn folded_network_matches_unfolded_eval_graph() {
        let arch = Arch::paper(3);
        let mut rng = ChaCha8Rng::seed_from_u64(12);
        let mut params = ParamSet::init(&arch, |b| rng.random_range(-b..b));
        // Non-trivial batch-norm statistics and affine parameters.
        for l in 1..=arch.conv.len() {
            for v in params.get_mut(&format!("bn{l}.running_mean")) {
                *v = rng.random_range(-0.5..0.5);
            }
            for v in params.get_mut(&format!("bn{l}.running_var")) {
                *v = rng.random_range(0.2..2.0);
            }
            for v in params.get_mut(&format!("bn{l}.weight")) {
                *v = rng.random_range(0.5..1.5);
            }
            for v in params.get_mut(&format!("bn{l}.bias")) {
                *v = rng.random_range(-0.3..0.3);
            }
        }
        let n = 64;
        let mut graph = Graph::new(&arch, n);
        let x = rand_mat(&mut rng, 2, n);
        graph.input_mut().copy_from(x.as_ref());
        graph.forward(&mut params, Mode::Eval);
        let unfolded = graph.output().to_owned();
        let net = Network::fold(&params);
        let mut scratch = net.scratch(16); // force chunking
        let mut out = Mat::zeros(3, n);
        net.forward(x.as_ref(), out.as_mut(), &mut scratch);
        let mut one = [0.0f32; 3];
        let mut worst = 0.0f32;
        for j in 0..n {
            net.forward_one(&[x[(0, j)], x[(1, j)]], &mut one, &mut scratch);
            for k in 0..3 {
                worst = worst.max((out[(k, j)] - unfolded[(k, j)]).abs());
                worst = worst.max((one[k] - unfolded[(k, j)]).abs());
            }
        }
        assert!(
            worst < 1e-5,
            "folded vs unfolded max abs difference {worst}"
        );
    }

    #[test]
    fn training_is_deterministic_and_learns() {
        let mut rng = ChaCha8Rng::seed_from_u64(13);
        let mut data = Dataset::default();
        for _ in 0..600 {
            let h: f32 = rng.random_range(0.0..90.0);
            let s: f32 = rng.random_range(0.5..3.0);
            data.push(
                s * h.to_radians().cos(),
                s * h.to_radians().sin(),
                h,
                f32::NAN,
            );
        }
        let (tr, va) = (
            Dataset {
                v_north: data.v_north[..500].to_vec(),
                v_east: data.v_east[..500].to_vec(),
                heading_deg: data.heading_deg[..500].to_vec(),
                speed_acc: data.speed_acc[..500].to_vec(),
            },
            Dataset {
                v_north: data.v_north[500..].to_vec(),
                v_east: data.v_east[500..].to_vec(),
                heading_deg: data.heading_deg[500..].to_vec(),
                speed_acc: data.speed_acc[500..].to_vec(),
            },
        );
        let head = Head::Angle {
            centre_deg: 45.0,
            half_range_deg: 45.0,
        };
        let cfg = TrainConfig {
            epochs: 30,
            batch: 50,
            lr: 5e-3,
            ..Default::default()
        };
        let mut first = None;
        let a = train(&Arch::tiny(2), &head, 3.0, &tr, &va, &cfg, |r| {
            first.get_or_insert(r.val_mae_deg);
        });
        let b = train(&Arch::tiny(2), &head, 3.0, &tr, &va, &cfg, |_| {});
        assert_eq!(
            a.params.data(),
            b.params.data(),
            "same seed must give same weights"
        );
        assert!(
            a.best_val_mae_deg < 0.5 * first.unwrap(),
            "validation MAE should halve: first {} best {}",
            first.unwrap(),
            a.best_val_mae_deg
        );
        let c = train(
            &Arch::tiny(2),
            &head,
            3.0,
            &tr,
            &va,
            &TrainConfig { seed: 2, ..cfg },
            |_| {},
        );
        assert_ne!(a.params.data(), c.params.data());
    }
}
