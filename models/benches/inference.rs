//! Inference cost of the shipped model: single-sample and batch paths, through the
//! `Predictor` the daemon uses (validation, network, head, status).
//!
//! `cargo bench -p ghnet-models --bench inference`

use std::hint::black_box;
use std::sync::Arc;

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use ghnet_models::{Model, Prediction, Predictor, Status};

fn inputs(n: usize) -> (Vec<f32>, Vec<f32>) {
    (0..n)
        .map(|i| {
            let a = i as f32 * 0.618;
            let s = 0.05 + (i % 97) as f32 * 0.1;
            (s * a.cos(), s * a.sin())
        })
        .unzip()
}

fn bench(c: &mut Criterion) {
    let model = Arc::new(Model::builtin("ghnet-full").expect("embedded model"));
    let mut p = Predictor::new(model);
    let (vn, ve) = inputs(4096);

    let mut g = c.benchmark_group("single");
    g.throughput(Throughput::Elements(1));
    let mut i = 0;
    g.bench_function("predict", |b| {
        b.iter(|| {
            i = (i + 1) & 4095;
            black_box(p.predict(black_box(vn[i]), black_box(ve[i])))
        })
    });
    g.finish();

    let mut g = c.benchmark_group("batch");
    for n in [16usize, 256, 4096] {
        let mut out = vec![
            Prediction {
                heading_deg: 0.0,
                std_deg: 0.0,
                atan2_deg: 0.0,
                speed: 0.0,
                status: Status::Invalid,
            };
            n
        ];
        g.throughput(Throughput::Elements(n as u64));
        g.bench_with_input(BenchmarkId::new("predict_batch", n), &n, |b, &n| {
            b.iter(|| p.predict_batch(black_box(&vn[..n]), black_box(&ve[..n]), &mut out))
        });
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
