//! [`Sender`] and [`Receiver`]: one publish-subscribe port plus its paired event port.
//!
//! iceoryx2 subscribers cannot be waited on, so every ghnet service is a *pair*: a
//! publish-subscribe service carrying the data and an event service of the same name
//! whose notifications wake sleepers. A [`Sender`] writes a sample straight into
//! shared memory (`loan_uninit` → `write_payload` → `send`) and then notifies; a
//! [`Receiver`] sleeps on its `Listener` and never busy-polls.
//!
//! The four aliases name the four roles: [`VelocityPublisher`] (a GNSS source),
//! [`VelocitySubscriber`] and [`HeadingPublisher`] (the daemon),
//! [`HeadingSubscriber`] (a consumer).
//!
//! Ports of `ipc::Service` are `!Send` (iceoryx2 keeps an `Rc` inside): create a
//! Sender/Receiver on the thread that uses it.

use std::cell::Cell;
use std::time::{Duration, Instant};

use iceoryx2::port::listener::{Listener, ListenerWaitError};
use iceoryx2::port::notifier::{Notifier, NotifierNotifyError};
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::port::{LoanError, ReceiveError};
use iceoryx2::prelude::*;

use crate::names::{validate_source_name, IpcConfig, NameError};
use crate::settings::{open_event, open_pubsub, EventFactory, Message, PubSubFactory};
use crate::{HeadingEstimate, VelocitySample};

type BoxError = Box<dyn std::error::Error + Send + Sync + 'static>;

/// A GNSS source's side of `<prefix>/<source>/velocity`.
///
/// ```
/// use ghnet_client::{VelocityPublisher, VelocitySample, VelocitySubscriber};
/// # let ns = ghnet_client::testing::TestNamespace::new("doc");
/// # let ipc = ns.ipc();
/// // `ipc` is usually `IpcConfig::default()`; the doc test uses a private namespace.
/// let publisher = VelocityPublisher::new(&ipc, "gnss0")?;
/// // The daemon's side, here only to show the sample arriving.
/// let subscriber = VelocitySubscriber::new(&ipc, "gnss0")?;
/// assert_eq!(publisher.subscriber_count(), 1);
///
/// publisher.send(VelocitySample::new(1_700_000_000_000_000_000, 0, 3.0, 4.0, 0.0))?;
///
/// let got = subscriber.recv_timeout(std::time::Duration::from_secs(1))?.unwrap();
/// assert_eq!((got.seq, got.v_east), (0, 4.0));
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub type VelocityPublisher = Sender<VelocitySample>;

/// The daemon's side of `<prefix>/<source>/velocity`; also handy for recorders.
pub type VelocitySubscriber = Receiver<VelocitySample>;

/// The daemon's side of `<prefix>/<source>/heading`; tests use it to fake a daemon.
pub type HeadingPublisher = Sender<HeadingEstimate>;

/// A consumer's side of `<prefix>/<source>/heading`: one [`HeadingEstimate`] per
/// velocity sample the daemon processed.
///
/// ```
/// use std::time::Duration;
/// use ghnet_client::{HeadingEstimate, HeadingPublisher, HeadingStatus, HeadingSubscriber};
/// # let ns = ghnet_client::testing::TestNamespace::new("doc");
/// # let ipc = ns.ipc();
/// let headings = HeadingSubscriber::new(&ipc, "gnss0")?;
/// assert!(headings.try_recv()?.is_none()); // nothing yet, returns at once
///
/// // Normally ghnetd answers; here we play the daemon.
/// let daemon = HeadingPublisher::new(&ipc, "gnss0")?;
/// let mut answer = HeadingEstimate::from_le_bytes(&[0; HeadingEstimate::SIZE]);
/// answer.seq = 7;
/// answer.heading_deg = 36.87;
/// answer.status = HeadingStatus::Ok.as_u32();
/// daemon.send(answer)?;
///
/// // Sleeps on the event service until the answer is there (or 1 s passes).
/// let h = headings.recv_timeout(Duration::from_secs(1))?.expect("answer");
/// assert_eq!(h.seq, 7);
/// assert_eq!(h.heading_status(), Some(HeadingStatus::Ok));
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub type HeadingSubscriber = Receiver<HeadingEstimate>;

/// Opening a [`Sender`] or [`Receiver`] failed.
#[derive(Debug, thiserror::Error)]
pub enum OpenError {
    /// The source name or prefix breaks the naming rules.
    #[error(transparent)]
    Name(#[from] NameError),
    /// iceoryx2 could not create a node (permissions on the root path, `/dev/shm`).
    #[error("cannot create iceoryx2 node")]
    Node(#[source] iceoryx2::node::NodeCreationFailure),
    /// The service exists with incompatible settings or type (another iceoryx2
    /// version, another payload type, smaller limits), or could not be created.
    #[error("cannot open or create {pattern} service `{service}`")]
    Service {
        /// Full service name.
        service: String,
        /// `publish-subscribe` or `event`.
        pattern: &'static str,
        /// The iceoryx2 error.
        #[source]
        source: BoxError,
    },
    /// A service limit is reached: all publisher, subscriber or node slots of the
    /// service are in use. The message names the ghnetd config key to raise
    /// (`ipc.max_publishers`, `ipc.max_subscribers`, `ipc.max_nodes`,
    /// `ipc.subscriber_buffer`; in Rust clients the same fields of
    /// [`ServiceSettings`](crate::ServiceSettings) via [`IpcConfig::with_settings`]).
    /// Every process must use the same limits.
    #[error("service `{service}`: {problem} ({key})")]
    Limit {
        /// Full service name.
        service: String,
        /// What ran out, e.g. `all 8 subscriber slots in use`.
        problem: String,
        /// The setting to raise, e.g. `ipc.max_subscribers`.
        key: &'static str,
    },
    /// The service exists with smaller limits than this process asks for: another
    /// process created it with other settings. Names *every* setting that is smaller,
    /// so that one change fixes them all; the fix is the same values in every process
    /// of the deployment.
    #[error(
        "service `{service}`: exists with smaller limits than this process asks for \
         (every process must use the same): {}",
        SettingMismatch::list(.settings)
    )]
    Mismatch {
        /// Full service name.
        service: String,
        /// The settings below what this process asks for, at least one.
        settings: Vec<SettingMismatch>,
    },
    /// The port could not be created for another reason (out of memory, resources of
    /// the service missing or inaccessible).
    #[error("cannot create {port} on service `{service}`")]
    Port {
        /// Full service name.
        service: String,
        /// `publisher`, `subscriber`, `notifier` or `listener`.
        port: &'static str,
        /// The iceoryx2 error.
        #[source]
        source: BoxError,
    },
}

/// One setting of an existing service below what this process asks for (see
/// [`OpenError::Mismatch`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SettingMismatch {
    /// The setting, named by its ghnetd config key, e.g. `ipc.max_subscribers` (Rust
    /// clients: the same field of [`ServiceSettings`](crate::ServiceSettings)).
    pub key: &'static str,
    /// What it limits, e.g. `subscriber slots`.
    pub what: &'static str,
    /// What this process asks for.
    pub asked: usize,
    /// What the service was created with.
    pub created: usize,
}

impl std::fmt::Display for SettingMismatch {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let Self {
            key,
            what,
            asked,
            created,
        } = self;
        write!(
            f,
            "fewer {what} than the {asked} asked, created with {created} ({key})"
        )
    }
}

impl SettingMismatch {
    fn list(settings: &[SettingMismatch]) -> String {
        let items: Vec<String> = settings.iter().map(ToString::to_string).collect();
        items.join("; ")
    }
}

/// Sending failed.
#[derive(Debug, thiserror::Error)]
pub enum SendError {
    /// No free sample in the publisher's data segment.
    #[error("cannot loan a sample")]
    Loan(#[source] LoanError),
    /// Delivering the sample to the subscribers failed.
    #[error("cannot deliver the sample")]
    Send(#[source] iceoryx2::port::SendError),
    /// The sample was delivered but the wake-up notification failed.
    #[error("cannot notify listeners")]
    Notify(#[source] NotifierNotifyError),
}

/// Receiving failed.
#[derive(Debug, thiserror::Error)]
pub enum RecvError {
    /// Reading from the publishers' data segments failed.
    #[error("cannot receive a sample")]
    Receive(#[source] ReceiveError),
    /// Waiting on the event service failed.
    #[error("cannot wait for a notification")]
    Wait(#[source] ListenerWaitError),
    /// A signal (e.g. Ctrl-C) interrupted the wait; the caller decides whether to
    /// retry or stop.
    #[error("interrupted by a signal")]
    Interrupted,
}

impl From<ListenerWaitError> for RecvError {
    fn from(e: ListenerWaitError) -> Self {
        match e {
            ListenerWaitError::InterruptSignal => RecvError::Interrupted,
            e => RecvError::Wait(e),
        }
    }
}

fn service_name_for<T: Message>(ipc: &IpcConfig, source: &str) -> Result<String, NameError> {
    validate_source_name(source)?;
    Ok(format!("{}/{}/{}", ipc.prefix(), source, T::SERVICE_SUFFIX))
}

fn create_node(ipc: &IpcConfig, role: &str) -> Result<Node<ipc::Service>, OpenError> {
    // Node names are for `iox2 node list`; a failure to build one is not worth an error.
    let mut builder = NodeBuilder::new().config(&ipc.iceoryx2_config());
    if let Ok(name) = NodeName::new(&format!("ghnet-{role}")) {
        builder = builder.name(&name);
    }
    builder.create::<ipc::Service>().map_err(OpenError::Node)
}

/// The service pair both endpoint kinds hold; the factories keep the services alive
/// for as long as this process uses them.
struct Pair<T: Message> {
    // Field order is drop order: the services before the node they were opened on.
    name: String,
    pubsub: PubSubFactory<T>,
    event: EventFactory,
    /// The endpoint's own node (`new`); `None` on a caller's node (`with_node`).
    _node: Option<Node<ipc::Service>>,
}

impl<T: Message> Pair<T> {
    /// Opens the pair on a node of its own, named after `role` for `iox2 node list`.
    fn open_own(ipc: &IpcConfig, source: &str, role: &str) -> Result<Self, OpenError> {
        validate_source_name(source)?;
        let node = create_node(ipc, &format!("{}-{role}", T::SERVICE_SUFFIX))?;
        let mut pair = Self::open(&node, ipc, source)?;
        pair._node = Some(node);
        Ok(pair)
    }

    fn open(node: &Node<ipc::Service>, ipc: &IpcConfig, source: &str) -> Result<Self, OpenError> {
        let name = service_name_for::<T>(ipc, source)?;
        let service_error = |pattern, e: BoxError| OpenError::Service {
            service: name.clone(),
            pattern,
            source: e,
        };
        // Names passing our validation always fit iceoryx2's rules (tested in names.rs).
        let service_name =
            ServiceName::new(&name).map_err(|e| service_error("publish-subscribe", Box::new(e)))?;
        let settings = ipc.settings();
        let pubsub = open_pubsub::<T>(node, &service_name, settings).map_err(|e| {
            limits::pubsub_open::<T>(node, &service_name, settings, &e)
                .unwrap_or_else(|| service_error("publish-subscribe", Box::new(e)))
        })?;
        let event = open_event(node, &service_name, settings).map_err(|e| {
            limits::event_open::<T>(node, &service_name, settings, &e)
                .unwrap_or_else(|| service_error("event", Box::new(e)))
        })?;
        Ok(Self {
            name,
            pubsub,
            event,
            _node: None,
        })
    }

    fn port_error<E: std::error::Error + Send + Sync + 'static>(
        &self,
        port: &'static str,
    ) -> impl FnOnce(E) -> OpenError + '_ {
        move |e| {
            limits::port(self, &e).unwrap_or_else(|| OpenError::Port {
                service: self.name.clone(),
                port,
                source: Box::new(e),
            })
        }
    }
}

/// Publishing end of a ghnet service pair; see [`VelocityPublisher`] and
/// [`HeadingPublisher`].
pub struct Sender<T: Message> {
    // Field order is drop order: ports before the services and node.
    publisher: Publisher<ipc::Service, T, ()>,
    notifier: Notifier<ipc::Service>,
    pair: Pair<T>,
}

impl<T: Message> Sender<T> {
    /// Creates its own iceoryx2 node, opens or creates the service pair for `source`
    /// (order against the other side does not matter) and creates a publisher and a
    /// notifier on it.
    pub fn new(ipc: &IpcConfig, source: &str) -> Result<Self, OpenError> {
        Self::on(Pair::open_own(ipc, source, "pub")?)
    }

    /// Like [`new`](Self::new) on an existing node, for processes that serve many
    /// sources from one node (the daemon). `node` must have been created with
    /// `ipc.iceoryx2_config()`.
    pub fn with_node(
        node: &Node<ipc::Service>,
        ipc: &IpcConfig,
        source: &str,
    ) -> Result<Self, OpenError> {
        Self::on(Pair::open(node, ipc, source)?)
    }

    fn on(pair: Pair<T>) -> Result<Self, OpenError> {
        let publisher = pair
            .pubsub
            .publisher_builder()
            .create()
            .map_err(pair.port_error("publisher"))?;
        let notifier = pair
            .event
            .notifier_builder()
            .create()
            .map_err(pair.port_error("notifier"))?;
        Ok(Self {
            publisher,
            notifier,
            pair,
        })
    }

    /// Writes `value` into shared memory, delivers it and wakes the listeners: the
    /// normal way to publish one message.
    pub fn send(&self, value: T) -> Result<(), SendError> {
        self.publish(value)?;
        self.notify()
    }

    /// Delivers `value` without waking anyone. For batches: `publish` each message,
    /// then [`notify`](Self::notify) once; the receiver drains everything per wake-up.
    pub fn publish(&self, value: T) -> Result<(), SendError> {
        let sample = self.publisher.loan_uninit().map_err(SendError::Loan)?;
        sample
            .write_payload(value)
            .send()
            .map_err(SendError::Send)?;
        Ok(())
    }

    /// Wakes every listener of the paired event service.
    pub fn notify(&self) -> Result<(), SendError> {
        self.notifier.notify().map_err(SendError::Notify)?;
        Ok(())
    }

    /// Subscribers currently connected to the service (including ones of dead
    /// processes not yet cleaned up). Lets a publisher wait for the daemon before its
    /// first sample, since the services keep no history.
    pub fn subscriber_count(&self) -> usize {
        use iceoryx2::service::port_factory::PortFactory;
        self.pair.pubsub.dynamic_config().number_of_subscribers()
    }

    /// The full service name, e.g. `ghnet/gnss0/velocity`.
    pub fn service_name(&self) -> &str {
        &self.pair.name
    }
}

/// Receiving end of a ghnet service pair; see [`HeadingSubscriber`] and
/// [`VelocitySubscriber`].
///
/// All receive calls return copies (the messages are small `Copy` structs), so no
/// shared-memory sample is held between calls.
pub struct Receiver<T: Message> {
    // Field order is drop order: ports before the services and node.
    subscriber: Subscriber<ipc::Service, T, ()>,
    listener: Listener<ipc::Service>,
    pair: Pair<T>,
    /// Sequence number of the last message returned, for [`missed`](Self::missed).
    /// `Cell`: receiving takes `&self`, and the type is `!Send` anyway.
    last_seq: Cell<Option<u64>>,
    missed: Cell<u64>,
}

impl<T: Message> Receiver<T> {
    /// Creates its own iceoryx2 node, opens or creates the service pair for `source`
    /// and creates a subscriber (buffer
    /// [`subscriber_buffer_size`](crate::ServiceSettings::subscriber_buffer_size) of
    /// `ipc`'s settings, 128 by default) and a listener on it. Fails with
    /// [`OpenError::Limit`] when all subscriber slots of the service are in use.
    pub fn new(ipc: &IpcConfig, source: &str) -> Result<Self, OpenError> {
        Self::on(Pair::open_own(ipc, source, "sub")?, ipc)
    }

    /// Like [`new`](Self::new) on an existing node (see [`Sender::with_node`]).
    pub fn with_node(
        node: &Node<ipc::Service>,
        ipc: &IpcConfig,
        source: &str,
    ) -> Result<Self, OpenError> {
        Self::on(Pair::open(node, ipc, source)?, ipc)
    }

    fn on(pair: Pair<T>, ipc: &IpcConfig) -> Result<Self, OpenError> {
        // Subscriber first, so that a full service reports the subscriber slots (the
        // setting users know) rather than the listener slots that follow them. A
        // message delivered before the listener exists loses only its wake-up: every
        // receive call looks into the buffer before it waits, and the daemon serves
        // every source once after (re)attaching its listeners.
        let subscriber = pair
            .pubsub
            .subscriber_builder()
            .buffer_size(ipc.settings().subscriber_buffer_size)
            .create()
            .map_err(pair.port_error("subscriber"))?;
        let listener = pair
            .event
            .listener_builder()
            .create()
            .map_err(pair.port_error("listener"))?;
        Ok(Self {
            subscriber,
            listener,
            pair,
            last_seq: Cell::new(None),
            missed: Cell::new(0),
        })
    }

    /// Returns the next message if one is buffered, else `None` at once.
    ///
    /// Also consumes pending wake-up notifications when it finds nothing, so a caller
    /// that only polls does not let them pile up.
    pub fn try_recv(&self) -> Result<Option<T>, RecvError> {
        if let Some(v) = self.receive()? {
            return Ok(Some(v));
        }
        self.drain_notifications()?;
        // A message may have landed between the first look and the drain; its
        // notification is gone now, so look once more.
        self.receive()
    }

    /// Sleeps on the event service until a message is there or `timeout` has passed
    /// (`Ok(None)`). Returns [`RecvError::Interrupted`] once SIGINT/SIGTERM has been
    /// recorded ([`crate::termination_requested`]) and no message is waiting: iceoryx2
    /// resumes its wait after a signal, so this is checked on every wake-up and at the
    /// deadline — loop on `recv_timeout` with a short timeout to stay Ctrl-C-aware.
    pub fn recv_timeout(&self, timeout: Duration) -> Result<Option<T>, RecvError> {
        let deadline = Instant::now() + timeout;
        loop {
            if let Some(v) = self.receive()? {
                return Ok(Some(v));
            }
            if crate::termination_requested() {
                return Err(RecvError::Interrupted);
            }
            let now = Instant::now();
            if now >= deadline {
                return Ok(None);
            }
            // A notification sent after `receive` above is still pending in the
            // listener, so this returns at once instead of missing it.
            self.listener.timed_wait(|_| {}, deadline - now)?;
        }
    }

    /// Sleeps on the event service until a message is there. It does not return on
    /// Ctrl-C (iceoryx2 resumes the wait after a signal): programs that must stop on a
    /// signal use [`Receiver::recv_timeout`] in a loop.
    pub fn recv(&self) -> Result<T, RecvError> {
        loop {
            if let Some(v) = self.receive()? {
                return Ok(v);
            }
            self.listener.blocking_wait(|_| {})?;
        }
    }

    /// The listener of the paired event service, to attach to a `WaitSet` when one
    /// thread waits on many receivers (the daemon). After each wake-up call
    /// [`drain_notifications`](Self::drain_notifications) (or the `WaitSet` wakes
    /// again at once) and then [`try_recv`](Self::try_recv) until `None`.
    pub fn listener(&self) -> &Listener<ipc::Service> {
        &self.listener
    }

    /// Consumes pending wake-up notifications without waiting.
    pub fn drain_notifications(&self) -> Result<(), RecvError> {
        self.listener.try_wait(|_| {})?;
        Ok(())
    }

    /// Publishers currently connected to the service (including ones of dead
    /// processes not yet cleaned up). The daemon drops a discovered source when
    /// this reaches zero.
    pub fn publisher_count(&self) -> usize {
        use iceoryx2::service::port_factory::PortFactory;
        self.pair.pubsub.dynamic_config().number_of_publishers()
    }

    /// The full service name, e.g. `ghnet/gnss0/heading`.
    pub fn service_name(&self) -> &str {
        &self.pair.name
    }

    /// Messages this receiver never saw, counted from gaps in the sequence numbers of
    /// consecutive messages (`seq` 4 then 7 adds 2).
    ///
    /// The main cause is a reader that fell behind: iceoryx2's safe overflow lets a
    /// full subscriber buffer overwrite its oldest message instead of blocking the
    /// publisher, and iceoryx2 0.10 tells neither side (the publisher's `send` only
    /// reports how many subscribers got the message). A gap already in the stream
    /// counts too: a source that skipped numbers, or velocity samples the daemon
    /// itself missed (its `gaps` counter). Not counted: messages before the first one
    /// this receiver got, and a restart of the sequence (a number not above the last
    /// one, e.g. a restarted publisher, or a `Stale` heading repeating the last
    /// number); a restarted publisher that continues *above* the old numbers shows as
    /// one large gap.
    pub fn missed(&self) -> u64 {
        self.missed.get()
    }

    fn receive(&self) -> Result<Option<T>, RecvError> {
        let got = self
            .subscriber
            .receive()
            .map_err(RecvError::Receive)?
            .map(|sample| *sample);
        if let Some(v) = &got {
            let seq = v.seq();
            if let Some(last) = self.last_seq.get() {
                if seq > last {
                    self.missed
                        .set(self.missed.get().saturating_add(seq - last - 1));
                }
            }
            self.last_seq.set(Some(seq));
        }
        Ok(got)
    }
}

/// Maps iceoryx2's limit errors to [`OpenError::Limit`] and [`OpenError::Mismatch`],
/// naming the setting(s) to raise.
mod limits {
    use iceoryx2::port::listener::ListenerCreateError;
    use iceoryx2::port::notifier::NotifierCreateError;
    use iceoryx2::port::publisher::PublisherCreateError;
    use iceoryx2::port::subscriber::SubscriberCreateError;
    use iceoryx2::prelude::*;
    use iceoryx2::service::builder::event::{EventOpenError, EventOpenOrCreateError};
    use iceoryx2::service::builder::publish_subscribe::{
        PublishSubscribeOpenError, PublishSubscribeOpenOrCreateError,
    };
    use iceoryx2::service::port_factory::PortFactory;

    use super::{OpenError, Pair, SettingMismatch};
    use crate::settings::{Message, ServiceSettings};

    const PUBLISHERS: &str = "ipc.max_publishers";
    const SUBSCRIBERS: &str = "ipc.max_subscribers";
    const NODES: &str = "ipc.max_nodes";
    const BUFFER: &str = "ipc.subscriber_buffer";

    fn limit(service: &str, problem: String, key: &'static str) -> Option<OpenError> {
        Some(OpenError::Limit {
            service: service.to_owned(),
            problem,
            key,
        })
    }

    fn nodes_full(service: &ServiceName, s: &ServiceSettings) -> Option<OpenError> {
        let problem = format!("all node slots in use ({} requested)", s.max_nodes);
        limit(service.as_str(), problem, NODES)
    }

    /// iceoryx2 reports only the first setting of an existing service that is below
    /// the request. Opening both services of the pair without requirements shows
    /// all of them, so the user fixes every one at once instead of one per attempt.
    /// `None` if neither service can be inspected (e.g. it went away meanwhile).
    fn mismatch<T: Message>(
        node: &Node<ipc::Service>,
        service: &ServiceName,
        s: &ServiceSettings,
    ) -> Option<OpenError> {
        let mut settings: Vec<SettingMismatch> = Vec::new();
        let mut note = |key, what, asked, created| {
            if created < asked && !settings.iter().any(|m| m.key == key) {
                settings.push(SettingMismatch {
                    key,
                    what,
                    asked,
                    created,
                });
            }
        };
        let builder = || node.service_builder(service);
        if let Ok(pubsub) = builder().publish_subscribe::<T>().open() {
            let c = pubsub.static_config();
            note(
                PUBLISHERS,
                "publisher slots",
                s.max_publishers,
                c.max_publishers(),
            );
            note(
                SUBSCRIBERS,
                "subscriber slots",
                s.max_subscribers,
                c.max_subscribers(),
            );
            note(NODES, "node slots", s.max_nodes, c.max_nodes());
            let buffer = c.subscriber_max_buffer_size();
            note(
                BUFFER,
                "subscriber buffer slots",
                s.subscriber_buffer_size,
                buffer,
            );
        }
        if let Ok(event) = builder().event().open() {
            let c = event.static_config();
            note(
                PUBLISHERS,
                "notifier slots",
                s.max_notifiers,
                c.max_notifiers(),
            );
            note(
                SUBSCRIBERS,
                "listener slots",
                s.max_listeners,
                c.max_listeners(),
            );
            note(NODES, "node slots", s.max_nodes, c.max_nodes());
        }
        (!settings.is_empty()).then(|| OpenError::Mismatch {
            service: service.as_str().to_owned(),
            settings,
        })
    }

    pub(super) fn pubsub_open<T: Message>(
        node: &Node<ipc::Service>,
        service: &ServiceName,
        s: &ServiceSettings,
        e: &PublishSubscribeOpenOrCreateError,
    ) -> Option<OpenError> {
        use PublishSubscribeOpenError as E;
        let PublishSubscribeOpenOrCreateError::PublishSubscribeOpenError(e) = e else {
            return None;
        };
        match e {
            E::ExceedsMaxNumberOfNodes => nodes_full(service, s),
            E::DoesNotSupportRequestedAmountOfPublishers
            | E::DoesNotSupportRequestedAmountOfSubscribers
            | E::DoesNotSupportRequestedAmountOfNodes
            | E::DoesNotSupportRequestedMinBufferSize => mismatch::<T>(node, service, s),
            _ => None,
        }
    }

    pub(super) fn event_open<T: Message>(
        node: &Node<ipc::Service>,
        service: &ServiceName,
        s: &ServiceSettings,
        e: &EventOpenOrCreateError,
    ) -> Option<OpenError> {
        use EventOpenError as E;
        let EventOpenOrCreateError::EventOpenError(e) = e else {
            return None;
        };
        match e {
            E::ExceedsMaxNumberOfNodes => nodes_full(service, s),
            E::DoesNotSupportRequestedAmountOfNotifiers
            | E::DoesNotSupportRequestedAmountOfListeners
            | E::DoesNotSupportRequestedAmountOfNodes => mismatch::<T>(node, service, s),
            _ => None,
        }
    }

    /// `e` is one of the four port creation errors; anything else is not a limit.
    pub(super) fn port<T: Message, E: std::error::Error + 'static>(
        pair: &Pair<T>,
        e: &E,
    ) -> Option<OpenError> {
        let any = e as &dyn std::error::Error;
        let pubsub = pair.pubsub.static_config();
        let event = pair.event.static_config();
        let full = |n: usize, what: &str| format!("all {n} {what} slots in use");
        let name = &pair.name;
        if let Some(e) = any.downcast_ref::<PublisherCreateError>() {
            if *e == PublisherCreateError::ExceedsMaxSupportedPublishers {
                return limit(name, full(pubsub.max_publishers(), "publisher"), PUBLISHERS);
            }
        } else if let Some(e) = any.downcast_ref::<SubscriberCreateError>() {
            match e {
                SubscriberCreateError::ExceedsMaxSupportedSubscribers => {
                    return limit(
                        name,
                        full(pubsub.max_subscribers(), "subscriber"),
                        SUBSCRIBERS,
                    )
                }
                SubscriberCreateError::BufferSizeExceedsMaxSupportedBufferSizeOfService => {
                    return limit(
                        name,
                        format!(
                            "subscriber buffer larger than the service's {}",
                            pubsub.subscriber_max_buffer_size()
                        ),
                        BUFFER,
                    )
                }
                _ => {}
            }
        } else if let Some(e) = any.downcast_ref::<NotifierCreateError>() {
            if *e == NotifierCreateError::ExceedsMaxSupportedNotifiers {
                return limit(name, full(event.max_notifiers(), "notifier"), PUBLISHERS);
            }
        } else if let Some(e) = any.downcast_ref::<ListenerCreateError>() {
            if *e == ListenerCreateError::ExceedsMaxSupportedListeners {
                return limit(name, full(event.max_listeners(), "listener"), SUBSCRIBERS);
            }
        }
        None
    }
}
