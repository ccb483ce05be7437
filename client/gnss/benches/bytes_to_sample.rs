//! Bytes in → sample published: decode one receiver epoch (UBX NAV-PVT, an NMEA
//! RMC + VTG + GGA cycle, a gpsd TPV line), stamp it, and `VelocityPublisher::send`
//! it into real iceoryx2 shared memory with a subscriber attached (as ghnetd is).
//! Target: median at most 50 µs per epoch.
//!
//! ```text
//! cargo bench -p ghnet-gnss --bench bytes_to_sample
//! ```

use std::time::{Duration, Instant};

use criterion::{criterion_group, criterion_main, Criterion};
use ghnet_client::testing::TestNamespace;
use ghnet_client::{VelocityPublisher, VelocitySubscriber};
use ghnet_gnss::stamp::{to_sample, Stamper};
use ghnet_receivers::ubx::NavPvt;
use ghnet_receivers::{Decoder, Epoch, Format};

/// Distinct epochs per format: gpsd drops a TPV whose time it has seen, so each
/// iteration needs a new one; the decoder is renewed (untimed) when they run out.
const EPOCHS: usize = 4096;
const T0: u64 = 1_700_000_000_000_000_000;

fn ubx_epochs() -> Vec<Vec<u8>> {
    (0..EPOCHS)
        .map(|i| {
            let epoch = Epoch {
                time_ns: Some(T0 + i as u64 * 100_000_000),
                v_north: 3.0,
                v_east: -1.5,
                v_down: Some(0.1),
                speed_accuracy: 0.25,
                valid: true,
                course_deg: f32::NAN,
                course_accuracy_deg: f32::NAN,
            };
            let mut frame = Vec::new();
            NavPvt::from_epoch(&epoch).write_frame(&mut frame);
            frame
        })
        .collect()
}

fn nmea_sentence(body: &str) -> String {
    let ck = body.bytes().fold(0u8, |x, b| x ^ b);
    format!("${body}*{ck:02X}\r\n")
}

fn nmea_epochs() -> Vec<Vec<u8>> {
    (0..EPOCHS)
        .map(|i| {
            let (h, m, s) = (i / 3600 % 24, i / 60 % 60, i % 60);
            let time = format!("{h:02}{m:02}{s:02}.00");
            let mut cycle = nmea_sentence(&format!(
                "GNRMC,{time},A,4807.03812,N,01131.00000,E,12.345,77.52,261126,,,A,V"
            ));
            cycle += &nmea_sentence("GNVTG,77.52,T,,M,12.345,N,22.863,K,A");
            cycle += &nmea_sentence(&format!(
                "GNGGA,{time},4807.03812,N,01131.00000,E,1,12,0.80,512.3,M,47.1,M,,"
            ));
            cycle.into_bytes()
        })
        .collect()
}

fn gpsd_epochs() -> Vec<Vec<u8>> {
    (0..EPOCHS)
        .map(|i| {
            let (h, m, s) = (10 + i / 3600, i / 60 % 60, i % 60);
            format!(
                "{{\"class\":\"TPV\",\"device\":\"/dev/ttyACM0\",\"status\":2,\"mode\":3,\"time\":\"2026-11-26T{h:02}:{m:02}:{s:02}.000Z\",\"ept\":0.005,\"lat\":48.117302,\"lon\":11.516667,\"altHAE\":559.4,\"altMSL\":512.3,\"epv\":1.6,\"track\":77.52,\"magtrack\":80.1,\"speed\":6.351,\"climb\":-0.02,\"eps\":0.23,\"velN\":1.37,\"velE\":6.2,\"velD\":0.02,\"geoidSep\":47.1,\"eph\":1.1}}\r\n"
            )
            .into_bytes()
        })
        .collect()
}

fn bench(c: &mut Criterion) {
    let ns = TestNamespace::new("gnss_bench");
    let ipc = ns.ipc();
    let publisher = VelocityPublisher::new(&ipc, "bench").expect("publisher");
    // ghnetd's side: attached, never drained (safe overflow, as a busy daemon).
    let _daemon = VelocitySubscriber::new(&ipc, "bench").expect("subscriber");
    let mut group = c.benchmark_group("bytes_to_sample");
    group.measurement_time(Duration::from_secs(5));
    for (name, format, inputs) in [
        ("ubx_nav_pvt", Format::Ubx, ubx_epochs()),
        ("nmea_rmc_vtg_gga", Format::Nmea, nmea_epochs()),
        ("gpsd_tpv", Format::Gpsd, gpsd_epochs()),
    ] {
        group.bench_function(name, |b| {
            b.iter_custom(|iters| {
                let mut decoder = Decoder::new(Some(format));
                let mut stamper = Stamper::new(true);
                let mut epochs = Vec::with_capacity(4);
                let mut total = Duration::ZERO;
                for i in 0..iters as usize {
                    if i % EPOCHS == 0 {
                        decoder = Decoder::new(Some(format));
                    }
                    let bytes = &inputs[i % EPOCHS];
                    let start = Instant::now();
                    decoder.push(bytes, &mut epochs);
                    for e in epochs.drain(..) {
                        let (seq, ts) = stamper.next(e.time_ns);
                        publisher.send(to_sample(&e, seq, ts, false)).expect("send");
                    }
                    total += start.elapsed();
                }
                assert_eq!(stamper.count(), iters, "one sample per epoch");
                total
            })
        });
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
