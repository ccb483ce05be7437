//! Ctrl-C for programs that use the helpers.
//!
//! iceoryx2 installs *capturing* SIGINT/SIGTERM handlers the first time its signal
//! module is used: by [`termination_requested`] itself, and by some iceoryx2
//! operations, depending on its configuration (zeroing a new shared-memory segment).
//! From then on Ctrl-C no longer kills the process; the signal is only recorded.
//! Creating a [`Sender`](crate::Sender) and sending does *not* reliably do it, so a
//! long-running publisher asks from the start, which also makes the first Ctrl-C
//! behave the same whether or not iceoryx2 got there first:
//!
//! ```no_run
//! # use ghnet_client::{IpcConfig, VelocityPublisher, VelocitySample};
//! let gnss = VelocityPublisher::new(&IpcConfig::default(), "gnss0")?;
//! let mut seq = 0;
//! while !ghnet_client::termination_requested() {
//!     gnss.send(VelocitySample::new(0, seq, 1.0, 0.0, 0.0))?;
//!     seq += 1;
//!     std::thread::sleep(std::time::Duration::from_millis(100));
//! }
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! A consumer waiting in [`Receiver::recv_timeout`](crate::Receiver::recv_timeout)
//! gets [`RecvError::Interrupted`](crate::RecvError::Interrupted) instead
//! ([`Receiver::recv`](crate::Receiver::recv) does not return on a signal).

/// `true` if SIGINT or SIGTERM arrived since the last call.
///
/// Reads (and clears) the signal iceoryx2 recorded; the first call also installs
/// iceoryx2's capturing handlers if nothing has yet, so the behaviour is the same
/// whether or not iceoryx2 already did. One caller per process should poll it.
pub fn termination_requested() -> bool {
    iceoryx2_bb_posix::signal::SignalHandler::termination_requested()
}
