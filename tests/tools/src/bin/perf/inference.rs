//! The model alone: `Predictor` timed in this process, one sample at a time (what
//! ghnetd does with one sample in flight) and in batches (what it does for sources
//! that wake together).

use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::Context;
use ghnet_inference::{Model, Predictor};
use ghnet_tools::Percentiles;

use crate::{info, us, Row};

/// Per-call time of the model alone.
pub struct Inference {
    pub p50: Duration,
    mean: Duration,
    /// Per-sample time of `predict_batch_with_accuracy`, by batch size.
    batch: Vec<(usize, Duration)>,
}

impl std::fmt::Display for Inference {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "one sample: p50 {} mean {}; batch, per sample:",
            us(self.p50),
            us(self.mean)
        )?;
        for (n, d) in &self.batch {
            write!(f, " {n}: {}", us(*d))?;
        }
        Ok(())
    }
}

/// Times `n` single-sample predictions (after a warm-up), each on its own: the
/// daemon answers one sample at a time when one is in flight.
pub fn time(model: &str, n: usize) -> anyhow::Result<Inference> {
    let model = Arc::new(Model::from_name_or_path(model).map_err(|e| anyhow::anyhow!("{e}"))?);
    let mut predictor = Predictor::new(model);
    let mut times = Vec::with_capacity(n);
    for i in 0..n + 2_000 {
        let vn = 3.0 + (i % 97) as f32 * 0.01;
        let t0 = Instant::now();
        std::hint::black_box(predictor.predict_with_accuracy(
            std::hint::black_box(vn),
            std::hint::black_box(4.0),
            f32::NAN,
        ));
        let dt = t0.elapsed().as_nanos() as u64;
        if i >= 2_000 {
            times.push(dt);
        }
    }
    let mean = Duration::from_nanos(times.iter().sum::<u64>() / n as u64);
    let p = Percentiles::of(times).context("no samples")?;
    // The batch path ghnetd takes when a source has several samples buffered: the
    // median over repetitions of one call, divided by the batch size.
    let mut batch = Vec::new();
    for size in [2usize, 4, 8, 16, 64, 128] {
        let vn: Vec<f32> = (0..size).map(|i| 3.0 + (i % 97) as f32 * 0.01).collect();
        let ve = vec![4.0f32; size];
        let acc = vec![f32::NAN; size];
        let mut out = vec![predictor.predict(1.0, 1.0); size];
        let reps = (n / size).clamp(50, 2_000);
        let mut t = Vec::with_capacity(reps);
        for _ in 0..reps {
            let t0 = Instant::now();
            predictor.predict_batch_with_accuracy(&vn, &ve, &acc, &mut out);
            std::hint::black_box(&out);
            t.push(t0.elapsed().as_nanos() as u64 / size as u64);
        }
        batch.push((size, Percentiles::of(t).context("no samples")?.p50));
    }
    Ok(Inference {
        p50: p.p50,
        mean,
        batch,
    })
}

impl Inference {
    /// The model-alone rows of the table.
    pub fn rows(&self) -> Vec<Row> {
        let batch: Vec<String> = (self.batch.iter())
            .filter(|(n, _)| [4, 16, 128].contains(n))
            .map(|(_, d)| us(*d))
            .collect();
        vec![
            info(
                "model alone: `Predictor::predict_with_accuracy`, p50 (mean)",
                "–".into(),
                format!("{} ({})", us(self.p50), us(self.mean)),
            ),
            info(
                "model alone: `predict_batch_with_accuracy` per sample, batch 4 / 16 / 128 (p50)",
                "–".into(),
                batch.join(" / "),
            ),
        ]
    }
}
