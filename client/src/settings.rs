//! The iceoryx2 service settings of every ghnet service: the defaults are chosen here
//! and only here ([`SERVICE_SETTINGS`]); a deployment that needs more slots raises
//! them with [`IpcConfig::with_settings`](crate::IpcConfig::with_settings) (a
//! program may expose them under names of its own, e.g. ghnetd's config keys).
//!
//! iceoryx2 fixes a service's limits when the service is *created*; whoever opens it
//! later may ask for at most those limits (asking for more fails with e.g.
//! `DoesNotSupportRequestedAmountOfPublishers`). Since either the publisher, the
//! daemon or a subscriber may be first, all of them create with, and open asking
//! for, the *same* settings: raise a limit in every process of a deployment, not only
//! in ghnetd. Clients in other languages must do the same (see the table in
//! `client/README.md`), or open without requesting limits. When a limit is reached,
//! opening fails with [`OpenError::Limit`](crate::OpenError::Limit), whose message
//! names the setting to raise.

use std::fmt::Debug;

use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::{event, publish_subscribe};

use crate::wire::{HeadingEstimate, VelocitySample};

/// Limits and buffering of a ghnet service pair (publish-subscribe + event of the same
/// name). The same values apply to `…/velocity` and `…/heading`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ServiceSettings {
    /// Publishers per publish-subscribe service. One is normal; the slack covers a
    /// restarted publisher overlapping with its predecessor before dead-node cleanup,
    /// plus a diagnostic tool.
    pub max_publishers: usize,
    /// Subscribers per publish-subscribe service: the daemon (or the consumer) plus
    /// monitors, recorders and tests.
    pub max_subscribers: usize,
    /// Processes (iceoryx2 nodes) that may have the service open at once.
    pub max_nodes: usize,
    /// Samples a subscriber buffers before the oldest is overwritten (safe overflow:
    /// a slow reader never blocks the publisher; lost samples show up as sequence
    /// gaps). 128 is over a second of data at 100 Hz, enough to ride out a stalled
    /// daemon or consumer, and costs only a few hundred KiB of shared memory.
    pub subscriber_buffer_size: usize,
    /// Samples replayed to a late subscriber. Zero: a heading for a sample that
    /// predates the subscriber is stale, and the daemon must not answer old
    /// velocities again after a restart. A publisher that needs its first sample
    /// answered waits for [`subscriber_count`](crate::Sender::subscriber_count) > 0.
    pub history_size: usize,
    /// Notifiers per event service (one per publisher).
    pub max_notifiers: usize,
    /// Listeners per event service (one per subscriber that sleeps).
    pub max_listeners: usize,
}

/// The default settings of every ghnet service (what [`IpcConfig`](crate::IpcConfig)
/// uses unless [`with_settings`](crate::IpcConfig::with_settings) replaces them, and
/// ghnetd's `[ipc]` defaults). Changing them changes the wire contract for services
/// that already exist (opening asks for these minimums).
pub const SERVICE_SETTINGS: ServiceSettings = ServiceSettings {
    max_publishers: 4,
    max_subscribers: 8,
    max_nodes: 16,
    subscriber_buffer_size: 128,
    history_size: 0,
    max_notifiers: 4,
    max_listeners: 8,
};

/// A payload type that travels on a ghnet service. Sealed: only the wire types of
/// this crate.
pub trait Message: Debug + Copy + ZeroCopySend + sealed::Sealed + 'static {
    /// Last level of the service name, `velocity` or `heading`.
    const SERVICE_SUFFIX: &'static str;
    /// The message's sequence number (`seq`), for [`Receiver::missed`](crate::Receiver::missed).
    fn seq(&self) -> u64;
}

impl Message for VelocitySample {
    const SERVICE_SUFFIX: &'static str = "velocity";
    fn seq(&self) -> u64 {
        self.seq
    }
}
impl Message for HeadingEstimate {
    const SERVICE_SUFFIX: &'static str = "heading";
    fn seq(&self) -> u64 {
        self.seq
    }
}

impl Default for ServiceSettings {
    fn default() -> Self {
        SERVICE_SETTINGS
    }
}

impl ServiceSettings {
    /// [`SERVICE_SETTINGS`] with the four limits a deployment may raise (the
    /// [`Setting`](crate::Setting)s). Notifier and listener slots follow publishers and
    /// subscribers one to one, since every [`Sender`](crate::Sender) holds one
    /// notifier and every [`Receiver`](crate::Receiver) one listener.
    pub fn with_limits(
        max_publishers: usize,
        max_subscribers: usize,
        max_nodes: usize,
        subscriber_buffer_size: usize,
    ) -> Self {
        Self {
            max_publishers,
            max_subscribers,
            max_nodes,
            subscriber_buffer_size,
            history_size: SERVICE_SETTINGS.history_size,
            max_notifiers: max_publishers,
            max_listeners: max_subscribers,
        }
    }
}

mod sealed {
    pub trait Sealed {}
    impl Sealed for super::VelocitySample {}
    impl Sealed for super::HeadingEstimate {}
}

pub(crate) type PubSubFactory<T> = publish_subscribe::PortFactory<ipc::Service, T, ()>;
pub(crate) type EventFactory = event::PortFactory<ipc::Service>;

/// Opens or creates the publish-subscribe service `name` with `s`.
pub(crate) fn open_pubsub<T: Message>(
    node: &Node<ipc::Service>,
    name: &ServiceName,
    s: &ServiceSettings,
) -> Result<
    PubSubFactory<T>,
    iceoryx2::service::builder::publish_subscribe::PublishSubscribeOpenOrCreateError,
> {
    node.service_builder(name)
        .publish_subscribe::<T>()
        .max_publishers(s.max_publishers)
        .max_subscribers(s.max_subscribers)
        .max_nodes(s.max_nodes)
        .subscriber_max_buffer_size(s.subscriber_buffer_size)
        .history_size(s.history_size)
        .enable_safe_overflow(true)
        .open_or_create()
}

/// Opens or creates the event service `name` (paired with the publish-subscribe
/// service of the same name) with `s`.
pub(crate) fn open_event(
    node: &Node<ipc::Service>,
    name: &ServiceName,
    s: &ServiceSettings,
) -> Result<EventFactory, iceoryx2::service::builder::event::EventOpenOrCreateError> {
    node.service_builder(name)
        .event()
        .max_notifiers(s.max_notifiers)
        .max_listeners(s.max_listeners)
        .max_nodes(s.max_nodes)
        .open_or_create()
}
