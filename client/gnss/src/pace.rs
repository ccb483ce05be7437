//! [`Pacer`]: replays a recorded log at its recorded pace, or `speed` times faster.

use std::time::{Duration, Instant};

use crate::input::sleep_unless;

/// A jump in the recording's time longer than this (or backwards) starts a new
/// timeline instead of a wait: captures joined together, a receiver that lost its
/// fix for minutes.
pub const MAX_REPLAY_GAP: Duration = Duration::from_secs(10);

/// Spaces out epochs by their receiver times divided by `speed`.
#[derive(Debug)]
pub struct Pacer {
    speed: f64,
    /// A receiver time and the instant it was (or is to be) published.
    anchor: Option<(u64, Instant)>,
    last: Option<u64>,
}

impl Pacer {
    /// A pacer replaying `speed` times faster than recorded; `speed <= 0` does not
    /// wait at all (the caller waits for ghnetd's answers instead).
    pub fn new(speed: f64) -> Self {
        Pacer {
            speed,
            anchor: None,
            last: None,
        }
    }

    /// Sleeps until the epoch recorded at `time_ns` is due. Epochs without a time
    /// go out at once. `false` if `stop` became true meanwhile.
    pub fn wait(&mut self, time_ns: Option<u64>, stop: &dyn Fn() -> bool) -> bool {
        let Some(t) = time_ns.filter(|_| self.speed > 0.0) else {
            return true;
        };
        let jump = self
            .last
            .is_none_or(|last| t < last || t - last > MAX_REPLAY_GAP.as_nanos() as u64);
        self.last = Some(t);
        let Some((t0, at)) = self.anchor.filter(|_| !jump) else {
            self.anchor = Some((t, Instant::now()));
            return true;
        };
        let due = at + Duration::from_secs_f64((t - t0) as f64 / 1e9 / self.speed);
        sleep_unless(due.saturating_duration_since(Instant::now()), stop)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn waits_by_recorded_time_over_speed() {
        let mut p = Pacer::new(10.0);
        let start = Instant::now();
        let s = 1_000_000_000u64;
        for t in [0, s, 2 * s, s / 2 /* backwards: new timeline */, s] {
            assert!(p.wait(Some(100 * s + t), &|| false));
        }
        let took = start.elapsed();
        // 0.1 s + 0.1 s, then a restart, then 0.05 s: at least 0.25 s.
        assert!(took >= Duration::from_millis(250), "{took:?}");
        assert!(Pacer::new(0.0).wait(Some(5), &|| false));
        assert!(!Pacer::new(1.0).wait_twice_with_stop());
    }

    impl Pacer {
        fn wait_twice_with_stop(&mut self) -> bool {
            self.wait(Some(0), &|| true);
            self.wait(Some(5_000_000_000), &|| true)
        }
    }
}
