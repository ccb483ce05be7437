//! Round-trip latency as deployed: one sample in flight, the publisher sends and
//! notifies, the receiver sleeps on its event (iceoryx2 listener, or the Zenoh
//! subscriber's channel) — no busy polling anywhere. Measured from just before
//! `send` to the answer in hand, on one clock in this process.

use std::time::{Duration, Instant};

use ghnet_client::zenoh::Session;
use ghnet_client::{
    HeadingStatus, HeadingSubscriber, VelocityPublisher, VelocitySample, ZenohHeadingSubscriber,
};
use ghnet_tools::Percentiles;

use crate::inference::Inference;
use crate::target::{Env, Kind, Spec, Target};
use crate::{info, row, us, Args, Row};

/// Which output the answer is read from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Output {
    Iceoryx2,
    Zenoh,
}

/// Longest wait for one answer before it counts as lost.
const ANSWER_TIMEOUT: Duration = Duration::from_secs(5);

pub struct LatencyRun {
    pub percentiles: Percentiles,
    pub lost: u64,
}

/// A moving sample, so the model runs in full; the speed varies a little per `seq`.
pub fn moving_sample(seq: u64) -> VelocitySample {
    let vn = 3.0 + (seq % 97) as f32 * 0.01;
    VelocitySample::new(ghnet_testkit::now_ns(), seq, vn, 4.0, 0.0)
}

/// Skips answers that are not the one awaited (a `Stale` status, or a late answer
/// to an earlier sample that had timed out).
fn is_answer_to(seq: u64, h: &ghnet_client::HeadingEstimate) -> bool {
    h.seq == seq && h.heading_status() != Some(HeadingStatus::Stale)
}

/// `warmup` then `n` measured round trips through `target` for `source`.
pub fn measure(
    target: &Target,
    session: &Session,
    output: Output,
    source: &str,
    first_seq: u64,
    warmup: u64,
    n: u64,
) -> anyhow::Result<LatencyRun> {
    let ipc = target.ipc().clone();
    let gnss = VelocityPublisher::new(&ipc, source)?;
    let (times, lost) = match output {
        Output::Iceoryx2 => {
            let headings = HeadingSubscriber::new(&ipc, source)?;
            target.wait_until("iceoryx2 connection", Duration::from_secs(30), || {
                gnss.subscriber_count() > 0 && headings.publisher_count() > 0
            })?;
            round_trips(target, &gnss, first_seq, warmup, n, |seq| loop {
                match headings.recv_timeout(ANSWER_TIMEOUT)? {
                    Some(h) if is_answer_to(seq, &h) => return Ok(true),
                    Some(_) => continue,
                    None => return Ok(false),
                }
            })?
        }
        Output::Zenoh => {
            let headings = ZenohHeadingSubscriber::new(session, &ipc, source)
                .map_err(|e| anyhow::anyhow!("{e}"))?;
            target.wait_until("iceoryx2 connection", Duration::from_secs(30), || {
                gnss.subscriber_count() > 0
            })?;
            // The subscriber's declaration travels to the target asynchronously: send
            // until one answer comes back over Zenoh, then drain the rest.
            let mut seq = first_seq;
            let t0 = Instant::now();
            loop {
                target.check_running()?;
                anyhow::ensure!(
                    t0.elapsed() < Duration::from_secs(30),
                    "{}: no heading over Zenoh within 30 s",
                    target.kind.label()
                );
                gnss.send(moving_sample(seq))?;
                seq += 1;
                if let Ok(Some(_)) = headings.recv_timeout(Duration::from_millis(20)) {
                    break;
                }
            }
            while let Ok(Some(_)) = headings.recv_timeout(Duration::from_millis(200)) {}
            round_trips(target, &gnss, seq, warmup, n, |seq| loop {
                match headings.recv_timeout(ANSWER_TIMEOUT) {
                    Ok(Some(h)) if is_answer_to(seq, &h) => return Ok(true),
                    Ok(Some(_)) | Err(_) => continue,
                    Ok(None) => return Ok(false),
                }
            })?
        }
    };
    let percentiles = Percentiles::of(times)
        .ok_or_else(|| anyhow::anyhow!("{}: no answer at all", target.kind.label()))?;
    Ok(LatencyRun { percentiles, lost })
}

/// `warmup` then `n` round trips from sequence number `first`: send one sample,
/// `answer(seq)` waits for its answer (`false`: none within [`ANSWER_TIMEOUT`]).
/// Returns the measured round trips in ns and how many were lost.
fn round_trips(
    target: &Target,
    gnss: &VelocityPublisher,
    first: u64,
    warmup: u64,
    n: u64,
    mut answer: impl FnMut(u64) -> anyhow::Result<bool>,
) -> anyhow::Result<(Vec<u64>, u64)> {
    let mut times = Vec::with_capacity(n as usize);
    let mut lost = 0;
    for i in 0..warmup + n {
        let seq = first + i;
        let sample = moving_sample(seq);
        let t0 = Instant::now();
        gnss.send(sample)?;
        let got = answer(seq)?;
        let dt = t0.elapsed();
        if i >= warmup {
            if got {
                times.push(dt.as_nanos() as u64);
            } else {
                lost += 1;
            }
        }
        if !got {
            target.check_running()?;
        }
    }
    Ok((times, lost))
}

/// Phase 2: latency, four passes (raw echo and ghnetd, each with the iceoryx2 and
/// the Zenoh output), one sample in flight.
pub fn rows(
    args: &Args,
    env: &Env,
    session: &Session,
    endpoint: &str,
    inference: &Inference,
) -> anyhow::Result<Vec<Row>> {
    let runs = measure_all(args, env, session, endpoint)?;
    let of = |k: Kind, o: Output| {
        let found = runs.iter().find(|((kk, oo), _)| *kk == k && *oo == o);
        &found.expect("measured").1
    };
    let mut rows = Vec::new();
    for (output, name) in [(Output::Iceoryx2, "iceoryx2"), (Output::Zenoh, "Zenoh")] {
        let (raw, d) = (of(Kind::Echo, output), of(Kind::Ghnetd, output));
        rows.extend(output_rows(args, name, inference, raw, d));
    }
    Ok(rows)
}

/// The four passes, each against a fresh target.
fn measure_all(
    args: &Args,
    env: &Env,
    session: &Session,
    endpoint: &str,
) -> anyhow::Result<Vec<((Kind, Output), LatencyRun)>> {
    let mut runs = Vec::new();
    let mut seq = 0;
    for kind in [Kind::Echo, Kind::Ghnetd] {
        let spec = Spec {
            kind,
            sources: vec!["lat0".into()],
            discovery: false,
            zenoh_connect: Some(endpoint.to_owned()),
        };
        let t = Target::spawn(env, &spec)?;
        for output in [Output::Iceoryx2, Output::Zenoh] {
            let (warmup, n) = (args.warmup_samples, args.samples);
            let r = measure(&t, session, output, "lat0", seq, warmup, n)?;
            seq += warmup + n + 10_000;
            let label = kind.label();
            eprintln!(
                "latency {label} {output:?}: {} lost {}",
                r.percentiles, r.lost
            );
            runs.push(((kind, output), r));
        }
        t.stop()?;
    }
    Ok(runs)
}

/// The rows of one output: p50 and p99 against their targets, p99.9 / max, losses.
fn output_rows(
    args: &Args,
    name: &str,
    inference: &Inference,
    raw_run: &LatencyRun,
    run: &LatencyRun,
) -> Vec<Row> {
    let (raw, d) = (&raw_run.percentiles, &run.percentiles);
    // A figure of ghnetd against its limit: the raw figure plus an allowance.
    let at_most = |metric: &str, raw: Duration, got: Duration, allowance: (&str, Duration)| {
        let limit = raw + allowance.1;
        let target = format!("≤ raw + {} = {}", allowance.0, us(limit));
        row(metric, us(raw), us(got), target, Some(got <= limit))
    };
    let model_and_10us = inference.p50 + Duration::from_micros(10);
    vec![
        at_most(
            &format!("latency p50, publisher → {{echo, ghnetd}} → {name} subscriber"),
            raw.p50,
            d.p50,
            ("model + 10 µs", model_and_10us),
        ),
        at_most(
            &format!("latency p99 ({name})"),
            raw.p99,
            d.p99,
            ("25 µs", Duration::from_micros(25)),
        ),
        info(
            &format!("latency p99.9 / max ({name})"),
            format!("{} / {}", us(raw.p999), us(raw.max)),
            format!("{} / {}", us(d.p999), us(d.max)),
        ),
        row(
            &format!("latency samples lost ({name}, of {} each)", args.samples),
            raw_run.lost.to_string(),
            run.lost.to_string(),
            "0".into(),
            Some(run.lost == 0),
        ),
    ]
}
