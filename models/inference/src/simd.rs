//! Runtime-dispatched SIMD for the inference hot loops: AVX-512, AVX2+FMA, portable.
//!
//! Binaries are built for baseline x86-64 (SSE2), so the wide paths are compiled with
//! `#[target_feature]` and chosen at run time ([`Kernel::detect`], or by name with
//! [`KERNEL_ENV`]). The AVX paths run the same generic code (the private `Simd` lane
//! trait is the only thing that differs); the portable path runs GELU on that code with
//! plain-Rust lanes and the network's products on faer ([`crate::net`]). They agree to
//! within f32 rounding: the AVX paths fuse multiply-adds, and each sums in its own order.
//!
//! Also here: 64-byte aligned buffers for weights and activations, and the FMA loop that
//! measures this core's peak throughput, so benches can state their GFLOP/s as a share of
//! a peak measured in the same run.

use std::fmt;
use std::str::FromStr;
use std::sync::OnceLock;

/// Which instruction set the inference kernels use.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Kernel {
    /// 16 f32 lanes, 32 registers (x86-64 with AVX-512F).
    Avx512,
    /// 8 f32 lanes with fused multiply-add (x86-64 with AVX2 and FMA).
    Avx2Fma,
    /// Any target: the network's products on faer's matrix product (faer picks its own
    /// instructions), GELU and the peak loop in plain Rust on groups of 4 lanes.
    Portable,
}

impl Kernel {
    /// Every kernel, widest first.
    pub const ALL: [Kernel; 3] = [Kernel::Avx512, Kernel::Avx2Fma, Kernel::Portable];

    /// The kernel inference runs on: the one [`KERNEL_ENV`] names if this CPU has it, else
    /// the widest this CPU supports. Read once per process, so every network and GELU in
    /// it agrees.
    pub fn detect() -> Self {
        static CHOSEN: OnceLock<Kernel> = OnceLock::new();
        *CHOSEN.get_or_init(|| {
            std::env::var(KERNEL_ENV)
                .ok()
                .and_then(|name| name.parse::<Kernel>().ok())
                .filter(|k| k.is_available())
                .unwrap_or_else(Self::widest)
        })
    }

    /// The widest kernel this CPU supports.
    pub fn widest() -> Self {
        Self::available().next().unwrap_or(Kernel::Portable)
    }

    /// This kernel if this CPU can run it, else [`Kernel::Portable`]: what the
    /// explicit-kernel entry points (benches, tests) fall back to.
    pub fn or_portable(self) -> Kernel {
        if self.is_available() {
            self
        } else {
            Kernel::Portable
        }
    }

    /// Whether this CPU can run the kernel (checked at run time, cached by std).
    pub fn is_available(self) -> bool {
        match self {
            #[cfg(target_arch = "x86_64")]
            Kernel::Avx512 => std::arch::is_x86_feature_detected!("avx512f"),
            #[cfg(target_arch = "x86_64")]
            Kernel::Avx2Fma => {
                std::arch::is_x86_feature_detected!("avx2")
                    && std::arch::is_x86_feature_detected!("fma")
            }
            #[cfg(not(target_arch = "x86_64"))]
            Kernel::Avx512 | Kernel::Avx2Fma => false,
            Kernel::Portable => true,
        }
    }

    /// The kernels this CPU can run, widest first.
    pub fn available() -> impl Iterator<Item = Kernel> {
        Self::ALL.into_iter().filter(|k| k.is_available())
    }

    /// f32 lanes per vector.
    pub fn lanes(self) -> usize {
        match self {
            Kernel::Avx512 => 16,
            Kernel::Avx2Fma => 8,
            Kernel::Portable => 4,
        }
    }

    /// The kernel's name: what [`fmt::Display`] prints, [`KERNEL_ENV`] takes and the
    /// benches call it.
    pub fn as_str(self) -> &'static str {
        match self {
            Kernel::Avx512 => "avx512",
            Kernel::Avx2Fma => "avx2+fma",
            Kernel::Portable => "portable",
        }
    }
}

impl fmt::Display for Kernel {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl FromStr for Kernel {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Self::ALL
            .into_iter()
            .find(|k| k.as_str() == s)
            .ok_or_else(|| format!("unknown kernel `{s}` (avx512, avx2+fma or portable)"))
    }
}

/// Environment variable that picks the inference kernel ([`Kernel::detect`]) by name:
/// `portable` runs every network on faer's matrix product on any CPU, as a CPU without
/// AVX2 would, to check or bench that path; `avx2+fma` the AVX2 kernel on an AVX-512
/// CPU. A name this CPU cannot run, or none, leaves the widest kernel.
pub const KERNEL_ENV: &str = "GHNET_KERNEL";

/// Rows of every weight matrix and activation are padded to a multiple of this (the widest
/// vector), so kernels never need a remainder loop over channels. Padded rows have zero
/// weights and bias, so they hold `gelu(0) = 0` and contribute nothing downstream.
pub(crate) const PAD: usize = 16;

/// `n` rounded up to a multiple of [`PAD`].
pub(crate) fn padded(n: usize) -> usize {
    n.div_ceil(PAD) * PAD
}

/// One cache line of f32s; a `Vec` of these is a 64-byte aligned f32 buffer.
#[derive(Debug, Clone, Copy)]
#[repr(C, align(64))]
struct Line([f32; 16]);

/// A zero-initialised, 64-byte aligned f32 buffer: vector loads never straddle cache lines.
#[derive(Debug, Clone)]
pub(crate) struct AlignedBuf {
    lines: Vec<Line>,
    len: usize,
}

impl AlignedBuf {
    /// `len` zeros.
    pub(crate) fn zeros(len: usize) -> Self {
        Self {
            lines: vec![Line([0.0; 16]); len.div_ceil(16)],
            len,
        }
    }

    pub(crate) fn as_slice(&self) -> &[f32] {
        // SAFETY: `Line` is `repr(C)` over `[f32; 16]` with no padding (64 bytes), so the
        // lines are `16 * lines.len() >= len` contiguous initialised f32s.
        unsafe { std::slice::from_raw_parts(self.lines.as_ptr().cast::<f32>(), self.len) }
    }

    pub(crate) fn as_mut_slice(&mut self) -> &mut [f32] {
        // SAFETY: as in `as_slice`, and `&mut self` makes the borrow unique.
        unsafe { std::slice::from_raw_parts_mut(self.lines.as_mut_ptr().cast::<f32>(), self.len) }
    }
}

/// A vector of f32 lanes with the operations the kernels need.
///
/// # Safety
/// Implementations wrap `#[target_feature]` intrinsics. Callers must only use a type whose
/// [`Kernel`] is available on this CPU, and pointers must be valid for `LANES` f32s.
/// The methods are `#[inline(always)]` so that, called from a `#[target_feature]` function,
/// they compile to single instructions.
pub(crate) trait Simd: Copy {
    const LANES: usize;
    unsafe fn splat(v: f32) -> Self;
    unsafe fn load(p: *const f32) -> Self;
    unsafe fn store(self, p: *mut f32);
    unsafe fn add(self, o: Self) -> Self;
    unsafe fn sub(self, o: Self) -> Self;
    unsafe fn mul(self, o: Self) -> Self;
    unsafe fn div(self, o: Self) -> Self;
    /// `self / o` to within about 2 ulps, for `o` in `[1, 2]`: on AVX a reciprocal
    /// estimate refined by one Newton step (a full division is the slowest instruction of
    /// the GELU, ~10 cycles per vector); exact division on the portable path.
    unsafe fn div_fast(self, o: Self) -> Self;
    /// `min(self, o)`; if `self` is NaN the result is `o` (as `f32::min` and `minps`).
    unsafe fn min(self, o: Self) -> Self;
    /// `self·b + c`, fused where the ISA has FMA.
    unsafe fn mul_add(self, b: Self, c: Self) -> Self;
    unsafe fn abs(self) -> Self;
    /// The magnitude of `self` with the sign of `sign`.
    unsafe fn copysign(self, sign: Self) -> Self;
    /// `2^k` for lanes holding small integral values (`-126 ≤ k ≤ 127`).
    unsafe fn pow2i(k: Self) -> Self;
    /// `self·2^k` for integral `k` as in [`Simd::pow2i`]; exact (no rounding) while the
    /// result is a normal number, so every implementation gives the same bits.
    #[inline(always)]
    unsafe fn mul_pow2i(self, k: Self) -> Self {
        self.mul(Self::pow2i(k))
    }
}

#[cfg(target_arch = "x86_64")]
mod x86 {
    use super::Simd;
    use std::arch::x86_64::*;

    /// The [`Simd`] methods both widths share but for the intrinsics' names (AVX-512F
    /// and AVX2+FMA name the same operations `_mm512_*` and `_mm256_*`), given in the
    /// order of the rule below: `set1`, `loadu`, `storeu`, `add`, `sub`, `mul`, `div`,
    /// `min`, `fmadd`, `fnmadd`, the reciprocal estimate, `cvtps_epi32`, `add_epi32`,
    /// `set1_epi32`, `slli_epi32` and the cast to f32 lanes. `abs`, `copysign` and
    /// `mul_pow2i` differ in more than names and stay with each type.
    macro_rules! shared_ops {
        (@binary $($op:ident $intr:ident),*) => {
            $(
                #[inline(always)]
                unsafe fn $op(self, o: Self) -> Self {
                    Self($intr(self.0, o.0))
                }
            )*
        };
        ($set1:ident, $loadu:ident, $storeu:ident, $add:ident, $sub:ident, $mul:ident,
         $div:ident, $min:ident, $fmadd:ident, $fnmadd:ident, $rcp:ident, $cvt:ident,
         $addi:ident, $set1i:ident, $slli:ident, $cast:ident) => {
            #[inline(always)]
            unsafe fn splat(v: f32) -> Self {
                Self($set1(v))
            }
            #[inline(always)]
            unsafe fn load(p: *const f32) -> Self {
                Self($loadu(p))
            }
            #[inline(always)]
            unsafe fn store(self, p: *mut f32) {
                $storeu(p, self.0)
            }
            shared_ops!(@binary add $add, sub $sub, mul $mul, div $div, min $min);
            #[inline(always)]
            unsafe fn mul_add(self, b: Self, c: Self) -> Self {
                Self($fmadd(self.0, b.0, c.0))
            }
            #[inline(always)]
            unsafe fn div_fast(self, o: Self) -> Self {
                // The reciprocal estimate (rcp14: relative error < 2^-14; rcp: < 1.5·2^-12)
                // refined by one Newton step, which squares its error.
                let r = $rcp(o.0);
                let e = $fnmadd(o.0, r, $set1(1.0));
                self.mul(Self($fmadd(r, e, r)))
            }
            #[inline(always)]
            unsafe fn pow2i(k: Self) -> Self {
                let e = $addi($cvt(k.0), $set1i(127));
                Self($cast($slli::<23>(e)))
            }
        };
    }

    /// AVX-512F: 16 lanes.
    #[derive(Clone, Copy)]
    pub(crate) struct V16(__m512);

    impl Simd for V16 {
        const LANES: usize = 16;
        shared_ops! {
            _mm512_set1_ps, _mm512_loadu_ps, _mm512_storeu_ps, _mm512_add_ps, _mm512_sub_ps,
            _mm512_mul_ps, _mm512_div_ps, _mm512_min_ps, _mm512_fmadd_ps, _mm512_fnmadd_ps,
            _mm512_rcp14_ps, _mm512_cvtps_epi32, _mm512_add_epi32, _mm512_set1_epi32,
            _mm512_slli_epi32, _mm512_castsi512_ps
        }
        #[inline(always)]
        unsafe fn abs(self) -> Self {
            V16(_mm512_abs_ps(self.0))
        }
        #[inline(always)]
        unsafe fn copysign(self, sign: Self) -> Self {
            // One bitwise select: sign bit (mask m) from `sign`, the rest from `self`.
            // Truth table 0xCA = a ? b : c, for operands (a, b, c) = (m, sign, self).
            let m = _mm512_set1_epi32(i32::MIN);
            V16(_mm512_castsi512_ps(_mm512_ternarylogic_epi32::<0xCA>(
                m,
                _mm512_castps_si512(sign.0),
                _mm512_castps_si512(self.0),
            )))
        }
        #[inline(always)]
        unsafe fn mul_pow2i(self, k: Self) -> Self {
            // vscalefps: one instruction instead of convert, add, shift, multiply.
            V16(_mm512_scalef_ps(self.0, k.0))
        }
    }

    /// AVX2 + FMA: 8 lanes.
    #[derive(Clone, Copy)]
    pub(crate) struct V8(__m256);

    impl Simd for V8 {
        const LANES: usize = 8;
        shared_ops! {
            _mm256_set1_ps, _mm256_loadu_ps, _mm256_storeu_ps, _mm256_add_ps, _mm256_sub_ps,
            _mm256_mul_ps, _mm256_div_ps, _mm256_min_ps, _mm256_fmadd_ps, _mm256_fnmadd_ps,
            _mm256_rcp_ps, _mm256_cvtps_epi32, _mm256_add_epi32, _mm256_set1_epi32,
            _mm256_slli_epi32, _mm256_castsi256_ps
        }
        #[inline(always)]
        unsafe fn abs(self) -> Self {
            V8(_mm256_andnot_ps(_mm256_set1_ps(-0.0), self.0))
        }
        #[inline(always)]
        unsafe fn copysign(self, sign: Self) -> Self {
            let m = _mm256_set1_ps(-0.0);
            V8(_mm256_or_ps(
                _mm256_andnot_ps(m, self.0),
                _mm256_and_ps(m, sign.0),
            ))
        }
    }
}
#[cfg(target_arch = "x86_64")]
pub(crate) use x86::{V16, V8};

/// Portable: 4 lanes of plain f32 arithmetic (no fused multiply-add, which would be a
/// libm call on baseline x86-64). Matches the scalar [`crate::gelu::gelu`] bit for bit.
#[derive(Clone, Copy)]
pub(crate) struct V4([f32; 4]);

impl V4 {
    #[inline(always)]
    fn map2(self, o: Self, f: impl Fn(f32, f32) -> f32) -> Self {
        V4([
            f(self.0[0], o.0[0]),
            f(self.0[1], o.0[1]),
            f(self.0[2], o.0[2]),
            f(self.0[3], o.0[3]),
        ])
    }
}

impl Simd for V4 {
    const LANES: usize = 4;
    #[inline(always)]
    unsafe fn splat(v: f32) -> Self {
        V4([v; 4])
    }
    #[inline(always)]
    unsafe fn load(p: *const f32) -> Self {
        V4(p.cast::<[f32; 4]>().read_unaligned())
    }
    #[inline(always)]
    unsafe fn store(self, p: *mut f32) {
        p.cast::<[f32; 4]>().write_unaligned(self.0)
    }
    #[inline(always)]
    unsafe fn add(self, o: Self) -> Self {
        self.map2(o, |a, b| a + b)
    }
    #[inline(always)]
    unsafe fn sub(self, o: Self) -> Self {
        self.map2(o, |a, b| a - b)
    }
    #[inline(always)]
    unsafe fn mul(self, o: Self) -> Self {
        self.map2(o, |a, b| a * b)
    }
    #[inline(always)]
    unsafe fn div(self, o: Self) -> Self {
        self.map2(o, |a, b| a / b)
    }
    #[inline(always)]
    unsafe fn div_fast(self, o: Self) -> Self {
        self.div(o)
    }
    #[inline(always)]
    unsafe fn min(self, o: Self) -> Self {
        self.map2(o, |a, b| if a < b { a } else { b })
    }
    #[inline(always)]
    unsafe fn mul_add(self, b: Self, c: Self) -> Self {
        self.mul(b).add(c)
    }
    #[inline(always)]
    unsafe fn abs(self) -> Self {
        V4(self.0.map(f32::abs))
    }
    #[inline(always)]
    unsafe fn copysign(self, sign: Self) -> Self {
        self.map2(sign, f32::copysign)
    }
    #[inline(always)]
    unsafe fn pow2i(k: Self) -> Self {
        V4(k.0.map(|k| f32::from_bits(((k as i32 + 127) as u32) << 23)))
    }
}

/// Runs the generic `f::<V>(args)` on the vector type of `kernel` (portable vectors when
/// this CPU lacks it), called from a function compiled with that kernel's target features
/// so that the [`Simd`] methods inline to its instructions:
/// `on_kernel!(kernel, f(arg: Type, ...) -> Ret)`, each `arg` a variable in scope.
macro_rules! on_kernel {
    ($kernel:expr, $f:ident($($arg:ident: $ty:ty),*) -> $ret:ty) => {{
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = "avx512f")]
        unsafe fn avx512($($arg: $ty),*) -> $ret {
            $f::<$crate::simd::V16>($($arg),*)
        }
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = "avx2,fma")]
        unsafe fn avx2($($arg: $ty),*) -> $ret {
            $f::<$crate::simd::V8>($($arg),*)
        }
        match $kernel.or_portable() {
            // SAFETY: the kernel is available on this CPU (`or_portable`).
            #[cfg(target_arch = "x86_64")]
            $crate::simd::Kernel::Avx512 => unsafe { avx512($($arg),*) },
            #[cfg(target_arch = "x86_64")]
            $crate::simd::Kernel::Avx2Fma => unsafe { avx2($($arg),*) },
            // SAFETY: V4 is plain Rust.
            _ => unsafe { $f::<$crate::simd::V4>($($arg),*) },
        }
    }};
}
pub(crate) use on_kernel;

/// Independent FMA chains in the peak loop: enough to cover FMA latency (4 cycles) times
/// the FMA ports (2) on current x86 cores, and few enough to stay in registers.
const PEAK_CHAINS: usize = 12;

/// Run `iters` rounds of `PEAK_CHAINS` independent vector FMAs on `kernel` and return a
/// value that depends on all of them (so the loop cannot be optimised away).
///
/// This is the reference for "share of peak": a loop that does nothing but fused
/// multiply-adds from registers. Count its work with [`peak_loop_flops`].
pub fn peak_fma_loop(kernel: Kernel, iters: u64) -> f32 {
    on_kernel!(kernel, peak_generic(iters: u64) -> f32)
}

/// Floating-point operations done by [`peak_fma_loop`]: 2 per lane per FMA.
pub fn peak_loop_flops(kernel: Kernel, iters: u64) -> u64 {
    let kernel = kernel.or_portable();
    iters * PEAK_CHAINS as u64 * kernel.lanes() as u64 * 2
}

#[inline(always)]
unsafe fn peak_generic<V: Simd>(iters: u64) -> f32 {
    // x ← x·a + b with a slightly below 1 converges, so values stay finite for any count.
    let a = V::splat(std::hint::black_box(0.999_9));
    let b = V::splat(std::hint::black_box(1e-4));
    let mut acc = [V::splat(0.0); PEAK_CHAINS];
    for (i, v) in acc.iter_mut().enumerate() {
        *v = V::splat(i as f32);
    }
    for _ in 0..iters {
        for v in acc.iter_mut() {
            *v = v.mul_add(a, b);
        }
    }
    let mut s = V::splat(0.0);
    for v in acc {
        s = s.add(v);
    }
    let mut lanes = [0.0f32; 16];
    s.store(lanes.as_mut_ptr());
    lanes.iter().sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn aligned_buf_is_aligned_and_zeroed() {
        let mut b = AlignedBuf::zeros(37);
        assert_eq!(b.as_slice().len(), 37);
        assert_eq!(b.as_slice().as_ptr() as usize % 64, 0);
        assert!(b.as_slice().iter().all(|&v| v == 0.0));
        b.as_mut_slice()[36] = 1.0;
        assert_eq!(b.as_slice()[36], 1.0);
    }

    #[test]
    fn peak_loop_runs_on_every_available_kernel() {
        assert!(Kernel::detect().is_available());
        for k in Kernel::available() {
            let v = peak_fma_loop(k, 1000);
            assert!(v.is_finite() && v > 0.0, "{k}: {v}");
            assert_eq!(peak_loop_flops(k, 10), 10 * 12 * 2 * k.lanes() as u64);
        }
    }
}
