//! `ghnet bench` (part of the `ghnet` binary, not the library): inference speed measured in
//! one run, next to this core's peak FMA rate measured in the same run.
//!
//! Counting: a sample costs [`Network::macs_per_sample`] multiply-adds of the unpadded
//! folded network (33,648 for `ghnet-epoch`: 2·24 + 24·48 + 48·96 + 96·192 + 192·48 + 48·4),
//! 2 FLOPs each. Bias, GELU (408 per sample) and the zero padding the kernels compute
//! are not counted, so the share of peak understates the work the core does.

use std::hint::black_box;
use std::sync::Arc;
use std::time::{Duration, Instant};

use ghnet_inference::gelu::gelu_inplace_with;
use ghnet_inference::net::Network;
use ghnet_inference::simd::{peak_fma_loop, peak_loop_flops, Kernel};
use ghnet_inference::{Model, Prediction, Predictor};
use serde::Serialize;

/// Batch size of the throughput figures.
const BATCH: usize = 256;

/// Everything `ghnet bench` measures.
#[derive(Debug, Serialize)]
pub struct Report {
    model: String,
    kernel: String,
    macs_per_sample: usize,
    gelus_per_sample: usize,
    /// Best round of the peak FMA loop on the widest kernel, GFLOP/s.
    peak_gflops: f64,
    /// `Network::forward` at batch 256: median round, samples/s.
    batch256_samples_per_s: f64,
    batch256_gflops: f64,
    batch256_share_of_peak: f64,
    /// `Predictor::predict_batch` at batch 256 (validation, network, head, status).
    predictor_batch256_samples_per_s: f64,
    /// `Network::forward_one`: median of individually timed calls, µs.
    single_median_us: f64,
    /// 99th percentile of the same calls, µs.
    single_p99_us: f64,
    /// `Predictor::predict`: median of individually timed calls, µs.
    predictor_single_median_us: f64,
    /// GELU over a batch-256 layer stack's worth of values: GELUs per second.
    gelu_per_s: f64,
}

impl Report {
    /// The report as a Markdown table.
    pub fn to_markdown(&self) -> String {
        format!(
            "| {} ({} kernel) | value |\n|---|---|\n\
             | batch 256, `Network::forward` | {:.0} samples/s |\n\
             | batch 256, GFLOP/s (2 × {} MACs/sample) | {:.1} ({:.0}% of peak) |\n\
             | batch 256, `Predictor::predict_batch` | {:.0} samples/s |\n\
             | single sample, `Network::forward_one`, median (p99) | {:.2} µs ({:.2} µs) |\n\
             | single sample, `Predictor::predict`, median | {:.2} µs |\n\
             | GELU ({} per sample) | {:.0} M/s |\n\
             | peak FMA loop, same run | {:.1} GFLOP/s |",
            self.model,
            self.kernel,
            self.batch256_samples_per_s,
            self.macs_per_sample,
            self.batch256_gflops,
            100.0 * self.batch256_share_of_peak,
            self.predictor_batch256_samples_per_s,
            self.single_median_us,
            self.single_p99_us,
            self.predictor_single_median_us,
            self.gelus_per_sample,
            self.gelu_per_s / 1e6,
            self.peak_gflops,
        )
    }
}

/// Run `f` (which does `work` units) in rounds of about 20 ms for `seconds`, after a
/// warm-up; the units per second of every round.
fn rates(seconds: f64, work: f64, mut f: impl FnMut()) -> Vec<f64> {
    let t = Instant::now();
    let mut calls = 0u64;
    while t.elapsed() < Duration::from_millis(20) {
        f();
        calls += 1;
    }
    let per_round = calls.max(1);
    let end = Instant::now() + Duration::from_secs_f64(seconds);
    let mut out = Vec::new();
    while out.len() < 5 || Instant::now() < end {
        let t = Instant::now();
        for _ in 0..per_round {
            f();
        }
        out.push(work * per_round as f64 / t.elapsed().as_secs_f64());
    }
    out
}

/// Individually timed calls for `seconds` after a warm-up, in µs, sorted.
fn latencies(seconds: f64, mut f: impl FnMut()) -> Vec<f64> {
    for _ in 0..10_000 {
        f();
    }
    let end = Instant::now() + Duration::from_secs_f64(seconds);
    let mut out = Vec::new();
    while out.len() < 1000 || Instant::now() < end {
        let t = Instant::now();
        f();
        out.push(t.elapsed().as_secs_f64() * 1e6);
    }
    out.sort_by(f64::total_cmp);
    out
}

fn quantile(sorted: &[f64], q: f64) -> f64 {
    sorted[((sorted.len() - 1) as f64 * q).round() as usize]
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    quantile(&v, 0.5)
}

/// The predictor (the model's own network, on the widest kernel): single-sample
/// latencies (µs, sorted) and the median batch rate (samples/s).
fn predictor_speed(model: &Arc<Model>, vn: &[f32], ve: &[f32], seconds: f64) -> (Vec<f64>, f64) {
    let mut p = Predictor::new(model.clone());
    let mut i = 0;
    let single = latencies(seconds, || {
        i = (i + 1) & 4095;
        black_box(p.predict(black_box(vn[i]), black_box(ve[i])));
    });
    let mut preds = vec![Prediction::INVALID; BATCH];
    let batch = median(rates(seconds, BATCH as f64, || {
        p.predict_batch(black_box(&vn[..BATCH]), black_box(&ve[..BATCH]), &mut preds);
        black_box(&preds);
    }));
    (single, batch)
}

/// GELUs per second on `kernel`, over one batch's worth of activations.
fn gelu_rate(net: &Network, kernel: Kernel, seconds: f64) -> f64 {
    let n_gelu = net.gelus_per_sample() * BATCH;
    let src: Vec<f32> = (0..n_gelu)
        .map(|i| (i % 1000) as f32 * 0.01 - 5.0)
        .collect();
    let mut buf = src.clone();
    median(rates(seconds / 2.0, n_gelu as f64, || {
        buf.copy_from_slice(&src);
        gelu_inplace_with(kernel, black_box(&mut buf));
    }))
}

/// Measure `model` on `kernel`, `seconds` per measurement.
pub fn run(model: &Arc<Model>, kernel: Kernel, seconds: f64) -> Report {
    let net: Network = model
        .network()
        .expect("ghnet bench times a network; kf has none")
        .clone()
        .with_kernel(kernel);
    let macs = net.macs_per_sample();
    let (vn, ve) = ghnet_lab::sim::spread_velocities(4096);
    let scale = model.meta().input_scale_mps;

    // Peak first and last: the best of both brackets the clock the network ran at.
    let widest = Kernel::detect();
    let iters = 1_000_000;
    let flops = peak_loop_flops(widest, iters) as f64;
    let mut peak = rates(seconds / 2.0, flops, || {
        black_box(peak_fma_loop(widest, black_box(iters)));
    });

    let x = faer::Mat::from_fn(
        2,
        BATCH,
        |i, j| {
            if i == 0 {
                vn[j] / scale
            } else {
                ve[j] / scale
            }
        },
    );
    let mut y = faer::Mat::zeros(net.outputs(), BATCH);
    let mut scratch = net.scratch(BATCH);
    let batch = median(rates(seconds, BATCH as f64, || {
        net.forward(black_box(x.as_ref()), y.as_mut(), &mut scratch);
        black_box(&y);
    }));

    let mut out = vec![0.0f32; net.outputs()];
    let mut i = 0;
    let single = latencies(seconds, || {
        i = (i + 1) & 4095;
        let x = [vn[i] / scale, ve[i] / scale];
        net.forward_one(black_box(&x), &mut out, &mut scratch);
        black_box(&out);
    });

    let (predictor_single, predictor_batch) = predictor_speed(model, &vn, &ve, seconds);
    let gelu = gelu_rate(&net, kernel, seconds);

    peak.extend(rates(seconds / 2.0, flops, || {
        black_box(peak_fma_loop(widest, black_box(iters)));
    }));
    let peak_gflops = peak.iter().copied().fold(0.0, f64::max) / 1e9;
    let gflops = batch * 2.0 * macs as f64 / 1e9;
    Report {
        model: model.name().to_string(),
        kernel: net.kernel().to_string(),
        macs_per_sample: macs,
        gelus_per_sample: net.gelus_per_sample(),
        peak_gflops,
        batch256_samples_per_s: batch,
        batch256_gflops: gflops,
        batch256_share_of_peak: gflops / peak_gflops,
        predictor_batch256_samples_per_s: predictor_batch,
        single_median_us: quantile(&single, 0.5),
        single_p99_us: quantile(&single, 0.99),
        predictor_single_median_us: quantile(&predictor_single, 0.5),
        gelu_per_s: gelu,
    }
}
