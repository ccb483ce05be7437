//! Layer kernels of training: forward and backward of dense, batch-norm, GELU and
//! dropout layers, the convolution stack and the whole per-epoch network graph.
//!
//! Activations are `channels × batch`, column-major. A weight `[out, in]` is held as its
//! column-major transpose `wt` (`in × out`), as the flat ParamSet stores it. Each
//! backward pass is a free function so the unit tests can check it against finite
//! differences on its own.

use faer::linalg::matmul::matmul;
use faer::reborrow::{Reborrow, ReborrowMut};
use faer::{Accum, Mat, MatMut, MatRef, Par};
use rand::Rng;

use ghnet_inference::gelu::gelu_with_grad;
use ghnet_inference::params::{Arch, ParamSet, BN_EPS};

/// Batch-norm momentum for running statistics, PyTorch's default.
const BN_MOMENTUM: f32 = 0.1;

/// `z = W·x + b` with `wt = Wᵀ`.
pub fn dense_forward(wt: MatRef<'_, f32>, b: &[f32], x: MatRef<'_, f32>, mut z: MatMut<'_, f32>) {
    for j in 0..z.ncols() {
        for (i, bi) in b.iter().enumerate() {
            z[(i, j)] = *bi;
        }
    }
    matmul(z, Accum::Add, wt.transpose(), x, 1.0f32, Par::Seq);
}

/// Backward of [`dense_forward`]: writes `∂L/∂Wᵀ` into `gwt`, `∂L/∂b` into `gb`, and
/// `∂L/∂x` into `dx` when asked.
pub fn dense_backward(
    wt: MatRef<'_, f32>,
    x: MatRef<'_, f32>,
    dz: MatRef<'_, f32>,
    gwt: MatMut<'_, f32>,
    gb: &mut [f32],
    dx: Option<MatMut<'_, f32>>,
) {
    matmul(gwt, Accum::Replace, x, dz.transpose(), 1.0f32, Par::Seq);
    gb.fill(0.0);
    for j in 0..dz.ncols() {
        for (i, g) in gb.iter_mut().enumerate() {
            *g += dz[(i, j)];
        }
    }
    if let Some(dx) = dx {
        matmul(dx, Accum::Replace, wt, dz, 1.0f32, Par::Seq);
    }
}

/// Per channel (row of `shape`), the sum over the batch (columns) of `term(c, j)`,
/// into `out`: the reductions of batch norm's forward and backward passes. Sums in
/// column order, as the layers' other loops walk faer's column-major storage.
fn sum_over_batch(shape: MatRef<'_, f32>, out: &mut [f32], term: impl Fn(usize, usize) -> f32) {
    out.fill(0.0);
    for j in 0..shape.ncols() {
        for (c, o) in out.iter_mut().enumerate().take(shape.nrows()) {
            *o += term(c, j);
        }
    }
}

/// Batch norm in training mode: normalises each channel (row) over the batch, writes
/// `x̂` and `y = γ·x̂ + β`, returns per-channel mean and biased variance.
#[allow(clippy::too_many_arguments)] // the layer's inputs and outputs, as in the math
pub fn bn_forward_train(
    z: MatRef<'_, f32>,
    gamma: &[f32],
    beta: &[f32],
    mut xhat: MatMut<'_, f32>,
    mut y: MatMut<'_, f32>,
    mean: &mut [f32],
    var: &mut [f32],
    inv_std: &mut [f32],
) {
    let n = z.ncols() as f32;
    sum_over_batch(z.as_ref(), mean, |c, j| z[(c, j)]);
    for m in mean.iter_mut() {
        *m /= n;
    }
    sum_over_batch(z.as_ref(), var, |c, j| {
        let d = z[(c, j)] - mean[c];
        d * d
    });
    for c in 0..z.nrows() {
        var[c] /= n;
        inv_std[c] = 1.0 / (var[c] + BN_EPS).sqrt();
    }
    for j in 0..z.ncols() {
        for c in 0..z.nrows() {
            let xh = (z[(c, j)] - mean[c]) * inv_std[c];
            xhat[(c, j)] = xh;
            y[(c, j)] = gamma[c] * xh + beta[c];
        }
    }
}

/// Backward of [`bn_forward_train`]: `∂L/∂z`, `∂L/∂γ`, `∂L/∂β` from `∂L/∂y`.
pub fn bn_backward_train(
    dy: MatRef<'_, f32>,
    xhat: MatRef<'_, f32>,
    gamma: &[f32],
    inv_std: &[f32],
    mut dz: MatMut<'_, f32>,
    dgamma: &mut [f32],
    dbeta: &mut [f32],
) {
    let n = dy.ncols() as f32;
    sum_over_batch(dy, dgamma, |c, j| dy[(c, j)] * xhat[(c, j)]);
    sum_over_batch(dy, dbeta, |c, j| dy[(c, j)]);
    // dxhat = dy·γ; Σdxhat = γ·dβ; Σ(dxhat·x̂) = γ·dγ.
    for j in 0..dy.ncols() {
        for c in 0..dy.nrows() {
            let dxh = dy[(c, j)] * gamma[c];
            dz[(c, j)] = inv_std[c] / n
                * (n * dxh - gamma[c] * dbeta[c] - xhat[(c, j)] * gamma[c] * dgamma[c]);
        }
    }
}

/// GELU in place, storing its derivative for the backward pass.
pub fn gelu_forward(mut a: MatMut<'_, f32>, mut grad: MatMut<'_, f32>) {
    for j in 0..a.ncols() {
        for c in 0..a.nrows() {
            let (y, g) = gelu_with_grad(a[(c, j)]);
            a[(c, j)] = y;
            grad[(c, j)] = g;
        }
    }
}

/// Dropout forward with a precomputed mask (0 or `1/(1−p)`): `y = x·mask`, in place.
/// Its backward is the same multiplication, applied to the gradient.
pub fn apply_mask(mut x: MatMut<'_, f32>, mask: MatRef<'_, f32>) {
    for j in 0..x.ncols() {
        for c in 0..x.nrows() {
            x[(c, j)] *= mask[(c, j)];
        }
    }
}

// ---------------------------------------------------------------------------------------

/// Per-layer buffers of one mini-batch.
struct ConvCache {
    z: Mat<f32>,
    xhat: Mat<f32>,
    a: Mat<f32>,
    dgelu: Mat<f32>,
    mean: Vec<f32>,
    var: Vec<f32>,
    inv_std: Vec<f32>,
}

/// How [`Graph::forward`] treats batch norm and dropout.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    /// Batch statistics, running-statistics update, dropout active.
    Train,
    /// Running statistics, no dropout: the same function the folded network computes.
    Eval,
}

/// Forward/backward workspace of the kernel-1 convolution stack (each followed by batch
/// norm and GELU, dropout after the last): the per-epoch part of every GHNet network,
/// shared by the per-epoch [`Graph`] and the temporal trainer.
pub struct ConvStack {
    arch: Arch,
    batch: usize,
    x: Mat<f32>,
    conv: Vec<ConvCache>,
    mask: Mat<f32>,
    da: Vec<Mat<f32>>,
    dz: Mat<f32>,
}

impl ConvStack {
    /// Buffers for mini-batches of exactly `batch` columns.
    pub fn new(arch: &Arch, batch: usize) -> Self {
        let conv = arch
            .conv
            .iter()
            .map(|&c| ConvCache {
                z: Mat::zeros(c, batch),
                xhat: Mat::zeros(c, batch),
                a: Mat::zeros(c, batch),
                dgelu: Mat::zeros(c, batch),
                mean: vec![0.0; c],
                var: vec![0.0; c],
                inv_std: vec![0.0; c],
            })
            .collect();
        let last = *arch.conv.last().expect("conv layers");
        Self {
            arch: arch.clone(),
            batch,
            x: Mat::zeros(arch.input, batch),
            conv,
            mask: Mat::from_fn(last, batch, |_, _| 1.0),
            da: arch.conv.iter().map(|&c| Mat::zeros(c, batch)).collect(),
            dz: Mat::zeros(arch.conv.iter().copied().max().unwrap_or(1), batch),
        }
    }

    /// The input buffer (`input × batch`).
    pub fn input_mut(&mut self) -> MatMut<'_, f32> {
        self.x.as_mut()
    }

    /// The last layer's output after dropout (`channels × batch`).
    pub fn features(&self) -> MatRef<'_, f32> {
        self.conv.last().expect("conv layers").a.as_ref()
    }

    /// Where the caller puts `∂L/∂features` before [`ConvStack::backward`].
    pub fn d_features_mut(&mut self) -> MatMut<'_, f32> {
        self.da.last_mut().expect("conv layers").as_mut()
    }

    /// Set the dropout mask for the next forward pass (`p = 0` disables it).
    pub fn sample_dropout(&mut self, p: f32, rng: &mut impl Rng) {
        let keep = 1.0 / (1.0 - p);
        for j in 0..self.mask.ncols() {
            for c in 0..self.mask.nrows() {
                self.mask[(c, j)] = if p > 0.0 && rng.random::<f32>() < p {
                    0.0
                } else if p > 0.0 {
                    keep
                } else {
                    1.0
                };
            }
        }
    }

    /// Forward pass. In [`Mode::Train`] the running statistics in `params` are updated.
    pub fn forward(&mut self, params: &mut ParamSet, mode: Mode) {
        let n_conv = self.arch.conv.len();
        for l in 0..n_conv {
            let name = l + 1;
            let (done, todo) = self.conv.split_at_mut(l);
            let cache = &mut todo[0];
            let input = if l == 0 {
                self.x.as_ref()
            } else {
                done[l - 1].a.as_ref()
            };
            dense_forward(
                params.matrix_t(&format!("conv{name}.weight")),
                params.get(&format!("conv{name}.bias")),
                input,
                cache.z.as_mut(),
            );
            match mode {
                Mode::Train => bn_train_step(params, name, cache, self.batch),
                Mode::Eval => bn_eval_step(params, name, cache, self.batch),
            }
            gelu_forward(cache.a.as_mut(), cache.dgelu.as_mut());
        }
        if mode == Mode::Train {
            apply_mask(self.conv[n_conv - 1].a.as_mut(), self.mask.as_ref());
        }
    }

    /// Backward pass of a [`Mode::Train`] forward from `∂L/∂features` (set through
    /// [`ConvStack::d_features_mut`]); gradients accumulate into `grads`.
    pub fn backward(&mut self, params: &ParamSet, grads: &mut [f32]) {
        let n_conv = self.arch.conv.len();
        apply_mask(self.da[n_conv - 1].as_mut(), self.mask.as_ref());
        for l in (0..n_conv).rev() {
            let name = l + 1;
            let c = self.arch.conv[l];
            let cache = &self.conv[l];
            let mut dy = self.da[l].as_mut();
            for j in 0..self.batch {
                for ch in 0..c {
                    dy[(ch, j)] *= cache.dgelu[(ch, j)];
                }
            }
            let gi = params.index_of(&format!("bn{name}.weight")).expect("bn");
            let bi = params.index_of(&format!("bn{name}.bias")).expect("bn");
            let (gr, br) = (params.range(gi), params.range(bi));
            let gamma = params.get(&format!("bn{name}.weight"));
            let mut dz = self.dz.as_mut().submatrix_mut(0, 0, c, self.batch);
            {
                let (dg, db) = split_two(grads, gr, br);
                bn_backward_train(
                    self.da[l].as_ref(),
                    cache.xhat.as_ref(),
                    gamma,
                    &cache.inv_std,
                    dz.rb_mut(),
                    dg,
                    db,
                );
            }
            let wname = format!("conv{name}.weight");
            let wi = params.index_of(&wname).expect("w");
            let bi = params.index_of(&format!("conv{name}.bias")).expect("b");
            let (wr, br) = (params.range(wi), params.range(bi));
            let cin = params.specs()[wi].shape[1];
            let (gw, gb) = split_two(grads, wr, br);
            let (da_prev, _) = self.da.split_at_mut(l);
            let input = if l == 0 {
                self.x.as_ref()
            } else {
                self.conv[l - 1].a.as_ref()
            };
            let dx = (l > 0).then(|| da_prev[l - 1].as_mut());
            dense_backward(
                params.matrix_t(&wname),
                input,
                dz.rb(),
                MatMut::from_column_major_slice_mut(gw, cin, c),
                gb,
                dx,
            );
        }
    }
}

/// Batch norm of layer `name` in training mode, with the running-statistics update.
fn bn_train_step(params: &mut ParamSet, name: usize, cache: &mut ConvCache, batch: usize) {
    let gamma = params.get(&format!("bn{name}.weight")).to_vec();
    let beta = params.get(&format!("bn{name}.bias")).to_vec();
    bn_forward_train(
        cache.z.as_ref(),
        &gamma,
        &beta,
        cache.xhat.as_mut(),
        cache.a.as_mut(),
        &mut cache.mean,
        &mut cache.var,
        &mut cache.inv_std,
    );
    let n = batch as f32;
    let unbias = if n > 1.0 { n / (n - 1.0) } else { 1.0 };
    let rm = params.get_mut(&format!("bn{name}.running_mean"));
    for (r, m) in rm.iter_mut().zip(&cache.mean) {
        *r = (1.0 - BN_MOMENTUM) * *r + BN_MOMENTUM * m;
    }
    let rv = params.get_mut(&format!("bn{name}.running_var"));
    for (r, v) in rv.iter_mut().zip(&cache.var) {
        *r = (1.0 - BN_MOMENTUM) * *r + BN_MOMENTUM * v * unbias;
    }
}

/// Batch norm of layer `name` with the running statistics (what folding computes).
fn bn_eval_step(params: &ParamSet, name: usize, cache: &mut ConvCache, batch: usize) {
    let gamma = params.get(&format!("bn{name}.weight"));
    let beta = params.get(&format!("bn{name}.bias"));
    let rm = params.get(&format!("bn{name}.running_mean"));
    let rv = params.get(&format!("bn{name}.running_var"));
    for c in 0..rm.len() {
        cache.mean[c] = rm[c];
        cache.var[c] = rv[c];
        cache.inv_std[c] = 1.0 / (rv[c] + BN_EPS).sqrt();
    }
    for j in 0..batch {
        for c in 0..rm.len() {
            let xh = (cache.z[(c, j)] - cache.mean[c]) * cache.inv_std[c];
            cache.xhat[(c, j)] = xh;
            cache.a[(c, j)] = gamma[c] * xh + beta[c];
        }
    }
}

/// `z = W·x + b` for `fc{l}` over the first `n` columns of `input` into `out`.
pub fn fc_forward(params: &ParamSet, l: usize, input: MatRef<'_, f32>, out: MatMut<'_, f32>) {
    dense_forward(
        params.matrix_t(&format!("fc{l}.weight")),
        params.get(&format!("fc{l}.bias")),
        input,
        out,
    );
}

/// Backward of [`fc_forward`]: gradients of `fc{l}` into `grads`, `∂L/∂input` into `dx`.
pub fn fc_backward(
    params: &ParamSet,
    l: usize,
    input: MatRef<'_, f32>,
    dout: MatRef<'_, f32>,
    grads: &mut [f32],
    dx: MatMut<'_, f32>,
) {
    let wname = format!("fc{l}.weight");
    let wi = params.index_of(&wname).expect("weight");
    let bi = params.index_of(&format!("fc{l}.bias")).expect("bias");
    let (wr, br) = (params.range(wi), params.range(bi));
    let shape = &params.specs()[wi].shape;
    let (fout, fin) = (shape[0], shape[1]);
    let (gw, gb) = split_two(grads, wr, br);
    dense_backward(
        params.matrix_t(&wname),
        input,
        dout,
        MatMut::from_column_major_slice_mut(gw, fin, fout),
        gb,
        Some(dx),
    );
}

/// Forward/backward workspace for the unfolded per-epoch network (training graph).
pub struct Graph {
    stack: ConvStack,
    fc: Vec<Mat<f32>>,
    dfc: Vec<Mat<f32>>,
}

impl Graph {
    /// Buffers for mini-batches of exactly `batch` samples.
    pub fn new(arch: &Arch, batch: usize) -> Self {
        let fc: Vec<Mat<f32>> = arch
            .fc_dims()
            .iter()
            .map(|&(_, o)| Mat::zeros(o, batch))
            .collect();
        Self {
            stack: ConvStack::new(arch, batch),
            dfc: fc.iter().map(|m| Mat::zeros(m.nrows(), batch)).collect(),
            fc,
        }
    }

    /// The input buffer (`input × batch`), to be filled with scaled velocities.
    pub fn input_mut(&mut self) -> MatMut<'_, f32> {
        self.stack.input_mut()
    }

    /// The network outputs of the last forward pass (`outputs × batch`).
    pub fn output(&self) -> MatRef<'_, f32> {
        self.fc.last().expect("fc layers").as_ref()
    }

    /// Set the dropout mask for the next forward pass (`p = 0` disables it).
    pub fn sample_dropout(&mut self, p: f32, rng: &mut impl Rng) {
        self.stack.sample_dropout(p, rng)
    }

    /// Forward pass. In [`Mode::Train`] the running statistics in `params` are updated.
    pub fn forward(&mut self, params: &mut ParamSet, mode: Mode) {
        self.stack.forward(params, mode);
        for l in 0..self.fc.len() {
            let (done, todo) = self.fc.split_at_mut(l);
            let input = if l == 0 {
                self.stack.features()
            } else {
                done[l - 1].as_ref()
            };
            fc_forward(params, l + 1, input, todo[0].as_mut());
        }
    }

    /// Backward pass of a [`Mode::Train`] forward: `dout` is `∂L/∂outputs`; gradients for
    /// every tensor go into `grads` (same layout as `params.data()`, buffers left at zero).
    pub fn backward(&mut self, params: &ParamSet, dout: MatRef<'_, f32>, grads: &mut [f32]) {
        let n_fc = self.fc.len();
        self.dfc[n_fc - 1].as_mut().copy_from(dout);
        for l in (0..n_fc).rev() {
            let (dprev, dcur) = self.dfc.split_at_mut(l);
            let stack = &mut self.stack;
            let (input, dx) = if l == 0 {
                let last = stack.conv.len() - 1;
                (stack.conv[last].a.as_ref(), stack.da[last].as_mut())
            } else {
                (self.fc[l - 1].as_ref(), dprev[l - 1].as_mut())
            };
            fc_backward(params, l + 1, input, dcur[0].as_ref(), grads, dx);
        }
        self.stack.backward(params, grads);
    }
}

/// Two disjoint mutable ranges of one slice.
fn split_two(
    v: &mut [f32],
    a: std::ops::Range<usize>,
    b: std::ops::Range<usize>,
) -> (&mut [f32], &mut [f32]) {
    if a.start < b.start {
        let (lo, hi) = v.split_at_mut(b.start);
        (&mut lo[a], &mut hi[..b.len()])
    } else {
        let (lo, hi) = v.split_at_mut(a.start);
        let (x, y) = (&mut hi[..a.len()], &mut lo[b]);
        (x, y)
    }
}
