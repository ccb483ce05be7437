//! The inference network: batch norm folded into the convolutions, linear head collapsed.
//!
//! With kernel size 1 and input length 1, each Conv1D layer is a dense layer over channels:
//! `z = W·x + b`. In evaluation mode batch norm is the affine map
//! `γ·(z − μ)/√(σ² + ε) + β`, so it folds into the convolution exactly:
//! `W' = diag(γ/√(σ²+ε))·W`, `b' = γ·(b − μ)/√(σ²+ε) + β`. The paper puts no activation between
//! its fully connected layers (and dropout is the identity at inference), so `fc4∘fc3∘fc2∘fc1`
//! is one affine map `W = W4·W3·W2·W1` — exact, not an approximation.
//!
//! Every layer is one kernel pass over `channels × batch` column-major activations (one
//! column per sample): `Y = act(W·X + b)` with bias and GELU applied to the accumulators
//! in registers before the single store, so each activation is written once and read once
//! per layer. Rows (channels) are padded to a multiple of 16 with zero weights, so the
//! kernels never need a remainder loop over channels; the kernel is AVX-512, AVX2+FMA or
//! portable, chosen at run time ([`Kernel`]). The batch path tiles the output as
//! `(rows of up to 3 vectors) × (8 or 4 samples)` in registers; the single-sample path is a
//! matrix-vector product that splits the sum over inputs into independent chains so FMA
//! latency does not dominate. The caller owns the scratch; nothing is allocated per call.
//!
//! The portable path is faer's matrix product ([`faer::linalg::matmul::matmul`]) with the
//! bias added first and the portable GELU after, one sample at a time: faer multiplies
//! one column with its matrix-vector kernel and several with its matrix-matrix kernels,
//! which sum in other orders, and a sample's answer must not depend on its batch. The
//! hand-written kernels are tested against it.

use faer::{Accum, Mat, MatMut, MatRef, Par};

use crate::gelu::{gelu_inplace_with, gelu_v};
use crate::params::{Arch, ParamSet, BN_EPS};
use crate::simd::{padded, AlignedBuf, Kernel, Simd};
#[cfg(target_arch = "x86_64")]
use crate::simd::{V16, V8};

/// One dense layer `y = W·x + b`, `W` stored column-major with `padded(rows)` rows.
#[derive(Debug, Clone)]
struct Dense {
    /// Real output channels.
    rows: usize,
    /// Input length as stored: the previous layer's padded rows (or the network input).
    k: usize,
    /// `padded(rows) × k`, column-major, zero in padded rows and in columns past the real
    /// inputs.
    w: AlignedBuf,
    /// `padded(rows)`, zero in padded rows.
    b: AlignedBuf,
}

impl Dense {
    /// From an `out × in` weight matrix and bias, stored for an input of length `k ≥ in`.
    fn new(w: MatRef<'_, f32>, b: &[f32], k: usize) -> Self {
        let (rows, inputs) = (w.nrows(), w.ncols());
        debug_assert!(k >= inputs && b.len() == rows);
        let rp = padded(rows);
        let mut wp = AlignedBuf::zeros(rp * k);
        let ws = wp.as_mut_slice();
        for j in 0..inputs {
            for i in 0..rows {
                ws[j * rp + i] = w[(i, j)];
            }
        }
        let mut bp = AlignedBuf::zeros(rp);
        bp.as_mut_slice()[..rows].copy_from_slice(b);
        Self {
            rows,
            k,
            w: wp,
            b: bp,
        }
    }

    fn rows_padded(&self) -> usize {
        padded(self.rows)
    }
}

/// The folded GHNet network, ready for inference.
#[derive(Debug, Clone)]
pub struct Network {
    arch: Arch,
    kernel: Kernel,
    /// The conv layers (GELU after each) and then the collapsed head (no activation).
    layers: Vec<Dense>,
}

/// Caller-owned buffers for [`Network::forward`] and [`Network::forward_one`].
///
/// Sized once for a maximum batch; a larger batch is processed in chunks of that size.
/// Made by [`Network::scratch`] for one network shape; using it with a network of another
/// shape panics.
#[derive(Debug)]
pub struct Scratch {
    max_batch: usize,
    /// The scaled inputs, `input × max_batch`.
    input: AlignedBuf,
    /// Each layer's output, `padded(rows) × max_batch`; the last one is the head's.
    acts: Vec<AlignedBuf>,
    /// `padded(rows)` of each layer, to check the scratch fits the network.
    shape: Vec<usize>,
}

impl Scratch {
    /// The largest batch processed in one pass.
    pub fn max_batch(&self) -> usize {
        self.max_batch
    }
}

impl Network {
    /// Fold batch norm into the convolutions and collapse the linear head.
    ///
    /// For a temporal architecture (`window > 1`) the result is the per-epoch feature
    /// extractor only (the convolutions; its outputs are the last conv layer's
    /// channels): the head over the window is [`collapse_fc`], applied by the streaming
    /// predictor to the cached features of the last `window` epochs.
    pub fn fold(params: &ParamSet) -> Self {
        let arch = params.arch().clone();
        let mut layers = Vec::with_capacity(arch.conv.len() + 1);
        let mut k = arch.input;
        for l in 1..=arch.conv.len() {
            let wt = params.matrix_t(&format!("conv{l}.weight")); // in × out
            let b = params.get(&format!("conv{l}.bias"));
            let gamma = params.get(&format!("bn{l}.weight"));
            let beta = params.get(&format!("bn{l}.bias"));
            let mean = params.get(&format!("bn{l}.running_mean"));
            let var = params.get(&format!("bn{l}.running_var"));
            let out = wt.ncols();
            let scale: Vec<f32> = (0..out)
                .map(|o| gamma[o] / (var[o] + BN_EPS).sqrt())
                .collect();
            let w = Mat::from_fn(out, wt.nrows(), |o, i| wt[(i, o)] * scale[o]);
            let b: Vec<f32> = (0..out)
                .map(|o| scale[o] * (b[o] - mean[o]) + beta[o])
                .collect();
            let d = Dense::new(w.as_ref(), &b, k);
            k = d.rows_padded();
            layers.push(d);
        }
        if arch.window <= 1 {
            let (head_w, head_b) = collapse_fc(params);
            layers.push(Dense::new(head_w.as_ref(), &head_b, k));
        }
        Self {
            arch,
            kernel: Kernel::detect(),
            layers,
        }
    }

    /// The same network running on `kernel` (if this CPU has it; otherwise unchanged).
    /// The widest available kernel is the default; this is for benches and for tests that
    /// hold the kernels against each other.
    pub fn with_kernel(mut self, kernel: Kernel) -> Self {
        if kernel.is_available() {
            self.kernel = kernel;
        }
        self
    }

    /// The kernel the forward passes run on.
    pub fn kernel(&self) -> Kernel {
        self.kernel
    }

    /// The architecture.
    pub fn arch(&self) -> &Arch {
        &self.arch
    }

    /// Number of outputs per sample.
    pub fn outputs(&self) -> usize {
        self.layers.last().expect("head layer").rows
    }

    /// Multiply-adds per sample of the folded network as specified (unpadded):
    /// `Σ inputs·outputs` over the conv layers and the collapsed head. GFLOP/s figures
    /// count 2 FLOPs per multiply-add and leave out bias, GELU and padding.
    pub fn macs_per_sample(&self) -> usize {
        let mut inputs = self.arch.input;
        let mut macs = 0;
        for d in &self.layers {
            macs += inputs * d.rows;
            inputs = d.rows;
        }
        macs
    }

    /// GELU evaluations per sample (the conv channels).
    pub fn gelus_per_sample(&self) -> usize {
        self.arch.conv.iter().sum()
    }

    /// Buffers for batches of up to `max_batch` samples (at least one).
    pub fn scratch(&self, max_batch: usize) -> Scratch {
        let max_batch = max_batch.max(1);
        Scratch {
            max_batch,
            input: AlignedBuf::zeros(self.arch.input * max_batch),
            acts: self
                .layers
                .iter()
                .map(|d| AlignedBuf::zeros(d.rows_padded() * max_batch))
                .collect(),
            shape: self.layers.iter().map(Dense::rows_padded).collect(),
        }
    }

    fn check_scratch(&self, scratch: &Scratch) {
        assert!(
            scratch.input.as_slice().len() == self.arch.input * scratch.max_batch
                && scratch.shape.len() == self.layers.len()
                && scratch
                    .shape
                    .iter()
                    .zip(&self.layers)
                    .all(|(&s, d)| s == d.rows_padded()),
            "scratch was made for a network of another shape"
        );
    }

    /// Forward one sample: `x` is the scaled input (length `arch.input`), `out` receives
    /// the outputs.
    pub fn forward_one(&self, x: &[f32], out: &mut [f32], scratch: &mut Scratch) {
        self.check_scratch(scratch);
        assert_eq!(x.len(), self.arch.input, "input length");
        assert_eq!(out.len(), self.outputs(), "output length");
        scratch.input.as_mut_slice()[..x.len()].copy_from_slice(x);
        self.run(1, scratch);
        let y = scratch.acts.last().expect("head layer").as_slice();
        out.copy_from_slice(&y[..out.len()]);
    }

    /// Forward a batch: `x` is `2 × n` (scaled inputs, one column per sample), `out` is
    /// `outputs × n`. Any `n` is accepted; it is processed in chunks of the scratch size.
    pub fn forward(&self, x: MatRef<'_, f32>, mut out: MatMut<'_, f32>, scratch: &mut Scratch) {
        self.check_scratch(scratch);
        let n = x.ncols();
        assert_eq!(x.nrows(), self.arch.input, "input rows");
        assert_eq!(out.nrows(), self.outputs(), "output rows");
        assert_eq!(out.ncols(), n, "output columns must match input columns");
        let inputs = self.arch.input;
        let rp = self.layers.last().expect("head layer").rows_padded();
        let mut start = 0;
        while start < n {
            let len = (n - start).min(scratch.max_batch);
            let xin = scratch.input.as_mut_slice();
            for j in 0..len {
                for i in 0..inputs {
                    xin[j * inputs + i] = x[(i, start + j)];
                }
            }
            self.run(len, scratch);
            let y = scratch.acts.last().expect("head layer").as_slice();
            for j in 0..len {
                for i in 0..out.nrows() {
                    out[(i, start + j)] = y[j * rp + i];
                }
            }
            start += len;
        }
    }

    /// All layers over the first `n ≤ max_batch` columns of `scratch.input`.
    fn run(&self, n: usize, scratch: &mut Scratch) {
        debug_assert!(n >= 1 && n <= scratch.max_batch);
        match self.kernel {
            // SAFETY: `self.kernel` is only ever an available kernel (`fold` detects it,
            // `with_kernel` checks it), and the scratch was checked against this network.
            #[cfg(target_arch = "x86_64")]
            Kernel::Avx512 => unsafe { run_avx512(self, n, scratch) },
            #[cfg(target_arch = "x86_64")]
            Kernel::Avx2Fma => unsafe { run_avx2(self, n, scratch) },
            _ => run_faer(self, n, scratch),
        }
    }

    /// Whether layer `l` has GELU after it: every convolution does; the collapsed linear
    /// head that ends a per-epoch network does not.
    fn has_gelu(&self, l: usize) -> bool {
        self.arch.window > 1 || l + 1 < self.layers.len()
    }
}

/// The fully connected layers collapsed into one affine map `(W, b)`, `W` of shape
/// `output × fc1 inputs`: exact, because the paper puts no activation between them and
/// dropout is the identity at inference. Composed in f64 so the collapse adds no error
/// worth measuring.
pub fn collapse_fc(params: &ParamSet) -> (Mat<f32>, Vec<f32>) {
    let n_fc = params.arch().fc.len() + 1;
    let mut w: Mat<f64> = {
        let t = params.matrix_t("fc1.weight");
        Mat::from_fn(t.ncols(), t.nrows(), |o, i| t[(i, o)] as f64)
    };
    let mut b: Vec<f64> = params.get("fc1.bias").iter().map(|&v| v as f64).collect();
    for l in 2..=n_fc {
        let t = params.matrix_t(&format!("fc{l}.weight"));
        let wl = Mat::from_fn(t.ncols(), t.nrows(), |o, i| t[(i, o)] as f64);
        let bl = params.get(&format!("fc{l}.bias"));
        let new_w = &wl * &w;
        let new_b = (0..wl.nrows())
            .map(|o| bl[o] as f64 + (0..wl.ncols()).map(|i| wl[(o, i)] * b[i]).sum::<f64>())
            .collect();
        w = new_w;
        b = new_b;
    }
    (
        Mat::from_fn(w.nrows(), w.ncols(), |i, j| w[(i, j)] as f32),
        b.into_iter().map(|v| v as f32).collect(),
    )
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
unsafe fn run_avx512(net: &Network, n: usize, scratch: &mut Scratch) {
    // 3 row vectors × 8 samples = 24 accumulators of 32 registers.
    run_v::<V16, 8>(net, n, scratch)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn run_avx2(net: &Network, n: usize, scratch: &mut Scratch) {
    // 3 row vectors × 4 samples = 12 accumulators of 16 registers.
    run_v::<V8, 4>(net, n, scratch)
}

/// Every layer, each reading the previous one's output in `scratch`.
///
/// # Safety
/// `V`'s kernel is available; `scratch` was made by `net.scratch` (checked shapes) and
/// `1 ≤ n ≤ scratch.max_batch`.
#[inline(always)]
unsafe fn run_v<V: Simd, const NR: usize>(net: &Network, n: usize, scratch: &mut Scratch) {
    let mut x = scratch.input.as_slice().as_ptr();
    let mut xs = net.arch.input;
    for (l, d) in net.layers.iter().enumerate() {
        let y = scratch.acts[l].as_mut_slice().as_mut_ptr();
        if net.has_gelu(l) {
            dense::<V, NR, true>(d, x, xs, n, y);
        } else {
            dense::<V, NR, false>(d, x, xs, n, y);
        }
        x = y;
        xs = d.rows_padded();
    }
}

/// Every layer on faer's product, each reading the previous one's output in `scratch`
/// (the first `n ≤ max_batch` columns).
fn run_faer(net: &Network, n: usize, scratch: &mut Scratch) {
    for (l, d) in net.layers.iter().enumerate() {
        let (done, rest) = scratch.acts.split_at_mut(l);
        let x = done.last().unwrap_or(&scratch.input).as_slice();
        dense_faer(d, x, n, rest[0].as_mut_slice(), net.has_gelu(l));
    }
}

/// `Y[:, j] = act(W·X[:, j] + b)` for `j < n` on faer's product, one column at a time
/// (see the module docs), `act` GELU (the portable kernel, bit for bit the scalar
/// [`crate::gelu::gelu`]) or the identity. `X` is `d.k × n` and `Y` `padded(d.rows) × n`,
/// both column-major without gaps.
fn dense_faer(d: &Dense, x: &[f32], n: usize, y: &mut [f32], gelu: bool) {
    let rows = d.rows_padded();
    let w = MatRef::from_column_major_slice(d.w.as_slice(), rows, d.k);
    for (xj, yj) in x.chunks_exact(d.k).zip(y.chunks_exact_mut(rows)).take(n) {
        yj.copy_from_slice(d.b.as_slice());
        faer::linalg::matmul::matmul(
            MatMut::from_column_major_slice_mut(yj, rows, 1),
            Accum::Add,
            w,
            MatRef::from_column_major_slice(xj, d.k, 1),
            1.0,
            Par::Seq,
        );
        if gelu {
            gelu_inplace_with(Kernel::Portable, yj);
        }
    }
}

/// `Y[:, j] = act(W·X[:, j] + b)` for `j < n`, with `act` GELU or the identity.
/// `X` has column stride `xs` and `d.k` rows; `Y` has column stride `padded(d.rows)`.
///
/// # Safety
/// As [`run_v`]; `x` valid for `n` columns, `y` for `n` columns, not overlapping.
#[inline(always)]
unsafe fn dense<V: Simd, const NR: usize, const GELU: bool>(
    d: &Dense,
    x: *const f32,
    xs: usize,
    n: usize,
    y: *mut f32,
) {
    let rv = d.rows_padded() / V::LANES;
    if n == 1 {
        // One sample: as many row vectors at once as divide the layer (up to 6
        // independent FMA chains), each output summed in the batch kernel's order, so a
        // sample's outputs do not depend on which others shared its batch.
        match rv {
            _ if rv.is_multiple_of(6) => matmul::<V, 6, 1, GELU>(d, x, xs, n, y),
            _ if rv.is_multiple_of(4) => matmul::<V, 4, 1, GELU>(d, x, xs, n, y),
            _ if rv.is_multiple_of(3) => matmul::<V, 3, 1, GELU>(d, x, xs, n, y),
            _ if rv.is_multiple_of(2) => matmul::<V, 2, 1, GELU>(d, x, xs, n, y),
            _ => matmul::<V, 1, 1, GELU>(d, x, xs, n, y),
        }
    } else {
        match rv {
            _ if rv.is_multiple_of(3) => matmul::<V, 3, NR, GELU>(d, x, xs, n, y),
            _ if rv.is_multiple_of(2) => matmul::<V, 2, NR, GELU>(d, x, xs, n, y),
            _ => matmul::<V, 1, NR, GELU>(d, x, xs, n, y),
        }
    }
}

/// The batch kernel: for each block of `MR` row vectors, tiles of `NR` samples, then the
/// remaining samples one by one.
#[inline(always)]
unsafe fn matmul<V: Simd, const MR: usize, const NR: usize, const GELU: bool>(
    d: &Dense,
    x: *const f32,
    xs: usize,
    n: usize,
    y: *mut f32,
) {
    let rows = d.rows_padded();
    let mut r0 = 0;
    while r0 < rows {
        let mut j = 0;
        while j + NR <= n {
            tile::<V, MR, NR, GELU>(d, x, xs, y, r0, j);
            j += NR;
        }
        while j < n {
            tile::<V, MR, 1, GELU>(d, x, xs, y, r0, j);
            j += 1;
        }
        r0 += MR * V::LANES;
    }
}

/// Rows `r0..r0 + MR·LANES` of samples `j0..j0 + NR`: accumulators start at the bias, one
/// FMA per weight vector and sample, then GELU in registers and one store.
// Indexing `acc[m][c]` by both loop counters is the point: the loops unroll into a
// register tile.
#[allow(clippy::needless_range_loop)]
#[inline(always)]
unsafe fn tile<V: Simd, const MR: usize, const NR: usize, const GELU: bool>(
    d: &Dense,
    x: *const f32,
    xs: usize,
    y: *mut f32,
    r0: usize,
    j0: usize,
) {
    let rows = d.rows_padded();
    let w = d.w.as_slice().as_ptr().add(r0);
    let b = d.b.as_slice().as_ptr().add(r0);
    let mut acc = [[V::splat(0.0); NR]; MR];
    for (m, row) in acc.iter_mut().enumerate() {
        let bv = V::load(b.add(m * V::LANES));
        for a in row.iter_mut() {
            *a = bv;
        }
    }
    let xc = x.add(j0 * xs);
    for kk in 0..d.k {
        let wk = w.add(kk * rows);
        let mut wv = [V::splat(0.0); MR];
        for (m, v) in wv.iter_mut().enumerate() {
            *v = V::load(wk.add(m * V::LANES));
        }
        for c in 0..NR {
            let xv = V::splat(*xc.add(c * xs + kk));
            for m in 0..MR {
                acc[m][c] = wv[m].mul_add(xv, acc[m][c]);
            }
        }
    }
    for (m, row) in acc.iter().enumerate() {
        for (c, &a) in row.iter().enumerate() {
            let v = if GELU { gelu_v(a) } else { a };
            v.store(y.add((j0 + c) * rows + r0 + m * V::LANES));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gelu::gelu_reference;

    /// A two-channel, one-conv network small enough to compute by hand.
    #[test]
    fn forward_matches_hand_computation() {
        let arch = Arch {
            input: 2,
            conv: vec![2],
            fc: vec![1],
            output: 1,
            window: 1,
        };
        let mut p = ParamSet::zeros(&arch);
        p.get_mut("conv1.weight")
            .copy_from_slice(&[1.0, 2.0, -1.0, 0.5]); // [[1,2],[-1,0.5]]
        p.get_mut("conv1.bias").copy_from_slice(&[0.5, -0.25]);
        p.get_mut("bn1.weight").copy_from_slice(&[2.0, 1.0]);
        p.get_mut("bn1.bias").copy_from_slice(&[0.0, 1.0]);
        p.get_mut("bn1.running_mean").copy_from_slice(&[1.0, 0.0]);
        p.get_mut("bn1.running_var").copy_from_slice(&[4.0, 1.0]);
        p.get_mut("fc1.weight").copy_from_slice(&[3.0, -1.0]);
        p.get_mut("fc1.bias").copy_from_slice(&[0.1]);
        p.get_mut("fc2.weight").copy_from_slice(&[2.0]);
        p.get_mut("fc2.bias").copy_from_slice(&[-1.0]);
        let x = [0.3f64, -0.2];
        // conv: z = W x + b
        let z = [x[0] + 2.0 * x[1] + 0.5, -x[0] + 0.5 * x[1] - 0.25];
        // batch norm (eval): γ (z − μ)/√(σ² + ε) + β
        let eps = BN_EPS as f64;
        let y = [
            2.0 * (z[0] - 1.0) / (4.0 + eps).sqrt(),
            (z[1] - 0.0) / (1.0 + eps).sqrt() + 1.0,
        ];
        let a = [gelu_reference(y[0]), gelu_reference(y[1])];
        let f1 = 3.0 * a[0] - a[1] + 0.1;
        let expect = 2.0 * f1 - 1.0;
        let net = Network::fold(&p);
        let mut s = net.scratch(4);
        let mut out = [0.0f32];
        net.forward_one(&[x[0] as f32, x[1] as f32], &mut out, &mut s);
        assert!(
            (out[0] as f64 - expect).abs() < 1e-5,
            "{} vs {expect}",
            out[0]
        );
        let xm = faer::Mat::from_fn(2, 3, |i, _| x[i] as f32);
        let mut om = faer::Mat::zeros(1, 3);
        net.forward(xm.as_ref(), om.as_mut(), &mut s);
        for j in 0..3 {
            assert!((om[(0, j)] as f64 - expect).abs() < 1e-5);
        }
    }

    /// The unfolded network in f64 straight from the parameters (conv, batch norm, exact
    /// tanh GELU, every fc layer): an independent reference for the kernels.
    fn reference(p: &ParamSet, x: [f64; 2]) -> Vec<f64> {
        let arch = p.arch();
        let mut a: Vec<f64> = x.to_vec();
        let dense = |name: &str, a: &[f64]| -> Vec<f64> {
            let wt = p.matrix_t(&format!("{name}.weight"));
            let b = p.get(&format!("{name}.bias"));
            (0..wt.ncols())
                .map(|o| {
                    b[o] as f64
                        + (0..wt.nrows())
                            .map(|i| wt[(i, o)] as f64 * a[i])
                            .sum::<f64>()
                })
                .collect()
        };
        for l in 1..=arch.conv.len() {
            let z = dense(&format!("conv{l}"), &a);
            let g = p.get(&format!("bn{l}.weight"));
            let be = p.get(&format!("bn{l}.bias"));
            let mu = p.get(&format!("bn{l}.running_mean"));
            let var = p.get(&format!("bn{l}.running_var"));
            a = (0..z.len())
                .map(|o| {
                    let y = g[o] as f64 * (z[o] - mu[o] as f64)
                        / (var[o] as f64 + BN_EPS as f64).sqrt()
                        + be[o] as f64;
                    gelu_reference(y)
                })
                .collect();
        }
        for l in 1..=arch.fc.len() + 1 {
            a = dense(&format!("fc{l}"), &a);
        }
        a
    }

    fn inputs(n: usize) -> Vec<[f32; 2]> {
        (0..n)
            .map(|i| {
                let t = i as f32 * 0.618;
                let r = 0.05 + (i % 37) as f32 * 0.13;
                [r * t.cos(), r * t.sin()]
            })
            .collect()
    }

    /// Every available kernel, batch and single-sample paths, against the f64 reference;
    /// batch sizes exercise whole tiles, leftover samples and chunking by the scratch size.
    fn check_against_reference(p: &ParamSet, tol: f64) {
        let base = Network::fold(p);
        let xs = inputs(75);
        let want: Vec<Vec<f64>> = xs
            .iter()
            .map(|x| reference(p, [x[0] as f64, x[1] as f64]))
            .collect();
        let scale = want.iter().flatten().fold(1.0f64, |m, v| m.max(v.abs()));
        for kernel in Kernel::available() {
            let net = base.clone().with_kernel(kernel);
            assert_eq!(net.kernel(), kernel);
            let k = net.outputs();
            for (max_batch, n) in [(256, 75), (16, 75), (8, 8), (32, 1), (4, 7)] {
                let mut s = net.scratch(max_batch);
                let xm = Mat::from_fn(2, n, |i, j| xs[j][i]);
                let mut out = Mat::from_fn(k, n, |_, _| f32::NAN);
                net.forward(xm.as_ref(), out.as_mut(), &mut s);
                for j in 0..n {
                    for o in 0..k {
                        let err = (out[(o, j)] as f64 - want[j][o]).abs() / scale;
                        assert!(err < tol, "{kernel} batch {n}/{max_batch} [{o},{j}]: {err}");
                    }
                }
            }
            let mut s = net.scratch(1);
            let mut one = vec![0.0f32; k];
            for (x, w) in xs.iter().zip(&want) {
                net.forward_one(x, &mut one, &mut s);
                for o in 0..k {
                    let err = (one[o] as f64 - w[o]).abs() / scale;
                    assert!(err < tol, "{kernel} single [{o}]: {err}");
                }
            }
        }
    }

    /// A sample's outputs are the same bits alone and in a batch of any size or
    /// position, on every kernel: a stream may batch the epochs of sources that woke
    /// together and still answer each as it would alone.
    #[test]
    fn batched_and_single_outputs_are_bit_identical() {
        let model = crate::Model::builtin("ghnet-temporal").expect("embedded model");
        let base = model.network().expect("network").clone();
        let inputs = base.arch().input;
        let n = 21; // two full 8-sample tiles and a remainder
        let xm = Mat::from_fn(inputs, n, |i, j| {
            ((i * 7 + j * 13) % 17) as f32 * 0.21 - 1.6
        });
        for kernel in Kernel::available() {
            let net = base.clone().with_kernel(kernel);
            let k = net.outputs();
            let mut one = vec![0.0f32; k];
            let mut s1 = net.scratch(1);
            for max_batch in [n, 8, 5] {
                let mut s = net.scratch(max_batch);
                let mut out = Mat::zeros(k, n);
                net.forward(xm.as_ref(), out.as_mut(), &mut s);
                for j in 0..n {
                    let x: Vec<f32> = (0..inputs).map(|i| xm[(i, j)]).collect();
                    net.forward_one(&x, &mut one, &mut s1);
                    for (o, &v) in one.iter().enumerate() {
                        assert_eq!(
                            v.to_bits(),
                            out[(o, j)].to_bits(),
                            "{kernel} batch of {n} by {max_batch}: output {o} of sample {j}"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn every_kernel_matches_f64_reference_on_shipped_model() {
        let model = crate::Model::builtin("ghnet-epoch").expect("embedded model");
        check_against_reference(model.params(), 2e-5);
    }

    /// Odd channel counts: padding, one- and two-vector row blocks, a 2-output head.
    #[test]
    fn every_kernel_matches_f64_reference_on_odd_shapes() {
        use rand::{Rng, SeedableRng};
        let arch = Arch {
            input: 2,
            conv: vec![5, 17, 40, 33],
            fc: vec![9],
            output: 2,
            window: 1,
        };
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let mut p = ParamSet::init(&arch, |b| rng.random_range(-b..b));
        for l in 1..=arch.conv.len() {
            for v in p.get_mut(&format!("bn{l}.running_mean")) {
                *v = rng.random_range(-0.5..0.5);
            }
            for v in p.get_mut(&format!("bn{l}.running_var")) {
                *v = rng.random_range(0.2..2.0);
            }
        }
        check_against_reference(&p, 2e-5);
    }

    /// A network of the one layer `d` on `kernel`, GELU after it or not.
    fn one_layer(d: Dense, gelu: bool, kernel: Kernel) -> Network {
        let arch = Arch {
            input: d.k,
            conv: vec![d.rows],
            fc: vec![],
            output: d.rows,
            window: if gelu { 2 } else { 1 },
        };
        Network {
            arch,
            kernel,
            layers: vec![d],
        }
    }

    /// `net`'s one layer over the `k × n` inputs `x` (column-major): its padded outputs.
    fn run_layer(net: &Network, x: &[f32], n: usize) -> Vec<f32> {
        let mut s = net.scratch(n);
        s.input.as_mut_slice().copy_from_slice(x);
        net.run(n, &mut s);
        s.acts[0].as_slice().to_vec()
    }

    /// Each SIMD kernel this CPU has against the faer path, one layer at a time on random
    /// weights, biases and inputs: every layer shape of the shipped models and odd ones
    /// (padding, one- and two-vector row blocks, one input), GELU after or not, batches
    /// of whole tiles, leftovers and a single sample.
    ///
    /// Tolerance: both sum the same `k + 1` terms (bias and products), in other orders
    /// and fused or not, so each lies within `(k+1)·ε·S` of the exact sum, `S = |b| +
    /// Σ|w·x|`, and they within twice that of each other; GELU's slope is under 1.13 and
    /// the vector GELU within `5e-7·(1 + |z|)` of the scalar one (`gelu` tests).
    #[test]
    fn every_simd_kernel_matches_faer_per_layer() {
        use rand::{Rng, SeedableRng};
        let mut shapes: Vec<(usize, usize)> = ["ghnet-epoch", "ghnet-temporal"]
            .iter()
            .flat_map(|name| {
                let model = crate::Model::builtin(name).expect("embedded model");
                let net = model.network().expect("network").clone();
                net.layers.iter().map(|d| (d.rows, d.k)).collect::<Vec<_>>()
            })
            .collect();
        shapes.extend([
            (1, 2),
            (5, 3),
            (17, 5),
            (33, 17),
            (40, 33),
            (2, 48),
            (100, 1),
        ]);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        for kernel in [Kernel::Avx512, Kernel::Avx2Fma] {
            if !kernel.is_available() {
                eprintln!("skipped: this CPU has no {kernel} kernel");
                continue;
            }
            eprintln!(
                "checking {kernel} against faer on {} layer shapes",
                shapes.len()
            );
            for &(rows, k) in &shapes {
                let w = Mat::from_fn(rows, k, |_, _| rng.random_range(-1.0f32..1.0));
                let b: Vec<f32> = (0..rows).map(|_| rng.random_range(-1.0..1.0)).collect();
                for (n, gelu) in [(1, true), (3, false), (8, true), (21, true), (21, false)] {
                    let x: Vec<f32> = (0..k * n).map(|_| rng.random_range(-2.0..2.0)).collect();
                    let layer = || Dense::new(w.as_ref(), &b, k);
                    let want = run_layer(&one_layer(layer(), gelu, Kernel::Portable), &x, n);
                    let got = run_layer(&one_layer(layer(), gelu, kernel), &x, n);
                    let rp = padded(rows);
                    for j in 0..n {
                        for i in 0..rows {
                            let s = (b[i].abs()
                                + (0..k)
                                    .map(|c| (w[(i, c)] * x[j * k + c]).abs())
                                    .sum::<f32>()) as f64;
                            let (g, f) = (got[j * rp + i] as f64, want[j * rp + i] as f64);
                            let sum = 2.0 * (k + 1) as f64 * f32::EPSILON as f64 * s;
                            // |z| ≤ S bounds the pre-activation the GELU saw.
                            let tol = if gelu {
                                1.13 * sum + 5e-7 * (1.0 + s)
                            } else {
                                sum
                            };
                            assert!(
                                (g - f).abs() <= tol,
                                "{kernel} {rows}×{k} n={n} gelu={gelu} [{i},{j}]: {g} vs faer {f}"
                            );
                        }
                        assert!(got[j * rp + rows..(j + 1) * rp].iter().all(|&v| v == 0.0));
                    }
                }
            }
        }
    }

    #[test]
    fn scratch_of_another_shape_is_refused() {
        let model = crate::Model::builtin("ghnet-epoch").expect("embedded model");
        let small = Network::fold(&ParamSet::init(&Arch::tiny(3), |b| b / 2.0));
        let mut s = small.scratch(4);
        let mut out = vec![0.0; model.network().unwrap().outputs()];
        let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            model
                .network()
                .unwrap()
                .forward_one(&[0.1, 0.2], &mut out, &mut s)
        }));
        let msg = r.expect_err("mismatched scratch must be refused");
        assert!(format!("{:?}", msg.downcast_ref::<&str>()).contains("another shape"));
    }
}
