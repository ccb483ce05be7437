//! What the decoders' unit tests share.

use crate::{Epoch, Format, Stats};

impl Format {
    /// Decodes a whole text log as this format, without detection, so a test of one
    /// decoder never passes through another; the stats say what was skipped and why.
    pub(crate) fn decode_text(self, text: &str) -> (Vec<Epoch>, Stats) {
        let d = crate::decode(text.as_bytes(), Some(self));
        (d.epochs, d.stats)
    }
}

/// Every nonzero skip counter as `name=n`, in [`crate::Skip::ALL`] order as the
/// summary line prints them: one assertion covers them all, so a skip nobody expected
/// fails the test too.
pub(crate) fn skips(s: &Stats) -> String {
    let words: Vec<String> = (s.skips())
        .map(|(reason, n)| format!("{}={n}", reason.name()))
        .collect();
    words.join(" ")
}
