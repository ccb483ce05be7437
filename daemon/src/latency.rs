//! Recent processing times of one source, for the stats percentiles: a fixed ring the
//! loop writes (nothing allocated per sample) and the stats snapshot copies.

/// Processing times kept per source for the stats percentiles (the most recent ones).
pub(crate) const LATENCY_WINDOW: usize = 1024;

/// Recent processing times of one source, a ring owned by the loop (allocated once
/// per source; writing into it allocates nothing).
pub(crate) struct LatencyRing {
    ns: Box<[u64; LATENCY_WINDOW]>,
    len: usize,
    next: usize,
    /// Times pushed since the ring was made, so a copy can take only what is new.
    pushed: u64,
}

impl LatencyRing {
    /// Times in the ring (at most [`LATENCY_WINDOW`]).
    pub(crate) fn len(&self) -> usize {
        self.len
    }

    /// Times pushed since the ring was made.
    pub(crate) fn pushed(&self) -> u64 {
        self.pushed
    }

    /// A copy of the whole window.
    pub(crate) fn copy(&self) -> Box<[u64; LATENCY_WINDOW]> {
        self.ns.clone()
    }

    pub(crate) fn new() -> Self {
        Self {
            ns: Box::new([0; LATENCY_WINDOW]),
            len: 0,
            next: 0,
            pushed: 0,
        }
    }

    pub(crate) fn push(&mut self, ns: u64) {
        self.ns[self.next] = ns;
        self.next = (self.next + 1) % LATENCY_WINDOW;
        self.len = (self.len + 1).min(LATENCY_WINDOW);
        self.pushed += 1;
    }

    /// Brings `copy` (a copy of this ring made when it had `seen` pushes) up to date
    /// and returns the count to pass next time. Copies only the slots written since:
    /// the loop refreshes a source's snapshot on every wake-up, and copying the whole
    /// window each time cost more than the model's head. A `seen` ahead of this ring
    /// (the source's state was made anew) copies everything.
    pub(crate) fn update(&self, copy: &mut [u64; LATENCY_WINDOW], seen: u64) -> u64 {
        let new = self
            .pushed
            .checked_sub(seen)
            .map_or(LATENCY_WINDOW, |n| n.min(LATENCY_WINDOW as u64) as usize);
        let start = (self.next + LATENCY_WINDOW - new) % LATENCY_WINDOW;
        let first = new.min(LATENCY_WINDOW - start);
        copy[start..start + first].copy_from_slice(&self.ns[start..start + first]);
        copy[..new - first].copy_from_slice(&self.ns[..new - first]);
        self.pushed
    }
}

#[cfg(test)]
mod tests {
    use super::{LatencyRing, LATENCY_WINDOW};

    /// A copy brought up to date now and then, over wrap-arounds and bursts longer
    /// than the window, equals the ring; a fresh ring behind the copy replaces it.
    #[test]
    fn latency_copy_takes_what_is_new() {
        let mut ring = LatencyRing::new();
        let mut copy = Box::new([0u64; LATENCY_WINDOW]);
        let mut seen = 0;
        let mut v = 1u64;
        for burst in [1usize, 3, 700, 1, 1500, 1023, 1024, 1025, 5, 2048, 17] {
            for _ in 0..burst {
                ring.push(v);
                v += 1;
            }
            seen = ring.update(&mut copy, seen);
            assert_eq!(copy[..], ring.ns[..], "after a burst of {burst}");
        }
        let mut fresh = LatencyRing::new();
        fresh.push(7);
        seen = fresh.update(&mut copy, seen);
        assert_eq!((seen, &copy[..]), (1, &fresh.ns[..]));
    }
}
