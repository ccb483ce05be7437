//! [`Stamper`]: the sequence numbers and monotonic timestamps the wire requires,
//! and [`to_sample`], an [`Epoch`] as a [`VelocitySample`].

use std::time::{SystemTime, UNIX_EPOCH};

use ghnet_client::{flags, VelocitySample};
use ghnet_receivers::Epoch;

/// Gives each published epoch the next sequence number and a timestamp that never
/// goes backwards (ghnetd answers a sample older than its predecessor with
/// `InvalidInput`).
///
/// The timestamp is the receiver's time when it has one. A receiver time behind the
/// last timestamp (captures joined together, a receiver reset) is held at the last
/// timestamp and counted in [`held_back`](Self::held_back). An epoch without a time
/// (no fix yet, or NMEA without any date) gets the host clock (`CLOCK_REALTIME`,
/// never below the last timestamp) from a live receiver, and the last timestamp (0
/// before any) in a replayed file, whose clock is the receiver's, not ours.
#[derive(Debug)]
pub struct Stamper {
    next_seq: u64,
    last_ts: Option<u64>,
    held_back: u64,
    live: bool,
}

impl Stamper {
    /// A stamper starting at sequence number 0.
    pub fn new(live: bool) -> Self {
        Stamper {
            next_seq: 0,
            last_ts: None,
            held_back: 0,
            live,
        }
    }

    /// The `(seq, timestamp_ns)` of the next sample, for an epoch at `time_ns`.
    pub fn next(&mut self, time_ns: Option<u64>) -> (u64, u64) {
        let ts = match (time_ns, self.last_ts) {
            (Some(t), Some(last)) if t < last => {
                self.held_back += 1;
                last
            }
            (Some(t), _) => t,
            (None, last) if self.live => host_now_ns().max(last.unwrap_or(0)),
            (None, last) => last.unwrap_or(0),
        };
        self.last_ts = Some(ts);
        let seq = self.next_seq;
        self.next_seq += 1;
        (seq, ts)
    }

    /// Samples stamped so far.
    pub fn count(&self) -> u64 {
        self.next_seq
    }

    /// Epochs whose receiver time was behind the previous timestamp.
    pub fn held_back(&self) -> u64 {
        self.held_back
    }
}

fn host_now_ns() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as u64)
}

/// The wire sample of `epoch`: `INVALID` when the receiver marked it so,
/// `V_DOWN_UNKNOWN` without a vertical speed (NMEA), `SIMULATED` for a replayed log.
pub fn to_sample(epoch: &Epoch, seq: u64, timestamp_ns: u64, replay: bool) -> VelocitySample {
    let mut s = VelocitySample::new(
        timestamp_ns,
        seq,
        epoch.v_north,
        epoch.v_east,
        epoch.v_down.unwrap_or(f32::NAN),
    );
    s.speed_accuracy = epoch.speed_accuracy;
    if !epoch.valid {
        s.flags |= flags::INVALID;
    }
    if epoch.v_down.is_none() {
        s.flags |= flags::V_DOWN_UNKNOWN;
    }
    if replay {
        s.flags |= flags::SIMULATED;
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn timestamps_never_go_back() {
        let mut s = Stamper::new(false);
        assert_eq!(s.next(None), (0, 0));
        assert_eq!(s.next(Some(100)), (1, 100));
        assert_eq!(s.next(Some(50)), (2, 100));
        assert_eq!(s.next(None), (3, 100));
        assert_eq!(s.next(Some(200)), (4, 200));
        assert_eq!((s.count(), s.held_back()), (5, 1));
        let mut live = Stamper::new(true);
        let (_, first) = live.next(None);
        assert!(first > 1_700_000_000_000_000_000);
        assert!(
            live.next(None).1 >= first,
            "a live receiver without time follows the host clock"
        );
        assert_eq!(live.next(Some(5)), (2, live.last_ts.unwrap()), "held back");
    }

    #[test]
    fn flags_follow_the_epoch() {
        let mut e = Epoch::invalid(Some(5));
        let s = to_sample(&e, 3, 7, true);
        assert_eq!((s.seq, s.timestamp_ns), (3, 7));
        assert_eq!(
            s.flags,
            flags::INVALID | flags::V_DOWN_UNKNOWN | flags::SIMULATED
        );
        e.valid = true;
        e.v_down = Some(0.5);
        e.speed_accuracy = 0.2;
        let s = to_sample(&e, 0, 0, false);
        assert_eq!((s.flags, s.v_down, s.speed_accuracy), (0, 0.5, 0.2));
    }
}
