//! The soak's two receivers, both booking into one [`Book`](super::Book): an iceoryx2
//! thread with one `WaitSet` over every heading listener, and a Zenoh callback
//! subscriber on `<prefix>/*/heading`.

use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, Ordering::Relaxed};
use std::sync::{mpsc, Arc};
use std::thread::JoinHandle;
use std::time::Duration;

use anyhow::Context;
use ghnet_client::zenoh::{self, Wait};
use ghnet_client::{decode_zenoh, HeadingSubscriber, IpcConfig};
use iceoryx2::prelude::*;

use super::book::{lock, SharedBook, Transport};
use super::Options;

/// Both receivers of a soak; the Zenoh one only when Zenoh is checked.
pub(crate) struct Receivers {
    iceoryx2: IceoryxCollector,
    zenoh: Option<ZenohCollector>,
    warmed_up: Arc<AtomicBool>,
}

impl Receivers {
    /// Returns once both listen (and ghnetd has answered a query on the Zenoh
    /// session, so it knows the subscriber).
    pub(crate) fn start(
        opts: &Options,
        names: &[String],
        book: &SharedBook,
    ) -> anyhow::Result<Self> {
        let iceoryx2 = IceoryxCollector::start(&opts.ipc, names, book.clone())?;
        let warmed_up = Arc::new(AtomicBool::new(false));
        let zenoh = match &opts.zenoh_connect {
            Some(endpoint) => {
                let index = (names.iter().enumerate())
                    .map(|(i, n)| (n.clone(), i))
                    .collect();
                let warmup = (opts.warmup_source(), warmed_up.clone());
                let z = ZenohCollector::start(endpoint, &opts.ipc, index, warmup, book.clone())?;
                z.wait_for_daemon(&opts.ipc, endpoint, opts.patience)?;
                Some(z)
            }
            None => None,
        };
        Ok(Self {
            iceoryx2,
            zenoh,
            warmed_up,
        })
    }

    /// Whether a heading of the warm-up source came over Zenoh (always, without Zenoh).
    pub(crate) fn warmed_up(&self) -> bool {
        self.zenoh.is_none() || self.warmed_up.load(Relaxed)
    }

    /// Stops the iceoryx2 thread (after a last drain) and undeclares the Zenoh side.
    pub(crate) fn stop(self) -> anyhow::Result<()> {
        self.iceoryx2.stop()?;
        drop(self.zenoh);
        Ok(())
    }
}

/// One thread, one node, one `WaitSet` over every source's heading listener.
struct IceoryxCollector {
    stop: Arc<AtomicBool>,
    thread: JoinHandle<anyhow::Result<()>>,
}

impl IceoryxCollector {
    /// Returns once every subscriber exists.
    fn start(ipc: &IpcConfig, names: &[String], book: SharedBook) -> anyhow::Result<Self> {
        let stop = Arc::new(AtomicBool::new(false));
        let (ready_tx, ready_rx) = mpsc::channel();
        let (ipc, names, flag) = (ipc.clone(), names.to_vec(), stop.clone());
        // iceoryx2 ports are !Send: everything is made on the thread that uses it.
        let thread = std::thread::spawn(move || -> anyhow::Result<()> {
            let node = NodeBuilder::new()
                .config(&ipc.iceoryx2_config())
                .create::<ipc::Service>()
                .context("cannot create the collector's iceoryx2 node")?;
            let subs: Vec<HeadingSubscriber> = (names.iter())
                .map(|n| HeadingSubscriber::with_node(&node, &ipc, n))
                .collect::<Result<_, _>>()?;
            // The caller owns Ctrl-C (its pacing node); this thread stops on `stop`.
            let waitset = WaitSetBuilder::new()
                .signal_handling_mode(SignalHandlingMode::Disabled)
                .create::<ipc::Service>()
                .context("cannot create the collector's WaitSet")?;
            let guards = (subs.iter())
                .map(|s| waitset.attach_notification(s.listener()))
                .collect::<Result<Vec<_>, _>>()
                .context("cannot attach a heading listener")?;
            ready_tx.send(())?;
            let mut failure = None;
            while !flag.load(Relaxed) && failure.is_none() {
                let on_event = |id: WaitSetAttachmentId<ipc::Service>| {
                    if let Some(i) = guards.iter().position(|g| id.has_event_from(g)) {
                        if let Err(e) = drain(&subs[i], i, &book) {
                            failure = Some(e);
                            return CallbackProgression::Stop;
                        }
                    }
                    CallbackProgression::Continue
                };
                waitset
                    .wait_and_process_once_with_timeout(on_event, Duration::from_millis(100))
                    .context("collector WaitSet failed")?;
            }
            if let Some(e) = failure {
                return Err(e);
            }
            // Whatever arrived without a wake-up we processed.
            for (i, s) in subs.iter().enumerate() {
                drain(s, i, &book)?;
            }
            Ok(())
        });
        if ready_rx.recv().is_err() {
            return Err(thread
                .join()
                .map_err(|_| anyhow::anyhow!("collector panicked"))?
                .unwrap_err());
        }
        Ok(Self { stop, thread })
    }

    fn stop(self) -> anyhow::Result<()> {
        self.stop.store(true, Relaxed);
        self.thread
            .join()
            .map_err(|_| anyhow::anyhow!("collector panicked"))?
    }
}

/// Wake-ups first (or the WaitSet fires again at once), then every buffered heading.
fn drain(sub: &HeadingSubscriber, index: usize, book: &SharedBook) -> anyhow::Result<()> {
    sub.drain_notifications()?;
    let mut book = lock(book);
    while let Some(h) = sub.try_recv()? {
        book.record(Transport::Iceoryx2, index, &h);
    }
    Ok(())
}

/// A Zenoh session connected to ghnetd and one callback subscriber on
/// `<prefix>/*/heading`; undeclared on drop.
struct ZenohCollector {
    _subscriber: zenoh::pubsub::Subscriber<()>,
    session: zenoh::Session,
}

impl ZenohCollector {
    /// Connects and declares the subscriber.
    fn start(
        endpoint: &str,
        ipc: &IpcConfig,
        index: HashMap<String, usize>,
        warmup: (String, Arc<AtomicBool>),
        book: SharedBook,
    ) -> anyhow::Result<Self> {
        let config = ghnet_client::peer_config(&[], &[endpoint.to_owned()])
            .map_err(|e| anyhow::anyhow!("zenoh endpoint {endpoint}: {e}"))?;
        let session = zenoh::open(config)
            .wait()
            .map_err(|e| anyhow::anyhow!("cannot open the Zenoh session: {e}"))?;
        let prefix = format!("{}/", ipc.prefix());
        let suffix = format!("/{}", ghnet_client::names::HEADING_SUFFIX);
        let subscriber = session
            .declare_subscriber(format!("{prefix}*{suffix}"))
            .callback(move |sample| {
                let key = sample.key_expr().as_str();
                let source = key
                    .strip_prefix(&prefix)
                    .and_then(|k| k.strip_suffix(&suffix));
                if source == Some(warmup.0.as_str()) {
                    warmup.1.store(true, Relaxed);
                    return;
                }
                let i = source.and_then(|s| index.get(s).copied());
                let mut book = lock(&book);
                match (i, decode_zenoh(&sample.payload().to_bytes())) {
                    (None, _) => book.foreign += 1,
                    (Some(i), Ok(h)) => book.record(Transport::Zenoh, i, &h),
                    (Some(_), Err(_)) => book.undecodable += 1,
                }
            })
            .wait()
            .map_err(|e| anyhow::anyhow!("cannot declare the Zenoh subscriber: {e}"))?;
        Ok(Self {
            _subscriber: subscriber,
            session,
        })
    }

    /// Returns once ghnetd has answered a query on this session, so it knows the
    /// subscriber (a query travels behind the declarations made before it).
    fn wait_for_daemon(
        &self,
        ipc: &IpcConfig,
        endpoint: &str,
        patience: Duration,
    ) -> anyhow::Result<()> {
        let what = format!(
            "ghnetd answering {} via {endpoint} (is its zenoh.listen there, with the same prefix?)",
            ipc.zenoh_model_key()
        );
        let poll = Duration::from_millis(100);
        ghnet_testkit::poll_until(&what, patience, poll, || {
            ghnet_testkit::model_answers(&self.session, ipc)
        })
    }
}
