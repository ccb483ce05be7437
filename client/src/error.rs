//! The errors of the endpoints: opening a [`Sender`](crate::Sender) or
//! [`Receiver`](crate::Receiver), sending and receiving. Limit errors name the
//! [`ServiceSettings`](crate::ServiceSettings) field to raise ([`Setting`]), the setting this crate knows.

use iceoryx2::port::listener::ListenerWaitError;
use iceoryx2::port::notifier::NotifierNotifyError;
use iceoryx2::port::{LoanError, ReceiveError};

use crate::names::NameError;

pub(crate) type BoxError = Box<dyn std::error::Error + Send + Sync + 'static>;

/// Opening a [`Sender`](crate::Sender) or [`Receiver`](crate::Receiver) failed.
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
    /// service are in use. The message names the [`Setting`] to raise (a field of
    /// [`ServiceSettings`](crate::ServiceSettings), set with [`IpcConfig::with_settings`](crate::IpcConfig::with_settings)); every process must
    /// use the same limits.
    #[error("{}", limit_text(.service, .problem, &.setting.to_string()))]
    Limit {
        /// Full service name.
        service: String,
        /// What ran out, e.g. `all 8 subscriber slots in use`.
        problem: String,
        /// The setting to raise.
        setting: Setting,
    },
    /// The service exists with smaller limits than this process asks for: another
    /// process created it with other settings. Names *every* setting that is smaller,
    /// so that one change fixes them all; the fix is the same values in every process
    /// of the deployment.
    #[error("{}", mismatch_text(.service, .settings, &|s: Setting| s.to_string()))]
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
    /// The setting.
    pub setting: Setting,
    /// What it limits, e.g. `subscriber slots`.
    pub what: &'static str,
    /// What this process asks for.
    pub asked: usize,
    /// What the service was created with.
    pub created: usize,
}

impl std::fmt::Display for SettingMismatch {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.text(&self.setting.to_string()))
    }
}

impl SettingMismatch {
    /// The message with the setting called `name`.
    fn text(&self, name: &str) -> String {
        let Self {
            what,
            asked,
            created,
            ..
        } = self;
        format!("fewer {what} than the {asked} asked, created with {created} ({name})")
    }
}

impl OpenError {
    /// The message, with every [`Setting`] called by `name` instead of its
    /// `ServiceSettings` field: a program that exposes the settings under names of its
    /// own (ghnetd: its `ipc.*` config keys) reports the error in its own words.
    pub fn naming(&self, name: impl Fn(Setting) -> String) -> String {
        match self {
            OpenError::Limit {
                service,
                problem,
                setting,
            } => limit_text(service, problem, &name(*setting)),
            OpenError::Mismatch { service, settings } => mismatch_text(service, settings, &name),
            other => other.to_string(),
        }
    }
}

fn limit_text(service: &str, problem: &str, name: &str) -> String {
    format!("service `{service}`: {problem} ({name})")
}

fn mismatch_text(
    service: &str,
    settings: &[SettingMismatch],
    name: &dyn Fn(Setting) -> String,
) -> String {
    let items: Vec<String> = settings.iter().map(|m| m.text(&name(m.setting))).collect();
    format!(
        "service `{service}`: exists with smaller limits than this process asks for \
         (every process must use the same): {}",
        items.join("; ")
    )
}

/// One of the four limits of [`ServiceSettings`](crate::ServiceSettings) a deployment may raise, as an open
/// can run into it. Errors name it by its field (`ServiceSettings::max_subscribers`);
/// see [`OpenError::naming`] for other names.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Setting {
    /// [`ServiceSettings::max_publishers`](crate::ServiceSettings::max_publishers) (also the notifier slots).
    MaxPublishers,
    /// [`ServiceSettings::max_subscribers`](crate::ServiceSettings::max_subscribers) (also the listener slots).
    MaxSubscribers,
    /// [`ServiceSettings::max_nodes`](crate::ServiceSettings::max_nodes).
    MaxNodes,
    /// [`ServiceSettings::subscriber_buffer_size`](crate::ServiceSettings::subscriber_buffer_size).
    SubscriberBufferSize,
}

impl Setting {
    /// The [`ServiceSettings`](crate::ServiceSettings) field, e.g. `max_subscribers`.
    pub fn field(self) -> &'static str {
        match self {
            Setting::MaxPublishers => "max_publishers",
            Setting::MaxSubscribers => "max_subscribers",
            Setting::MaxNodes => "max_nodes",
            Setting::SubscriberBufferSize => "subscriber_buffer_size",
        }
    }
}

impl std::fmt::Display for Setting {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "ServiceSettings::{}", self.field())
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
