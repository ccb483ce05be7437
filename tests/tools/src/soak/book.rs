//! Exactly-once bookkeeping of a soak: per source and transport, how often each
//! sequence number arrived, and whether the two transports carried the same bytes.

use std::collections::HashMap;
use std::fmt;
use std::sync::{Arc, Mutex, MutexGuard};

use ghnet_client::{HeadingEstimate, HeadingStatus};

/// The two transports a heading arrives on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Transport {
    /// Shared memory, `<prefix>/<source>/heading` service.
    Iceoryx2 = 0,
    /// Zenoh key `<prefix>/<source>/heading`.
    Zenoh = 1,
}

impl Transport {
    fn other(self) -> Self {
        match self {
            Transport::Iceoryx2 => Transport::Zenoh,
            Transport::Zenoh => Transport::Iceoryx2,
        }
    }
}

/// Per source: how often each seq arrived on each transport, and the values waiting
/// for their twin on the other transport.
#[derive(Debug)]
pub(crate) struct SourceBook {
    /// `counts[t][seq]`, saturating at 255.
    counts: [Vec<u8>; 2],
    unexpected: [u64; 2],
    /// First arrival of a seq on one transport, until it arrives on the other.
    pending: HashMap<u64, (Transport, [u8; HeadingEstimate::SIZE])>,
    pub(crate) compared: u64,
    pub(crate) mismatches: u64,
}

/// Exactly-once bookkeeping of one soak, shared by the iceoryx2 collector and the
/// Zenoh callback (behind a mutex: about 2000 short updates a second at 100 × 10 Hz).
#[derive(Debug)]
pub struct Book {
    pub(crate) sources: Vec<SourceBook>,
    /// Distinct seqs answered so far, per transport (progress and drain).
    pub(crate) unique: [u64; 2],
    /// Status `Stale` messages (not answers; see the shared contract).
    pub(crate) stale: u64,
    /// Zenoh headings of sources that are not ours (same prefix, other publishers).
    pub(crate) foreign: u64,
    /// Zenoh payloads that did not decode.
    pub(crate) undecodable: u64,
    /// Sample timestamp → receipt, µs, per transport.
    pub(crate) latency_us: [Vec<u32>; 2],
}

impl Book {
    /// Room for `planned` seqs of `sources` sources.
    pub fn new(sources: usize, planned: u64) -> Self {
        let per = || SourceBook {
            counts: [vec![0; planned as usize], vec![0; planned as usize]],
            unexpected: [0; 2],
            pending: HashMap::new(),
            compared: 0,
            mismatches: 0,
        };
        Self {
            sources: (0..sources).map(|_| per()).collect(),
            unique: [0; 2],
            stale: 0,
            foreign: 0,
            undecodable: 0,
            latency_us: [Vec::new(), Vec::new()],
        }
    }

    /// Records one heading of source `index` received on `t`.
    pub fn record(&mut self, t: Transport, index: usize, h: &HeadingEstimate) {
        if h.heading_status() == Some(HeadingStatus::Stale) {
            self.stale += 1;
            return;
        }
        let latency_us = ghnet_testkit::now_ns().saturating_sub(h.timestamp_ns) / 1000;
        self.latency_us[t as usize].push(latency_us.min(u64::from(u32::MAX)) as u32);
        let Some(s) = self.sources.get_mut(index) else {
            return;
        };
        let Some(c) = s.counts[t as usize].get_mut(h.seq as usize) else {
            s.unexpected[t as usize] += 1;
            return;
        };
        let first = *c == 0;
        *c = c.saturating_add(1);
        if !first {
            return;
        }
        self.unique[t as usize] += 1;
        let bytes = h.to_le_bytes();
        match s.pending.remove(&h.seq) {
            Some((from, twin)) if from == t.other() => {
                s.compared += 1;
                s.mismatches += u64::from(twin != bytes);
            }
            _ => {
                s.pending.insert(h.seq, (t, bytes));
            }
        }
    }

    /// Distinct seqs answered on `t` so far, all sources.
    pub fn unique(&self, t: Transport) -> u64 {
        self.unique[t as usize]
    }

    /// Exactly-once accounting of source `index` on `t` for seqs `0..sent`.
    pub fn tally(&self, index: usize, t: Transport, sent: u64) -> Tally {
        let s = &self.sources[index];
        let counts = &s.counts[t as usize];
        let (inside, after) = counts.split_at((sent as usize).min(counts.len()));
        Tally {
            lost: inside.iter().filter(|&&c| c == 0).count() as u64,
            duplicates: inside.iter().map(|&c| u64::from(c.saturating_sub(1))).sum(),
            unexpected: s.unexpected[t as usize] + after.iter().map(|&c| u64::from(c)).sum::<u64>(),
        }
    }
}

pub(crate) type SharedBook = Arc<Mutex<Book>>;

pub(crate) fn lock(book: &SharedBook) -> MutexGuard<'_, Book> {
    // A panicking receiver would poison it; the counts are still the best we have.
    book.lock().unwrap_or_else(|e| e.into_inner())
}

/// Exactly-once accounting of the answers to sequence numbers `0..sent`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Tally {
    /// Sequence numbers in `0..sent` that got no answer.
    pub lost: u64,
    /// Extra answers to a sequence number that was already answered.
    pub duplicates: u64,
    /// Answers whose sequence number was never sent (crossed sources, corruption).
    pub unexpected: u64,
}

impl Tally {
    /// No loss, no duplicate, nothing unexpected.
    pub fn is_exactly_once(&self) -> bool {
        *self == Tally::default()
    }

    /// Field-wise sum.
    pub fn add(&mut self, o: &Tally) {
        self.lost += o.lost;
        self.duplicates += o.duplicates;
        self.unexpected += o.unexpected;
    }
}

impl fmt::Display for Tally {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "lost {}  duplicates {}  unexpected {}",
            self.lost, self.duplicates, self.unexpected
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn heading(seq: u64, heading_deg: f32, status: HeadingStatus) -> HeadingEstimate {
        HeadingEstimate {
            seq,
            // The same on both transports, as ghnetd sends it.
            timestamp_ns: 1_700_000_000_000_000_000 + seq,
            heading_deg,
            status: status.as_u32(),
            ..HeadingEstimate::from_le_bytes(&[0; HeadingEstimate::SIZE])
        }
    }

    #[test]
    fn book_counts_loss_duplicates_unexpected_and_mismatches() {
        let mut b = Book::new(2, 4);
        let ok = HeadingStatus::Ok;
        for seq in [0, 1, 1, 3, 9] {
            b.record(Transport::Iceoryx2, 0, &heading(seq, 1.0, ok));
        }
        for seq in [0, 1, 2, 3] {
            // seq 3 differs between the transports.
            let deg = if seq == 3 { 2.0 } else { 1.0 };
            b.record(Transport::Zenoh, 0, &heading(seq, deg, ok));
        }
        b.record(Transport::Zenoh, 1, &heading(0, 1.0, HeadingStatus::Stale));
        let t = b.tally(0, Transport::Iceoryx2, 4);
        assert_eq!((t.lost, t.duplicates, t.unexpected), (1, 1, 1));
        assert!(b.tally(0, Transport::Zenoh, 4).is_exactly_once());
        assert_eq!((b.sources[0].compared, b.sources[0].mismatches), (3, 1));
        assert_eq!(b.stale, 1);
        assert_eq!(b.tally(1, Transport::Zenoh, 4).lost, 4);
        // Interrupted after 2 samples: seq 3 was never sent, so it is unexpected.
        let t = b.tally(0, Transport::Iceoryx2, 2);
        assert_eq!((t.lost, t.duplicates, t.unexpected), (0, 1, 2));
    }
}
