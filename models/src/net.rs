//! The inference network: batch norm folded into the convolutions, linear head collapsed.
//!
//! With kernel size 1 and input length 1, each Conv1D layer is a dense layer over channels:
//! `z = W·x + b`. In evaluation mode batch norm is the affine map
//! `γ·(z − μ)/√(σ² + ε) + β`, so it folds into the convolution exactly:
//! `W' = diag(γ/√(σ²+ε))·W`, `b' = γ·(b − μ)/√(σ²+ε) + β`. The paper puts no activation between
//! its fully connected layers (and dropout is the identity at inference), so `fc4∘fc3∘fc2∘fc1`
//! is one affine map `W = W4·W3·W2·W1` — exact, not an approximation.
//!
//! Activations are column-major `channels × batch` matrices, one column per sample, so every
//! layer of a batch is one faer matrix product. The caller owns the scratch; nothing is
//! allocated per call.

use faer::linalg::matmul::matmul;
use faer::reborrow::ReborrowMut;
use faer::{Accum, Mat, MatMut, MatRef, Par};

use crate::gelu::gelu_inplace;
use crate::params::{Arch, ParamSet, BN_EPS};

/// One dense layer `y = W·x + b` with `W` stored `out × in` column-major.
#[derive(Debug, Clone)]
struct Dense {
    w: Mat<f32>,
    b: Vec<f32>,
}

impl Dense {
    fn out(&self) -> usize {
        self.w.nrows()
    }

    /// `y = W·x + b` for one sample, as a sum of weight columns (vectorises over `out`).
    #[inline]
    fn apply_one(&self, x: &[f32], y: &mut [f32]) {
        y.copy_from_slice(&self.b);
        for (j, &xj) in x.iter().enumerate() {
            let col = self
                .w
                .col(j)
                .try_as_col_major()
                .expect("owned Mat is contiguous");
            for (yi, wi) in y.iter_mut().zip(col.as_slice()) {
                *yi += wi * xj;
            }
        }
    }

    /// `Y = W·X + b·1ᵀ` for a batch.
    fn apply(&self, x: MatRef<'_, f32>, mut y: MatMut<'_, f32>) {
        for j in 0..y.ncols() {
            let col = y
                .rb_mut()
                .col_mut(j)
                .try_as_col_major_mut()
                .expect("contiguous");
            col.as_slice_mut().copy_from_slice(&self.b);
        }
        matmul(y, Accum::Add, self.w.as_ref(), x, 1.0f32, Par::Seq);
    }
}

/// The folded GHNet network, ready for inference.
#[derive(Debug, Clone)]
pub struct Network {
    arch: Arch,
    conv: Vec<Dense>,
    head: Dense,
}

/// Caller-owned buffers for [`Network::forward`] and [`Network::forward_one`].
///
/// Sized once for a maximum batch; a larger batch is processed in chunks of that size.
#[derive(Debug)]
pub struct Scratch {
    max_batch: usize,
    acts: Vec<Mat<f32>>,
    one: Vec<Vec<f32>>,
}

impl Scratch {
    /// The largest batch processed in one pass.
    pub fn max_batch(&self) -> usize {
        self.max_batch
    }
}

impl Network {
    /// Fold batch norm into the convolutions and collapse the linear head.
    pub fn fold(params: &ParamSet) -> Self {
        let arch = params.arch().clone();
        let mut conv = Vec::with_capacity(arch.conv.len());
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
            let b = (0..out)
                .map(|o| scale[o] * (b[o] - mean[o]) + beta[o])
                .collect();
            conv.push(Dense { w, b });
        }
        // Collapse fc layers: start with fc1 and compose.
        let n_fc = arch.fc.len() + 1;
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
        let head = Dense {
            w: Mat::from_fn(w.nrows(), w.ncols(), |i, j| w[(i, j)] as f32),
            b: b.into_iter().map(|v| v as f32).collect(),
        };
        Self { arch, conv, head }
    }

    /// The architecture.
    pub fn arch(&self) -> &Arch {
        &self.arch
    }

    /// Number of outputs per sample.
    pub fn outputs(&self) -> usize {
        self.head.out()
    }

    /// Buffers for batches of up to `max_batch` samples (at least one).
    pub fn scratch(&self, max_batch: usize) -> Scratch {
        let max_batch = max_batch.max(1);
        let mut acts = Vec::new();
        let mut one = Vec::new();
        for d in &self.conv {
            acts.push(Mat::zeros(d.out(), max_batch));
            one.push(vec![0.0; d.out()]);
        }
        Scratch {
            max_batch,
            acts,
            one,
        }
    }

    /// Forward one sample: `x` is the scaled input (length 2), `out` receives the outputs.
    pub fn forward_one(&self, x: &[f32], out: &mut [f32], scratch: &mut Scratch) {
        debug_assert_eq!(x.len(), self.arch.input);
        debug_assert_eq!(out.len(), self.outputs());
        let (first, rest) = scratch.one.split_at_mut(1);
        self.conv[0].apply_one(x, &mut first[0]);
        gelu_inplace(&mut first[0]);
        let mut prev: &mut Vec<f32> = &mut first[0];
        for (d, buf) in self.conv[1..].iter().zip(rest.iter_mut()) {
            d.apply_one(prev, buf);
            gelu_inplace(buf);
            prev = buf;
        }
        self.head.apply_one(prev, out);
    }

    /// Forward a batch: `x` is `2 × n` (scaled inputs, one column per sample), `out` is
    /// `outputs × n`. Any `n` is accepted; it is processed in chunks of the scratch size.
    pub fn forward(&self, x: MatRef<'_, f32>, mut out: MatMut<'_, f32>, scratch: &mut Scratch) {
        let n = x.ncols();
        assert_eq!(out.ncols(), n, "output columns must match input columns");
        let mut start = 0;
        while start < n {
            let len = (n - start).min(scratch.max_batch);
            let xin = x.subcols(start, len);
            for (l, d) in self.conv.iter().enumerate() {
                let (done, todo) = scratch.acts.split_at_mut(l);
                let mut dst = todo[0].as_mut().subcols_mut(0, len);
                let src = if l == 0 {
                    xin
                } else {
                    done[l - 1].as_ref().subcols(0, len)
                };
                d.apply(src, dst.rb_mut());
                for j in 0..len {
                    let c = dst
                        .rb_mut()
                        .col_mut(j)
                        .try_as_col_major_mut()
                        .expect("contiguous");
                    gelu_inplace(c.as_slice_mut());
                }
            }
            let last = scratch.acts.last().expect("at least one conv layer");
            self.head.apply(
                last.as_ref().subcols(0, len),
                out.rb_mut().subcols_mut(start, len),
            );
            start += len;
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
}
