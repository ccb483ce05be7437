//! Where answers go: per source the iceoryx2 heading service and, with
//! `zenoh.enabled`, the Zenoh key `<prefix>/<source>/heading` (`remote::ZenohOutput`),
//! both made in `Daemon::open_source`. The event loop only sees the trait.

use ghnet_client::{HeadingEstimate, HeadingPublisher, SendError};

/// One destination for a source's answers. Created once per source; `publish` runs
/// on the per-sample path and must not allocate on success.
pub(crate) trait HeadingOutput {
    /// Short name for logs, e.g. `iceoryx2`.
    fn kind(&self) -> &'static str;
    /// Delivers one answer.
    fn publish(&self, answer: &HeadingEstimate) -> Result<(), OutputError>;
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

    fn publish(&self, answer: &HeadingEstimate) -> Result<(), OutputError> {
        Ok(HeadingPublisher::publish(self, *answer)?)
    }

    fn flush(&self) -> Result<(), OutputError> {
        Ok(self.notify()?)
    }
}
