//! Maps iceoryx2's limit errors to [`OpenError::Limit`] and [`OpenError::Mismatch`],
//! naming the setting(s) to raise.
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

use crate::error::{OpenError, Setting, SettingMismatch};
use crate::settings::{EventFactory, Message, PubSubFactory, ServiceSettings};

const PUBLISHERS: Setting = Setting::MaxPublishers;
const SUBSCRIBERS: Setting = Setting::MaxSubscribers;
const NODES: Setting = Setting::MaxNodes;
const BUFFER: Setting = Setting::SubscriberBufferSize;

fn limit(service: &str, problem: String, setting: Setting) -> Option<OpenError> {
    Some(OpenError::Limit {
        service: service.to_owned(),
        problem,
        setting,
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
    let mut note = |setting, what, asked, created| {
        if created < asked && !settings.iter().any(|m| m.setting == setting) {
            settings.push(SettingMismatch {
                setting,
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

/// How an existing service refused to be opened, when it is a limit.
pub(crate) enum Refusal {
    /// All its node slots are in use.
    NodesFull,
    /// It was created with smaller limits than asked for.
    Smaller,
}

impl Refusal {
    /// The limit behind a publish-subscribe open error, if it is one.
    pub(crate) fn of_pubsub(e: &PublishSubscribeOpenOrCreateError) -> Option<Self> {
        use PublishSubscribeOpenError as E;
        match e {
            PublishSubscribeOpenOrCreateError::PublishSubscribeOpenError(e) => match e {
                E::ExceedsMaxNumberOfNodes => Some(Self::NodesFull),
                E::DoesNotSupportRequestedAmountOfPublishers
                | E::DoesNotSupportRequestedAmountOfSubscribers
                | E::DoesNotSupportRequestedAmountOfNodes
                | E::DoesNotSupportRequestedMinBufferSize => Some(Self::Smaller),
                _ => None,
            },
            _ => None,
        }
    }

    /// The limit behind an event open error, if it is one.
    pub(crate) fn of_event(e: &EventOpenOrCreateError) -> Option<Self> {
        let EventOpenOrCreateError::EventOpenError(e) = e else {
            return None;
        };
        match e {
            EventOpenError::ExceedsMaxNumberOfNodes => Some(Self::NodesFull),
            EventOpenError::DoesNotSupportRequestedAmountOfNotifiers
            | EventOpenError::DoesNotSupportRequestedAmountOfListeners
            | EventOpenError::DoesNotSupportRequestedAmountOfNodes => Some(Self::Smaller),
            _ => None,
        }
    }

    /// The error that names the limit (the settings that differ, or the node slots),
    /// `None` if the service's settings cannot be read back.
    pub(crate) fn error<T: Message>(
        self,
        node: &Node<ipc::Service>,
        service: &ServiceName,
        s: &ServiceSettings,
    ) -> Option<OpenError> {
        match self {
            Self::NodesFull => nodes_full(service, s),
            Self::Smaller => mismatch::<T>(node, service, s),
        }
    }
}

/// `e` is one of the four port creation errors; anything else is not a limit.
pub(crate) fn port<T: Message, E: std::error::Error + 'static>(
    name: &str,
    pubsub: &PubSubFactory<T>,
    event: &EventFactory,
    e: &E,
) -> Option<OpenError> {
    let any = e as &dyn std::error::Error;
    let pubsub = pubsub.static_config();
    let event = event.static_config();
    let full = |n: usize, what: &str| format!("all {n} {what} slots in use");
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
