//! Where answers go: per source the iceoryx2 heading service and, with
//! `zenoh.enabled`, the Zenoh key `<prefix>/<source>/heading` (`remote::ZenohOutput`),
//! both made in `Daemon::open_source`. The event loop only sees the trait.

use ghnet_client::{HeadingEstimate, HeadingPublisher, SendError};

/// Where an answer stands in one round of the loop (up to 128 answers of the sources
/// that woke together, published back to back, then [`HeadingOutput::flush`] per
/// source).
///
/// An output that pays per message sent (Zenoh: a TCP segment and a thread wake-up
/// each) batches the answers followed by more and sends at the last one, so a burst
/// costs one send and a lone answer (one sample in flight, the normal case) goes out
/// at once, as before.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Burst {
    /// More answers of this round follow.
    More,
    /// The last answer of the round (or the only one).
    Last,
}

impl Burst {
    /// The position of answer `i` of `n` in a round.
    pub(crate) fn of(i: usize, n: usize) -> Self {
        if i + 1 < n {
            Self::More
        } else {
            Self::Last
        }
    }
}

/// One destination for a source's answers. Created once per source; `publish` runs
/// on the per-sample path and must not allocate on success.
pub(crate) trait HeadingOutput {
    /// Short name for logs, e.g. `iceoryx2`.
    fn kind(&self) -> &'static str;
    /// Delivers one answer; `burst` says whether more of the same round follow.
    fn publish(&self, answer: &HeadingEstimate, burst: Burst) -> Result<(), OutputError>;
    /// Called once after a batch of answers (one wake-up's worth), e.g. to wake
    /// listeners once instead of per answer.
    fn flush(&self) -> Result<(), OutputError>;
}

/// An output failed; the message is for the log.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub(crate) struct OutputError(#[from] pub(crate) Box<dyn std::error::Error + Send + Sync>);

impl From<SendError> for OutputError {
    fn from(e: SendError) -> Self {
        Self(Box::new(e))
    }
}

/// The iceoryx2 heading service: shared-memory publish, one notify per batch.
impl HeadingOutput for HeadingPublisher {
    fn kind(&self) -> &'static str {
        "iceoryx2"
    }

    /// Shared memory costs nothing per message to send; the one wake-up per round
    /// is `flush`.
    fn publish(&self, answer: &HeadingEstimate, _: Burst) -> Result<(), OutputError> {
        Ok(HeadingPublisher::publish(self, *answer)?)
    }

    fn flush(&self) -> Result<(), OutputError> {
        Ok(self.notify()?)
    }
}

#[cfg(test)]
mod tests {
    use super::Burst;

    #[test]
    fn only_the_last_answer_of_a_round_is_last() {
        assert_eq!(Burst::of(0, 1), Burst::Last);
        let three: Vec<_> = (0..3).map(|i| Burst::of(i, 3)).collect();
        assert_eq!(three, [Burst::More, Burst::More, Burst::Last]);
    }
}
