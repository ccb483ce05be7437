//! `ghnet_client`: the wire of ghnet — message types, service names and the
//! publish/subscribe helpers that GNSS sources, the `ghnetd` daemon and consumers
//! share. Nothing here depends on the daemon or the model.
//!
//! # Layout
//!
//! - [`wire`] — [`VelocitySample`] (in) and [`HeadingEstimate`] (out): `#[repr(C)]`,
//!   no implicit padding, fixed iceoryx2 type names, a little-endian byte codec for
//!   transports without shared memory. Field tables for other languages are in
//!   `client/README.md`; unit tests pin every offset.
//! - [`names`] — [`IpcConfig`] (service prefix + optional private iceoryx2 config) and
//!   the naming scheme `<prefix>/<source>/velocity` → `<prefix>/<source>/heading`,
//!   with source-name validation and the Zenoh key helper.
//! - [`settings`] — [`SERVICE_SETTINGS`], the one place where service limits and
//!   buffer sizes are chosen (settings of an existing service are minimums, so every
//!   party must ask for the same).
//! - [`endpoint`] — [`Sender`]/[`Receiver`], each a port on a publish-subscribe
//!   service plus one on the paired event service of the same name, so receivers
//!   sleep instead of polling. Aliases: [`VelocityPublisher`], [`HeadingSubscriber`]
//!   (the two a user needs) and [`VelocitySubscriber`], [`HeadingPublisher`] (the
//!   daemon's side).
//! - [`error`] — what opening, sending and receiving can fail with; a limit error
//!   names the [`ServiceSettings`] field to raise ([`Setting`]). `limits` (private)
//!   turns iceoryx2's limit errors into those.
//! - `codec` (feature `zenoh`) — `encode_zenoh`/`decode_zenoh`: a [`HeadingEstimate`]
//!   as the Zenoh payload (bincode 2, fixed-width little-endian: the same 64 bytes as
//!   the iceoryx2 layout); bad bytes are a `DecodeError`, never a panic.
//! - `remote` (feature `zenoh`) — `ZenohHeadingSubscriber`, the `@ghnetd` key names
//!   (presence, stats, model) and `peer_config`, the loopback-only Zenoh config.
//! - [`signals`] — [`termination_requested`] and [`StopLatch`]: Ctrl-C handling for
//!   programs using the helpers (iceoryx2 captures SIGINT/SIGTERM once it is in use).
//! - `cli` (feature `cli`) — `IpcArgs`, the `--service-prefix` and iceoryx2 override
//!   flags every bridge flattens into its command line.
//! - [`waitset`] — [`attach_listeners`] and [`wait_for_listeners`]: which of many receivers woke a `WaitSet`,
//!   by position, for a thread that serves them all.
//! - `testing` (feature `testing`) — `testing::TestNamespace`, a private iceoryx2
//!   namespace per test that cleans up after itself; helpers tests of several crates
//!   share.
//!
//! # Features
//!
//! - `zenoh` (default): the Zenoh modules above, and the `zenoh` re-export. Without
//!   it the crate is iceoryx2 only: a publisher or consumer on shared memory builds
//!   without Zenoh and bincode (`default-features = false`).
//! - `testing`: the `testing` module, for tests of this crate and of its users.
//! - `cli`: the `cli` module (adds clap).
//!
//! # Protocol in one paragraph
//!
//! A source opens `<prefix>/<source>/velocity` and sends [`VelocitySample`]s, each
//! followed by an event notification. `ghnetd` finds the service (statically
//! configured or discovered), answers every sample with exactly one
//! [`HeadingEstimate`] on `<prefix>/<source>/heading` (timestamp and sequence number
//! echoed) and notifies that event service. Everything is `open_or_create` with the
//! same [`SERVICE_SETTINGS`], so start order does not matter; services keep no
//! history, so a message sent before the other side is connected is not seen by it.
//!
//! All processes must use iceoryx2 **0.10.0** exactly (`VersionMismatch` otherwise).
//!
//! ```
//! use ghnet_client::{VelocityPublisher, VelocitySample};
//! # let ns = ghnet_client::testing::TestNamespace::new("doc");
//! # let ipc = ns.ipc();
//! // In production: let ipc = ghnet_client::IpcConfig::default();
//! let gnss = VelocityPublisher::new(&ipc, "gnss0")?;
//! assert_eq!(gnss.service_name(), "ghnet/gnss0/velocity");
//! gnss.send(VelocitySample::new(1, 0, 1.0, 1.0, 0.0))?;  // no daemon needed to send
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

#![warn(missing_docs)]

#[cfg(feature = "cli")]
pub mod cli;
#[cfg(feature = "zenoh")]
pub mod codec;
pub mod endpoint;
pub mod error;
mod limits;
pub mod names;
#[cfg(feature = "zenoh")]
pub mod remote;
pub mod settings;
pub mod signals;
#[cfg(feature = "testing")]
pub mod testing;
pub mod waitset;
pub mod wire;

#[cfg(feature = "zenoh")]
pub use codec::{decode_zenoh, encode_zenoh, DecodeError, ZENOH_HEADING_LEN};
pub use endpoint::{
    HeadingPublisher, HeadingSubscriber, Receiver, Sender, VelocityPublisher, VelocitySubscriber,
};
pub use error::{OpenError, RecvError, SendError, Setting, SettingMismatch};
pub use names::{
    validate_source_name, IpcConfig, NameError, DEFAULT_PREFIX, EXPIRED_CONNECTION_BUFFER,
};
#[cfg(feature = "zenoh")]
pub use remote::{
    peer_config, ZenohHeadingSubscriber, ZenohOpenError, DEFAULT_ZENOH_PORT, ZENOH_TX_QUEUE,
};
pub use settings::{Message, ServiceSettings, SERVICE_SETTINGS};
pub use signals::{termination_requested, StopLatch};
pub use waitset::{attach_listeners, wait_for_listeners};
pub use wire::{flags, CodecError, HeadingEstimate, HeadingStatus, VelocitySample, MODEL_NAME_LEN};

/// The iceoryx2 crate this wire is built on, re-exported so users (and the daemon)
/// name exactly the pinned version's types, e.g. `ghnet_client::iceoryx2::config::Config`.
pub use iceoryx2;
#[cfg(feature = "zenoh")]
/// The Zenoh crate of the Zenoh output (pinned `=1.10.2`, tcp and unix-socket
/// transports only), re-exported so consumers open sessions with the same version.
pub use zenoh;
