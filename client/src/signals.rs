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

/// A stop request that stays requested: [`termination_requested`] clears the signal
/// it reads, so a program that asks from several places (its input loop, its output
/// wait) latches the first answer here and sees `true` everywhere after.
#[derive(Debug)]
pub struct StopLatch(std::cell::Cell<bool>);

impl StopLatch {
    /// Installs iceoryx2's capturing handlers now, before anything blocks (the first
    /// [`termination_requested`] call does), keeping a signal that already came.
    pub fn new() -> Self {
        Self(std::cell::Cell::new(termination_requested()))
    }

    /// Whether a stop was requested, now or before. `on_first` runs once, when this
    /// call is the one that sees the signal (e.g. to log it); not for a signal
    /// latched by [`new`](Self::new).
    pub fn poll(&self, on_first: impl FnOnce()) -> bool {
        if !self.0.get() && termination_requested() {
            on_first();
            self.0.set(true);
        }
        self.0.get()
    }
}

impl Default for StopLatch {
    fn default() -> Self {
        Self::new()
    }
}
