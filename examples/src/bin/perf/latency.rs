//! Round-trip latency as deployed: one sample in flight, the publisher sends and
//! notifies, the receiver sleeps on its event (iceoryx2 listener, or the Zenoh
//! subscriber's channel) — no busy polling anywhere. Measured from just before
//! `send` to the answer in hand, on one clock in this process.

use std::time::{Duration, Instant};

use ghnet_client::zenoh::Session;
use ghnet_client::{
    HeadingStatus, HeadingSubscriber, VelocityPublisher, VelocitySample, ZenohHeadingSubscriber,
};
use ghnet_examples::Percentiles;

use crate::target::Target;

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
    VelocitySample::new(ghnet_examples::now_ns(), seq, vn, 4.0, 0.0)
}

/// Skips answers that are not the one awaited (a `Stale` status, or a late answer
/// to an earlier sample that had timed out).
fn is_answer_to(seq: u64, h: &ghnet_client::HeadingEstimate) -> bool {
    h.seq == seq && h.heading_status() != Some(HeadingStatus::Stale)
}

/// `warmup` then `n` measured round trips through `target` for `source`.
pub fn measure(
    target: &mut Target,
    session: &Session,
    output: Output,
    source: &str,
    first_seq: u64,
    warmup: u64,
    n: u64,
) -> anyhow::Result<LatencyRun> {
    let ipc = target.ipc.clone();
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
    target: &mut Target,
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
