//! One thread waiting on many receivers: which of them woke an iceoryx2 `WaitSet`.

use std::time::Duration;

use iceoryx2::prelude::*;
use iceoryx2::waitset::{WaitSetAttachmentError, WaitSetRunError, WaitSetRunResult};

use crate::{Message, Receiver};

/// Waits on `waitset` for at most `timeout` and appends to `fired` the position in
/// `guards` of every listener that woke it, so a loop over many sources gets indexes
/// into its own list of receivers (iceoryx2 names attachments by id). Attachments not
/// in `guards` (an interval) are left out. Allocates nothing while `fired` has room,
/// so it may sit on a per-sample path.
///
/// Call [`Receiver::drain_notifications`](crate::Receiver::drain_notifications) and
/// then [`Receiver::try_recv`](crate::Receiver::try_recv) on each fired receiver.
pub fn wait_for_listeners(
    waitset: &WaitSet<ipc::Service>,
    guards: &[WaitSetGuard<'_, '_, ipc::Service>],
    timeout: Duration,
    fired: &mut Vec<usize>,
) -> Result<WaitSetRunResult, WaitSetRunError> {
    let on_event = |id: WaitSetAttachmentId<ipc::Service>| {
        if let Some(i) = guards.iter().position(|g| id.has_event_from(g)) {
            fired.push(i);
        }
        CallbackProgression::Continue
    };
    waitset.wait_and_process_once_with_timeout(on_event, timeout)
}

/// Attaches the listener of every receiver in `receivers` to `waitset`, in order, so
/// that a guard's position is its receiver's position: the index
/// [`wait_for_listeners`] reports. The guards detach on drop; keep them for as long as
/// the loop waits. Fails on the first listener the `WaitSet` cannot take (its capacity
/// is the limit).
pub fn attach_listeners<'w, 'a, T: Message + 'a>(
    waitset: &'w WaitSet<ipc::Service>,
    receivers: impl IntoIterator<Item = &'a Receiver<T>>,
) -> Result<Vec<WaitSetGuard<'w, 'a, ipc::Service>>, WaitSetAttachmentError> {
    receivers
        .into_iter()
        .map(|r| waitset.attach_notification(r.listener()))
        .collect()
}
