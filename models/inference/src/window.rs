//! [`WindowHead`]: the temporal network's fully connected layers, collapsed to one
//! affine map over the features of the last `window` epochs. Apart from the stream so
//! that a [`crate::Model`] can hold one without depending on the streaming code.

/// The temporal head: the fully connected layers collapsed to `y = W·[f_t, …, f_{t−W+1}]
/// + b` over the cached features of the last `window` epochs.
#[derive(Debug, Clone)]
pub struct WindowHead {
    window: usize,
    features: usize,
    outputs: usize,
    /// `outputs × (window·features)`, row-major; slot `k` (age in epochs) at columns
    /// `k·features..`.
    w: Vec<f32>,
    b: Vec<f32>,
}

impl WindowHead {
    /// From the collapsed map `w` (`outputs × window·features`) and bias.
    pub fn new(w: faer::MatRef<'_, f32>, b: &[f32], window: usize) -> Self {
        let (outputs, cols) = (w.nrows(), w.ncols());
        assert!(window > 0 && cols.is_multiple_of(window) && b.len() == outputs);
        Self {
            window,
            features: cols / window,
            outputs,
            w: (0..outputs)
                .flat_map(|o| (0..cols).map(move |j| (o, j)))
                .map(|(o, j)| w[(o, j)])
                .collect(),
            b: b.to_vec(),
        }
    }

    /// Epochs in the window.
    pub fn window(&self) -> usize {
        self.window
    }

    /// Features per epoch.
    pub fn features(&self) -> usize {
        self.features
    }

    /// `out = W·ring + b` where `ring` holds `window` feature vectors and slot `k` (age
    /// `k`, 0 = newest) is at `ring[((newest + window − k) % window)·features..]`; slots
    /// `k ≥ filled` are empty (zero) and skipped.
    ///
    /// Runs once per epoch on the streaming path. With AVX2 (chosen at run time, as the
    /// network's kernels are) the same code runs on 256-bit lanes: the same multiplies
    /// and adds in the same order, so the answer is bit for bit the plain lanes'.
    pub fn apply(&self, ring: &[f32], newest: usize, filled: usize, out: &mut [f32]) {
        #[cfg(target_arch = "x86_64")]
        if crate::simd::Kernel::Avx2Fma.is_available() {
            // SAFETY: checked just above.
            return unsafe { self.apply_avx2(ring, newest, filled, out) };
        }
        self.apply_lanes(ring, newest, filled, out);
    }

    /// [`WindowHead::apply_lanes`] with its eight partial sums in one AVX register:
    /// the same multiply, then add, per lane and in the same order (no fused
    /// multiply-add), so the same bits. Features not a multiple of eight take the
    /// plain path.
    ///
    /// # Safety
    /// The CPU has AVX2 and FMA ([`crate::simd::Kernel::Avx2Fma`] is available).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn apply_avx2(&self, ring: &[f32], newest: usize, filled: usize, out: &mut [f32]) {
        use crate::simd::{Simd, V8};
        let (w, c) = (self.window, self.features);
        if !c.is_multiple_of(8) {
            return self.apply_lanes(ring, newest, filled, out);
        }
        let cols = w * c;
        for (o, y) in out.iter_mut().enumerate().take(self.outputs) {
            let row = &self.w[o * cols..(o + 1) * cols];
            let mut acc = V8::splat(0.0);
            for k in 0..filled.min(w) {
                let slot = slot_of_age(newest, k, w);
                let f = &ring[slot * c..(slot + 1) * c];
                let wk = &row[k * c..(k + 1) * c];
                for j in 0..c / 8 {
                    // SAFETY: `8·j + 8 ≤ c`, the length of both slices.
                    let (fv, wv) = (
                        V8::load(f.as_ptr().add(8 * j)),
                        V8::load(wk.as_ptr().add(8 * j)),
                    );
                    acc = acc.add(fv.mul(wv));
                }
            }
            let mut lanes = [0.0f32; 8];
            acc.store(lanes.as_mut_ptr());
            *y = self.b[o] + lanes.iter().sum::<f32>();
        }
    }

    /// The head on plain Rust lanes.
    #[inline(always)]
    fn apply_lanes(&self, ring: &[f32], newest: usize, filled: usize, out: &mut [f32]) {
        let (w, c) = (self.window, self.features);
        let cols = w * c;
        for (o, y) in out.iter_mut().enumerate().take(self.outputs) {
            let row = &self.w[o * cols..(o + 1) * cols];
            // Eight partial sums: one running sum is a chain of dependent additions
            // the compiler may not reorder; eight independent ones vectorise.
            let mut acc = [0.0f32; 8];
            for k in 0..filled.min(w) {
                let slot = slot_of_age(newest, k, w);
                let f = &ring[slot * c..(slot + 1) * c];
                let wk = &row[k * c..(k + 1) * c];
                let (fc, wc) = (f.chunks_exact(8), wk.chunks_exact(8));
                for (a, b) in fc.remainder().iter().zip(wc.remainder()) {
                    acc[0] += a * b;
                }
                for (fs, ws) in fc.zip(wc) {
                    for l in 0..8 {
                        acc[l] += fs[l] * ws[l];
                    }
                }
            }
            *y = self.b[o] + acc.iter().sum::<f32>();
        }
    }
}

/// The ring slot of the features `k < window` epochs old when the newest are in slot
/// `newest`: `(newest + window − k) % window`, without a division.
#[inline(always)]
fn slot_of_age(newest: usize, k: usize, window: usize) -> usize {
    if newest >= k {
        newest - k
    } else {
        newest + window - k
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// The dispatched head (AVX2 where this CPU has it) gives the plain lanes' bits for
    /// every fill of the ring and every newest slot, with features a multiple of eight
    /// (the wide path) and not (the plain path).
    #[test]
    fn the_wide_head_gives_the_plain_heads_bits() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        for features in [48, 13] {
            let (window, outputs) = (8, 3);
            let w: Vec<f32> = (0..outputs * window * features)
                .map(|_| rng.random_range(-1.0..1.0))
                .collect();
            let b = [0.1, -0.2, 0.3];
            let w = faer::MatRef::from_row_major_slice(&w, outputs, window * features);
            let head = WindowHead::new(w, &b, window);
            let ring: Vec<f32> = (0..window * features)
                .map(|_| rng.random_range(-3.0..3.0))
                .collect();
            for newest in 0..window {
                for filled in 0..=window {
                    let (mut wide, mut plain) = ([0.0f32; 3], [0.0f32; 3]);
                    head.apply(&ring, newest, filled, &mut wide);
                    head.apply_lanes(&ring, newest, filled, &mut plain);
                    assert_eq!(
                        wide.map(f32::to_bits),
                        plain.map(f32::to_bits),
                        "{features} features, newest {newest}, filled {filled}"
                    );
                }
            }
        }
    }
}
