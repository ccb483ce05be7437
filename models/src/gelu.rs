//! GELU in the tanh form the paper writes (PyTorch's `GELU(approximate="tanh")`).
//!
//! `gelu(x) = 0.5·x·(1 + tanh(√(2/π)·(x + 0.044715·x³)))`. This is not the exact erf GELU;
//! weights trained in PyTorch with the exact form would load but give slightly different
//! outputs, so the model metadata names the activation (`gelu_tanh`).

/// `√(2/π)`.
const K0: f32 = 0.797_884_6;
/// The cubic coefficient of the tanh approximation.
const K1: f32 = 0.044_715;

/// `tanh` accurate to a few f32 ulps, written so the compiler can vectorise a loop over it:
/// `tanh(x) = sign(x)·(1 − e)/(1 + e)` with `e = exp(−2|x|)`, and `exp` by range reduction
/// to `2^k·exp(r)` with a degree-6 polynomial on `|r| ≤ ln2/2`.
#[inline(always)]
pub fn tanh_fast(x: f32) -> f32 {
    let ax = x.abs().min(9.0); // tanh(9) = 1 - 3e-8: saturated in f32
    let e = exp_neg(2.0 * ax);
    let t = (1.0 - e) / (1.0 + e);
    t.copysign(x)
}

/// `exp(-y)` for `y` in `[0, 18]`, branch-free.
#[inline(always)]
fn exp_neg(y: f32) -> f32 {
    const LN2: f32 = std::f32::consts::LN_2;
    // Round to nearest with the 1.5·2^23 trick instead of `round()`, which on baseline
    // x86-64 (no SSE4.1) is a libm call that keeps the loop from vectorising.
    const MAGIC: f32 = 12_582_912.0;
    let z = -y;
    let k = (z / LN2 + MAGIC) - MAGIC;
    let r = z - k * LN2; // |r| <= ln2/2
                         // Taylor to r^7/7!: relative error < 2e-9 on |r| <= 0.347.
    let p = 1.0
        + r * (1.0
            + r * (0.5
                + r * (1.0 / 6.0
                    + r * (1.0 / 24.0 + r * (1.0 / 120.0 + r * (1.0 / 720.0 + r / 5040.0))))));
    let bits = ((k as i32 + 127) as u32) << 23;
    p * f32::from_bits(bits)
}

/// GELU (tanh form) of one value.
#[inline(always)]
pub fn gelu(x: f32) -> f32 {
    let u = K0 * (x + K1 * x * x * x);
    0.5 * x * (1.0 + tanh_fast(u))
}

/// GELU applied in place over a slice.
pub fn gelu_inplace(xs: &mut [f32]) {
    for x in xs {
        *x = gelu(*x);
    }
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
