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

/// Round trips per block. The passes of echo and ghnetd alternate in blocks of this
/// many (echo first, then ghnetd first, and so on), so a slow minute of the machine
/// falls on both alike instead of on whichever pass ran then.
const BLOCK: u64 = 5_000;

/// Unmeasured round trips at the start of every block after the first (the first
/// has `--warmup-samples`): the other process just had the caches and the cores.
const BLOCK_WARMUP: u64 = 200;

/// Where a probe reads its answers.
enum Headings {
    Iceoryx2(Box<HeadingSubscriber>),
    Zenoh(ZenohHeadingSubscriber),
}

/// One side of the comparison: a publisher into one target and a subscriber of its
/// answers on one output, connected, with the next sequence number to send.
struct Probe<'t> {
    target: &'t Target,
    gnss: VelocityPublisher,
    headings: Headings,
    seq: u64,
    times: Vec<u64>,
    lost: u64,
}

impl<'t> Probe<'t> {
    /// Opens the ports for `source` and waits until answers can flow.
    fn open(
        target: &'t Target,
        session: &Session,
        output: Output,
        source: &str,
    ) -> anyhow::Result<Self> {
        let ipc = target.ipc().clone();
        let gnss = VelocityPublisher::new(&ipc, source)?;
        let headings = match output {
            Output::Iceoryx2 => Headings::Iceoryx2(Box::new(HeadingSubscriber::new(&ipc, source)?)),
            Output::Zenoh => Headings::Zenoh(
                ZenohHeadingSubscriber::new(session, &ipc, source)
                    .map_err(|e| anyhow::anyhow!("{e}"))?,
            ),
        };
        let mut probe = Self {
            target,
            gnss,
            headings,
            // The Zenoh pass goes on counting where the iceoryx2 pass (same target,
            // same source) left off, so the daemon sees no duplicate.
            seq: match output {
                Output::Iceoryx2 => 0,
                Output::Zenoh => 1 << 32,
            },
            times: Vec::new(),
            lost: 0,
        };
        target.wait_until("iceoryx2 connection", Duration::from_secs(30), || {
            probe.gnss.subscriber_count() > 0
                && match &probe.headings {
                    Headings::Iceoryx2(h) => h.publisher_count() > 0,
                    Headings::Zenoh(_) => true,
                }
        })?;
        if let Headings::Zenoh(h) = &probe.headings {
            // The subscriber's declaration travels to the target asynchronously: send
            // until one answer comes back over Zenoh, then drain the rest.
            let t0 = Instant::now();
            loop {
                target.check_running()?;
                anyhow::ensure!(
                    t0.elapsed() < Duration::from_secs(30),
                    "{}: no heading over Zenoh within 30 s",
                    target.kind.label()
                );
                probe.gnss.send(moving_sample(probe.seq))?;
                probe.seq += 1;
                if let Ok(Some(_)) = h.recv_timeout(Duration::from_millis(20)) {
                    break;
                }
            }
            while let Ok(Some(_)) = h.recv_timeout(Duration::from_millis(200)) {}
        }
        Ok(probe)
    }

    /// Waits for the answer to `seq`; `false` if none came within [`ANSWER_TIMEOUT`].
    fn answer(&self, seq: u64) -> anyhow::Result<bool> {
        loop {
            let got = match &self.headings {
                Headings::Iceoryx2(h) => h.recv_timeout(ANSWER_TIMEOUT)?,
                // A payload that is not a heading is not the answer: wait on.
                Headings::Zenoh(h) => match h.recv_timeout(ANSWER_TIMEOUT) {
                    Ok(got) => got,
                    Err(_) => continue,
                },
            };
            match got {
                Some(h) if is_answer_to(seq, &h) => return Ok(true),
                Some(_) => continue,
                None => return Ok(false),
            }
        }
    }

    /// `warmup` then `n` round trips: send one sample, wait for its answer. Keeps the
    /// measured ones (ns) and counts the lost ones.
    fn round_trips(&mut self, warmup: u64, n: u64) -> anyhow::Result<()> {
        for i in 0..warmup + n {
            let seq = self.seq;
            self.seq += 1;
            let t0 = Instant::now();
            self.gnss.send(moving_sample(seq))?;
            let got = self.answer(seq)?;
            let dt = t0.elapsed();
            if i >= warmup {
                if got {
                    self.times.push(dt.as_nanos() as u64);
                } else {
                    self.lost += 1;
                }
            }
            if !got {
                self.target.check_running()?;
            }
        }
        Ok(())
    }

    fn finish(self) -> anyhow::Result<LatencyRun> {
        let label = self.target.kind.label();
        let percentiles = Percentiles::of(self.times)
            .ok_or_else(|| anyhow::anyhow!("{label}: no answer at all"))?;
        Ok(LatencyRun {
            percentiles,
            lost: self.lost,
        })
    }
}

/// `n` measured round trips per target on `output`, the targets taking turns in
/// blocks of [`BLOCK`] (the order reversing every block).
fn interleaved(
    targets: &[&Target],
    session: &Session,
    output: Output,
    warmup: u64,
    n: u64,
) -> anyhow::Result<Vec<LatencyRun>> {
    let mut probes = targets
        .iter()
        .map(|t| Probe::open(t, session, output, "lat0"))
        .collect::<anyhow::Result<Vec<_>>>()?;
    let (mut done, mut block) = (0, 0);
    while done < n {
        let len = BLOCK.min(n - done);
        let warm = if block == 0 { warmup } else { BLOCK_WARMUP };
        let mut order: Vec<usize> = (0..probes.len()).collect();
        if block % 2 == 1 {
            order.reverse();
        }
        for k in order {
            probes[k].round_trips(warm, len)?;
        }
        done += len;
        block += 1;
    }
    probes.into_iter().map(Probe::finish).collect()
}

/// Phase 2: latency, one sample in flight: the raw echo and ghnetd running side by
/// side, for each output their round trips interleaved block by block.
pub fn rows(
    args: &Args,
    env: &Env,
    session: &Session,
    endpoint: &str,
    inference: &Inference,
) -> anyhow::Result<Vec<Row>> {
    let spawn = |kind| {
        let spec = Spec {
            kind,
            sources: vec!["lat0".into()],
            discovery: false,
            zenoh_connect: Some(endpoint.to_owned()),
        };
        Target::spawn(env, &spec)
    };
    let (echo, ghnetd) = (spawn(Kind::Echo)?, spawn(Kind::Ghnetd)?);
    let mut rows = Vec::new();
    for (output, name) in [(Output::Iceoryx2, "iceoryx2"), (Output::Zenoh, "Zenoh")] {
        let (warmup, n) = (args.warmup_samples, args.samples);
        let targets = [&echo, &ghnetd];
        let runs = interleaved(&targets, session, output, warmup, n)?;
        for (t, r) in targets.iter().zip(&runs) {
            let label = t.kind.label();
            eprintln!(
                "latency {label} {output:?}: {} lost {}",
                r.percentiles, r.lost
            );
        }
        rows.extend(output_rows(args, name, inference, &runs[0], &runs[1]));
    }
    echo.stop()?;
    ghnetd.stop()?;
    Ok(rows)
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
