//! GELU in the tanh form the paper writes (PyTorch's `GELU(approximate="tanh")`).
//!
//! `gelu(x) = 0.5·x·(1 + tanh(√(2/π)·(x + 0.044715·x³)))`. This is not the exact erf GELU;
//! weights trained in PyTorch with the exact form would load but give slightly different
//! outputs, so the model metadata names the activation (`gelu_tanh`).
//!
//! Two forms of the same arithmetic: the scalar [`gelu`] / [`gelu_with_grad`] that training
//! uses, and a vector form (the crate-internal `gelu_v`, exposed as [`gelu_inplace`]) that
//! inference runs on AVX-512, AVX2+FMA or portable code chosen at run time. They perform
//! the same operations in the same order, except that the AVX paths fuse multiply-adds and
//! divide by a refined reciprocal estimate (together a few f32 ulps apart); the portable
//! path is bit-identical to the scalar one. So a model trained with
//! the scalar form answers the same in inference.

use crate::simd::{on_kernel, Kernel, Simd};

/// `√(2/π)`.
const K0: f32 = 0.797_884_6;
/// The cubic coefficient of the tanh approximation.
const K1: f32 = 0.044_715;
/// `log2(e)`: `exp(z) = 2^(z·log2 e)`.
const LOG2E: f32 = std::f32::consts::LOG2_E;
const LN2: f32 = std::f32::consts::LN_2;
/// Adding and subtracting `1.5·2^23` rounds an f32 of magnitude < 2^22 to the nearest
/// integer without `round()`, which on baseline x86-64 (no SSE4.1) is a libm call that
/// keeps a loop from vectorising.
const MAGIC: f32 = 12_582_912.0;
/// Taylor coefficients of `exp(r)` from `r^2/2!` to `r^7/7!`: relative error < 2e-9 on
/// `|r| ≤ ln2/2`.
const C2: f32 = 0.5;
const C3: f32 = 1.0 / 6.0;
const C4: f32 = 1.0 / 24.0;
const C5: f32 = 1.0 / 120.0;
const C6: f32 = 1.0 / 720.0;
const C7: f32 = 1.0 / 5040.0;

/// `tanh` accurate to a few f32 ulps, written so the compiler can vectorise a loop over it:
/// `tanh(x) = sign(x)·(1 − e)/(1 + e)` with `e = exp(−2|x|)`, and `exp` by range reduction
/// to `2^k·exp(r)` with a degree-7 polynomial on `|r| ≤ ln2/2`.
#[inline(always)]
pub fn tanh_fast(x: f32) -> f32 {
    let ax = x.abs().min(9.0); // tanh(9) = 1 - 3e-8: saturated in f32
    let e = exp_neg(2.0 * ax);
    let t = (1.0 - e) / (1.0 + e);
    t.copysign(x)
}

/// `exp(-y)` for `y` in `[0, 18]`, branch-free. Same operations as `exp_v`.
#[inline(always)]
fn exp_neg(y: f32) -> f32 {
    let z = -y;
    let k = (z * LOG2E + MAGIC) - MAGIC;
    let r = z + k * -LN2; // |r| <= ln2/2
    let p = 1.0 + r * (1.0 + r * (C2 + r * (C3 + r * (C4 + r * (C5 + r * (C6 + r * C7))))));
    let bits = ((k as i32 + 127) as u32) << 23;
    p * f32::from_bits(bits)
}

/// [`gelu`] on every lane of `x`.
///
/// # Safety
/// `V`'s kernel must be available on this CPU (see [`Simd`]).
#[inline(always)]
pub(crate) unsafe fn gelu_v<V: Simd>(x: V) -> V {
    let one = V::splat(1.0);
    // K0·(x + K1·x·x·x)
    let u = V::splat(K0).mul(V::splat(K1).mul(x).mul(x).mul_add(x, x));
    // tanh_fast(u)
    let ax = u.abs().min(V::splat(9.0));
    let e = exp_v(ax.mul(V::splat(-2.0)));
    let t = one.sub(e).div_fast(one.add(e)).copysign(u);
    V::splat(0.5).mul(x).mul(one.add(t))
}

/// `exp(z)` for `z` in `[-18, 0]` on every lane: `exp_neg(-z)`, same operations.
#[inline(always)]
unsafe fn exp_v<V: Simd>(z: V) -> V {
    let k = z
        .mul_add(V::splat(LOG2E), V::splat(MAGIC))
        .sub(V::splat(MAGIC));
    let r = k.mul_add(V::splat(-LN2), z);
    let mut p = r.mul_add(V::splat(C7), V::splat(C6));
    for c in [C5, C4, C3, C2, 1.0, 1.0] {
        p = r.mul_add(p, V::splat(c));
    }
    p.mul_pow2i(k)
}

/// GELU over a slice, `V::LANES` at a time, the tail through the scalar form.
#[inline(always)]
unsafe fn gelu_slice_v<V: Simd>(xs: &mut [f32]) {
    let mut chunks = xs.chunks_exact_mut(V::LANES);
    for c in &mut chunks {
        gelu_v(V::load(c.as_ptr())).store(c.as_mut_ptr());
    }
    for x in chunks.into_remainder() {
        *x = gelu(*x);
    }
}

/// GELU (tanh form) of one value.
#[inline(always)]
pub fn gelu(x: f32) -> f32 {
    let u = K0 * (x + K1 * x * x * x);
    0.5 * x * (1.0 + tanh_fast(u))
}

/// GELU applied in place over a slice, with the widest kernel this CPU has.
pub fn gelu_inplace(xs: &mut [f32]) {
    gelu_inplace_with(Kernel::detect(), xs)
}

/// GELU in place with a given kernel (an unavailable one falls back to portable code);
/// for benches and for tests that hold the paths against each other.
pub fn gelu_inplace_with(kernel: Kernel, xs: &mut [f32]) {
    on_kernel!(kernel, gelu_slice_v(xs: &mut [f32]) -> ())
}

/// GELU and its derivative at `x`, for the backward pass.
#[inline(always)]
pub fn gelu_with_grad(x: f32) -> (f32, f32) {
    let u = K0 * (x + K1 * x * x * x);
    let t = tanh_fast(u);
    let y = 0.5 * x * (1.0 + t);
    let du = K0 * (1.0 + 3.0 * K1 * x * x);
    let dy = 0.5 * (1.0 + t) + 0.5 * x * (1.0 - t * t) * du;
    (y, dy)
}

/// The reference GELU in f64 with the standard library's `tanh`, for tests.
pub fn gelu_reference(x: f64) -> f64 {
    let k0 = (2.0 / std::f64::consts::PI).sqrt();
    0.5 * x * (1.0 + (k0 * (x + 0.044715 * x * x * x)).tanh())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tanh_fast_matches_std_within_f32_noise() {
        let mut worst: f64 = 0.0;
        let mut x = -20.0f32;
        while x <= 20.0 {
            let err = (tanh_fast(x) as f64 - (x as f64).tanh()).abs();
            worst = worst.max(err);
            x += 0.000_37;
        }
        // f32 has 2^-24 ≈ 6e-8 relative precision; allow a few ulps.
        assert!(worst < 4e-7, "worst abs error {worst}");
    }

    #[test]
    fn gelu_hand_values() {
        // gelu(0) = 0; gelu(1) = 0.5·(1 + tanh(0.7978846·1.044715)) = 0.841192
        assert_eq!(gelu(0.0), 0.0);
        assert!((gelu(1.0) - 0.841_192).abs() < 1e-6);
        assert!((gelu(-1.0) + 0.158_808).abs() < 1e-6);
        // large |x|: identity and zero
        assert!((gelu(10.0) - 10.0).abs() < 1e-6);
        assert!(gelu(-10.0).abs() < 1e-6);
        let mut x = -8.0f32;
        while x < 8.0 {
            let err = (gelu(x) as f64 - gelu_reference(x as f64)).abs();
            assert!(err < 1e-6 * (1.0 + x.abs() as f64), "x={x} err={err}");
            x += 0.01;
        }
    }

    /// Every kernel against the f64 reference over a dense grid of `[-12, 12]`, and the
    /// kernels against each other: the bound is what the f32 arithmetic can promise.
    #[test]
    fn vector_gelu_error_bound_and_agreement_between_kernels() {
        let n = 1 << 20;
        let xs: Vec<f32> = (0..n)
            .map(|i| -12.0 + 24.0 * i as f32 / (n - 1) as f32)
            .chain([0.0, -0.0, 1e-30, -1e-30, 20.0, -20.0, 1e6, -1e6])
            .collect();
        let mut scalar = xs.clone();
        for x in &mut scalar {
            *x = gelu(*x);
        }
        for k in Kernel::available() {
            let mut ys = xs.clone();
            gelu_inplace_with(k, &mut ys);
            let mut worst_ref: f64 = 0.0;
            let mut worst_scalar: f64 = 0.0;
            for ((&x, &y), &s) in xs.iter().zip(&ys).zip(&scalar) {
                let tol = 1.0 + (x as f64).abs();
                worst_ref = worst_ref.max((y as f64 - gelu_reference(x as f64)).abs() / tol);
                worst_scalar = worst_scalar.max((y as f64 - s as f64).abs() / tol);
            }
            assert!(worst_ref < 5e-7, "{k}: error vs f64 reference {worst_ref}");
            assert!(
                worst_scalar < 5e-7,
                "{k}: differs from scalar gelu by {worst_scalar}"
            );
            if k == Kernel::Portable {
                assert_eq!(ys, scalar, "portable path must be bit-identical to scalar");
            }
        }
    }

    #[test]
    fn vector_gelu_propagates_nan_and_infinities() {
        for k in Kernel::available() {
            let mut ys = [f32::NAN, f32::INFINITY, f32::NEG_INFINITY, 3.0].repeat(8);
            gelu_inplace_with(k, &mut ys);
            for c in ys.chunks(4) {
                assert!(c[0].is_nan(), "{k}");
                assert_eq!(c[1], f32::INFINITY, "{k}");
                // gelu(-inf) is 0·(-inf) in this form: NaN (scalar) or -inf (the
                // reciprocal estimate leaves 1 + tanh a hair above 0); never finite.
                assert!(!c[2].is_finite(), "{k}: {}", c[2]);
                assert!((c[3] - gelu(3.0)).abs() < 1e-6, "{k}");
            }
        }
    }

    #[test]
    fn gelu_grad_matches_finite_difference() {
        let mut x = -5.0f64;
        while x < 5.0 {
            let h = 1e-4;
            let fd = (gelu_reference(x + h) - gelu_reference(x - h)) / (2.0 * h);
            let (_, g) = gelu_with_grad(x as f32);
            assert!((g as f64 - fd).abs() < 1e-5, "x={x} g={g} fd={fd}");
            x += 0.05;
        }
    }
}
