//! [`Lines`]: splits a byte stream into `\n`-terminated lines for the text protocols
//! (NMEA, gpsd JSON), bounded in length, in any chunking.

use crate::stats::{Skip, Stats};

/// Reassembles lines across pushes. A line longer than `max` bytes is discarded
/// whole and counted once as [`Skip::BadLength`] when its end arrives, so a stream
/// without newlines (binary noise, a wrong baud rate) cannot grow memory.
#[derive(Debug)]
pub(crate) struct Lines {
    pending: Vec<u8>,
    max: usize,
    /// Bytes of an overlong line thrown away so far (its end not seen yet).
    discarded: Option<usize>,
}

impl Lines {
    pub(crate) fn new(max: usize) -> Self {
        Lines {
            pending: Vec::new(),
            max,
            discarded: None,
        }
    }

    /// Calls `line` with every complete line in `bytes` (terminator included: the
    /// callee decides whether those bytes were used or skipped).
    pub(crate) fn push(
        &mut self,
        bytes: &[u8],
        stats: &mut Stats,
        mut line: impl FnMut(&[u8], &mut Stats),
    ) {
        let mut start = 0;
        while let Some(nl) = bytes[start..].iter().position(|&b| b == b'\n') {
            let end = start + nl + 1;
            let piece = &bytes[start..end];
            start = end;
            if let Some(n) = self.discarded.take() {
                stats.skip(Skip::BadLength, n + piece.len());
            } else if self.pending.is_empty() {
                self.deliver(piece, stats, &mut line);
            } else {
                self.pending.extend_from_slice(piece);
                let whole = std::mem::take(&mut self.pending);
                self.deliver(&whole, stats, &mut line);
                self.pending = whole;
                self.pending.clear();
            }
        }
        self.keep_tail(&bytes[start..]);
    }

    fn deliver(&self, whole: &[u8], stats: &mut Stats, line: &mut impl FnMut(&[u8], &mut Stats)) {
        if whole.len() > self.max {
            stats.skip(Skip::BadLength, whole.len());
        } else {
            line(whole, stats);
        }
    }

    fn keep_tail(&mut self, tail: &[u8]) {
        if let Some(n) = &mut self.discarded {
            *n += tail.len();
            return;
        }
        self.pending.extend_from_slice(tail);
        if self.pending.len() > self.max {
            self.discarded = Some(self.pending.len());
            self.pending.clear();
        }
    }

    /// End of stream or connection: an unterminated line is counted as
    /// [`Skip::Truncated`] (or [`Skip::BadLength`] if it was already too long).
    pub(crate) fn finish(&mut self, stats: &mut Stats) {
        if let Some(n) = self.discarded.take() {
            stats.skip(Skip::BadLength, n);
        } else if !self.pending.is_empty() {
            stats.skip(Skip::Truncated, self.pending.len());
            self.pending.clear();
        }
    }
}

/// A line without its `\n` and an optional `\r` before it.
pub(crate) fn trim_eol(line: &[u8]) -> &[u8] {
    let line = line.strip_suffix(b"\n").unwrap_or(line);
    line.strip_suffix(b"\r").unwrap_or(line)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn collect(chunks: &[&[u8]], max: usize) -> (Vec<Vec<u8>>, Stats) {
        let mut lines = Lines::new(max);
        let mut stats = Stats::default();
        let mut got = Vec::new();
        for c in chunks {
            stats.add_input(c.len());
            lines.push(c, &mut stats, |l, _| got.push(l.to_vec()));
        }
        lines.finish(&mut stats);
        (got, stats)
    }

    #[test]
    fn lines_across_chunks_overlong_and_truncated() {
        let (got, stats) = collect(&[b"ab\r\ncd", b"e\n0123456789", b"abc\nxy\nzz"], 8);
        assert_eq!(
            got,
            vec![b"ab\r\n".to_vec(), b"cde\n".to_vec(), b"xy\n".to_vec()]
        );
        assert_eq!(stats.skipped(Skip::BadLength), 1);
        assert_eq!(stats.skipped(Skip::Truncated), 1);
        assert_eq!(stats.bytes_skipped(), 14 + 2);
        assert_eq!(trim_eol(b"ab\r\n"), b"ab");
    }
}
