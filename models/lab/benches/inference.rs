//! Inference cost of the shipped model, with this core's peak measured in the same run.
//!
//! `cargo bench -p ghnet-lab --bench inference`
//!
//! Groups:
//! - `stream`: one epoch through `StreamPredictor::predict` with a source's history, for
//!   the default model, `kf` and `ghnet-temporal`: the per-sample streaming cost (the temporal
//!   model's target is at most 3 µs median here), inputs cycling over a simulated drive.
//! - `single`: one sample through `Predictor::predict` (validation, network, head, status)
//!   and through `Network::forward_one` on every kernel this CPU has.
//! - `batch`: `Predictor::predict_batch` at 16, 256 and 4096, and `Network::forward` at 256
//!   on every kernel; throughput in samples (elements) per second.
//! - `gflops`: the same `Network::forward` at 256 with throughput counted in FLOPs, so
//!   criterion's "elem/s" reads as FLOP/s: 2 per multiply-add of the unpadded folded net
//!   (33,648 MACs per sample for `ghnet-epoch`; bias, GELU and padding not counted).
//! - `peak`: a loop of nothing but independent register FMAs on each kernel, counted the
//!   same way: its `avx512` figure is this core's peak, and `gflops / peak` is the share.
//! - `gelu`: the vector GELU over one batch-256 pass worth of values (408 per sample).
//!
//! `ghnet bench` prints the same figures (and the share of peak) as one table.

use std::hint::black_box;
use std::sync::Arc;

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use faer::Mat;
use ghnet_inference::gelu::gelu_inplace_with;
use ghnet_inference::simd::{peak_fma_loop, peak_loop_flops, Kernel};
use ghnet_inference::{Epoch, Model, Prediction, Predictor, StreamPredictor};

fn stream(c: &mut Criterion) {
    let p = ghnet_lab::drive::DriveParams {
        tracks: 1,
        ..Default::default()
    };
    let drive: Vec<Epoch> = ghnet_lab::drive::simulate(&p, 3)[0]
        .samples
        .iter()
        .map(|s| Epoch {
            t_s: s.t_s,
            v_north: s.v_north,
            v_east: s.v_east,
            speed_acc: s.speed_acc,
        })
        .collect();
    let span = drive.last().map_or(1.0, |e| e.t_s) + 1.0;
    let mut g = c.benchmark_group("stream");
    g.throughput(Throughput::Elements(1));
    // The default once (it may be one of the other two: criterion refuses repeated ids).
    let mut names = vec![ghnet_inference::DEFAULT_MODEL, "kf", "ghnet-temporal"];
    names.sort_unstable();
    names.dedup();
    for name in names {
        let Ok(model) = Model::builtin(name) else {
            continue;
        };
        let mut sp = StreamPredictor::new(Arc::new(model));
        let mut h = sp.history();
        let (mut i, mut lap) = (0usize, 0.0f64);
        g.bench_function(BenchmarkId::new("predict", name), |b| {
            b.iter(|| {
                i += 1;
                if i == drive.len() {
                    // Time keeps going forward across laps, as a source's would.
                    (i, lap) = (0, lap + span);
                }
                let e = Epoch {
                    t_s: drive[i].t_s + lap,
                    ..drive[i]
                };
                black_box(sp.predict(&mut h, black_box(&e)))
            })
        });
    }
    g.finish();
}

fn bench(c: &mut Criterion) {
    let model = Arc::new(Model::builtin("ghnet-epoch").expect("embedded model"));
    let mut p = Predictor::new(model.clone());
    let (vn, ve) = ghnet_lab::sim::spread_velocities(4096);
    let scale = model.meta().input_scale_mps;
    let macs = model.network().unwrap().macs_per_sample() as u64;

    let mut g = c.benchmark_group("single");
    g.throughput(Throughput::Elements(1));
    let mut i = 0;
    g.bench_function("predict", |b| {
        b.iter(|| {
            i = (i + 1) & 4095;
            black_box(p.predict(black_box(vn[i]), black_box(ve[i])))
        })
    });
    for k in Kernel::available() {
        let net = model.network().unwrap().clone().with_kernel(k);
        let mut s = net.scratch(1);
        let mut out = vec![0.0f32; net.outputs()];
        g.bench_function(BenchmarkId::new("forward_one", k), |b| {
            b.iter(|| {
                i = (i + 1) & 4095;
                let x = [vn[i] / scale, ve[i] / scale];
                net.forward_one(black_box(&x), &mut out, &mut s);
                black_box(&out);
            })
        });
    }
    g.finish();

    let mut g = c.benchmark_group("batch");
    for n in [16usize, 256, 4096] {
        let mut out = vec![Prediction::INVALID; n];
        g.throughput(Throughput::Elements(n as u64));
        g.bench_with_input(BenchmarkId::new("predict_batch", n), &n, |b, &n| {
            b.iter(|| p.predict_batch(black_box(&vn[..n]), black_box(&ve[..n]), &mut out))
        });
    }
    g.finish();

    // `Network::forward` at 256 on every kernel: samples/s in `batch`, FLOP/s in `gflops`.
    let n = 256;
    let x = Mat::from_fn(2, n, |r, j| (if r == 0 { vn[j] } else { ve[j] }) / scale);
    for (group, per_sample) in [("batch", 1), ("gflops", 2 * macs)] {
        let mut g = c.benchmark_group(group);
        g.throughput(Throughput::Elements(n as u64 * per_sample));
        for k in Kernel::available() {
            let net = model.network().unwrap().clone().with_kernel(k);
            let mut s = net.scratch(n);
            let mut y = Mat::zeros(net.outputs(), n);
            g.bench_function(BenchmarkId::new("forward_256", k), |b| {
                b.iter(|| {
                    net.forward(black_box(x.as_ref()), y.as_mut(), &mut s);
                    black_box(&y);
                })
            });
        }
        g.finish();
    }
}

/// The machine's FMA peak and the vectorised GELU per kernel: what the network's
/// GFLOP/s and its activation cost are measured against.
fn kernels(c: &mut Criterion) {
    let model = Model::builtin("ghnet-epoch").expect("embedded model");
    let mut g = c.benchmark_group("peak");
    let iters = 100_000;
    for k in Kernel::available() {
        g.throughput(Throughput::Elements(peak_loop_flops(k, iters)));
        g.bench_function(BenchmarkId::new("fma_loop", k), |b| {
            b.iter(|| black_box(peak_fma_loop(k, black_box(iters))))
        });
    }
    g.finish();

    let mut g = c.benchmark_group("gelu");
    let len = model.network().unwrap().gelus_per_sample() * 256;
    let src: Vec<f32> = (0..len).map(|i| (i % 1000) as f32 * 0.01 - 5.0).collect();
    let mut buf = src.clone();
    g.throughput(Throughput::Elements(len as u64));
    for k in Kernel::available() {
        g.bench_function(BenchmarkId::new("inplace", k), |b| {
            b.iter(|| {
                buf.copy_from_slice(&src);
                gelu_inplace_with(k, black_box(&mut buf));
            })
        });
    }
    g.finish();
}

criterion_group!(benches, stream, bench, kernels);
criterion_main!(benches);
