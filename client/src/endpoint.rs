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

use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;

use crate::error::{BoxError, OpenError, RecvError, SendError};
use crate::limits::{self, Refusal};
use crate::names::{validate_source_name, IpcConfig, NameError};
use crate::settings::{open_event, open_pubsub, EventFactory, Message, PubSubFactory};
use crate::wire::{HeadingEstimate, VelocitySample};

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
            Refusal::of_pubsub(&e)
                .and_then(|r| r.error::<T>(node, &service_name, settings))
                .unwrap_or_else(|| service_error("publish-subscribe", Box::new(e)))
        })?;
        let event = open_event(node, &service_name, settings).map_err(|e| {
            Refusal::of_event(&e)
                .and_then(|r| r.error::<T>(node, &service_name, settings))
                .unwrap_or_else(|| service_error("event", Box::new(e)))
        })?;
        Ok(Self {
            name,
            pubsub,
            event,
            _node: None,
        })
    }

    /// Creates one port of the pair with `make`; a refusal becomes an [`OpenError`]
    /// that names the service and the port (or the setting that ran out).
    fn port<P, E: std::error::Error + Send + Sync + 'static>(
        &self,
        port: &'static str,
        make: impl FnOnce(&Self) -> Result<P, E>,
    ) -> Result<P, OpenError> {
        make(self).map_err(|e| {
            limits::port(&self.name, &self.pubsub, &self.event, &e).unwrap_or_else(|| {
                OpenError::Port {
                    service: self.name.clone(),
                    port,
                    source: Box::new(e),
                }
            })
        })
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
        let publisher = pair.port("publisher", |p| p.pubsub.publisher_builder().create())?;
        let notifier = pair.port("notifier", |p| p.event.notifier_builder().create())?;
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
        let buffer = ipc.settings().subscriber_buffer_size;
        let subscriber = pair.port("subscriber", |p| {
            p.pubsub.subscriber_builder().buffer_size(buffer).create()
        })?;
        let listener = pair.port("listener", |p| p.event.listener_builder().create())?;
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
