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
    pub fn apply(&self, ring: &[f32], newest: usize, filled: usize, out: &mut [f32]) {
        let (w, c) = (self.window, self.features);
        let cols = w * c;
        for (o, y) in out.iter_mut().enumerate().take(self.outputs) {
            let row = &self.w[o * cols..(o + 1) * cols];
            // Eight partial sums: one running sum is a chain of dependent additions
            // the compiler may not reorder; eight independent ones vectorise.
            let mut acc = [0.0f32; 8];
            for k in 0..filled.min(w) {
                let slot = (newest + w - k) % w;
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
