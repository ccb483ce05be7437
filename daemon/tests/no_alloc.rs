//! ghnetd's serve path adds no allocation per sample to what its libraries make.
//!
//! A counting global allocator counts only on threads that opt in. Two servers answer
//! the same samples, one after the other, each on such a thread:
//! - ghnetd: the real serve path, `ghnetd::run` in-process (iceoryx2 in, the model,
//!   iceoryx2 and Zenoh out, stats snapshot, everything);
//! - raw: a loop making the calls into iceoryx2 and Zenoh that ghnetd's serve path
//!   makes per wake-up and per sample (wait, drain, receive, loan, send, put, notify)
//!   and nothing else: no model, no bookkeeping.
//!
//! Per sample, ghnetd may exceed the raw loop by less than [`MARGIN`]; a single
//! allocation of its own per sample would add 1.0. The raw loop's count is what the
//! libraries allocate (iceoryx2 0.10: one `Rc` per `loan_uninit`, two short `Vec`s per
//! WaitSet wake-up; Zenoh: the payload buffer and its reference count per `put`); the
//! test prints both. Two patterns: one sample in flight (the normal case: the
//! one-sample path) and bursts from several sources that wake together (the batch
//! path: one model call, or a temporal model's staged passes, and one Zenoh batch per
//! round).

mod common;

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering::Relaxed};
use std::sync::Arc;
use std::time::Duration;

use common::{unix_endpoint, wait_until, InProcess, WATCHDOG};
use ghnet_client::iceoryx2::prelude::*;
use ghnet_client::zenoh::{self, Wait};
use ghnet_client::{
    encode_zenoh, wait_for_listeners, HeadingEstimate, HeadingSubscriber, IpcConfig,
    VelocityPublisher, VelocitySample,
};

/// Allowed excess of ghnetd over the raw loop, per sample, both the fewest of
/// several measurements. Covers the wake-ups that differ between two runs (the
/// sources of a burst may wake the loop together or one by one: a few allocations per
/// 128 samples); one allocation per sample is 1.0.
const MARGIN: f64 = 0.25;

use ghnet_client::testing::alloc::{allocations, count_this_thread, CountingAllocator};

#[global_allocator]
static GLOBAL: CountingAllocator = CountingAllocator;

const SOURCES: [&str; 4] = ["a", "b", "c", "d"];
/// Samples per source per burst: a burst of all sources is one full round (128).
const PER_SOURCE: u64 = 32;

/// Allocations per sample on the server's thread, for each pattern.
#[derive(Debug)]
struct PerSample {
    one_in_flight: f64,
    bursts: f64,
}

/// The default model, `kf` and ghnet-temporal (stateful: each sample against its
/// source's history; ghnet-temporal's bursts in staged passes, one sample per source
/// per pass), and the per-epoch model that batches.
#[test]
fn serve_path_allocates_no_more_than_its_libraries() {
    let mut models = vec![
        ghnet_inference::DEFAULT_MODEL,
        "kf",
        "ghnet-temporal",
        "ghnet-epoch",
    ];
    models.sort_unstable();
    models.dedup();
    let raw = measure_raw();
    for model in models {
        let ghnetd = measure_ghnetd(model);
        eprintln!("allocations per sample: ghnetd ({model}) {ghnetd:?}, raw iceoryx2 + Zenoh calls {raw:?}");
        assert!(
            ghnetd.one_in_flight < raw.one_in_flight + MARGIN,
            "{model}, one sample in flight: ghnetd {:.2} vs the libraries' {:.2} per sample",
            ghnetd.one_in_flight,
            raw.one_in_flight
        );
        assert!(
            ghnetd.bursts < raw.bursts + MARGIN,
            "{model}, bursts: ghnetd {:.2} vs the libraries' {:.2} per sample",
            ghnetd.bursts,
            raw.bursts
        );
    }
}

fn measure_ghnetd(model: &str) -> PerSample {
    measure(|driver| {
        let mut daemon = InProcess::start_on(
            "noalloc",
            |c| {
                c.model.name = model.into();
                c.sources.static_sources = SOURCES.map(String::from).to_vec();
                c.sources.discovery = false;
                // No housekeeping, stale message or stats line during the test: they
                // are not per sample.
                c.sources.discovery_interval_ms = 60_000;
                c.sources.stale_after_ms = 0;
            },
            count_this_thread,
        );
        let endpoint = daemon.endpoint.clone();
        let ipc = daemon.ipc();
        driver(ipc, endpoint);
        daemon.stop();
    })
}

fn measure_raw() -> PerSample {
    measure(|driver| {
        let dir = tempfile::tempdir().unwrap();
        let ns = ghnet_client::testing::TestNamespace::new("noallocraw");
        let endpoint = unix_endpoint(dir.path().join("raw.sock"));
        let stop = Arc::new(AtomicBool::new(false));
        let server = std::thread::spawn({
            let (ipc, endpoint, stop) = (ns.ipc(), endpoint.clone(), stop.clone());
            move || raw_server(&ipc, &endpoint, &stop)
        });
        driver(ns.ipc(), endpoint);
        stop.store(true, Relaxed);
        server.join().unwrap();
    })
}

/// Runs `serve`, which starts a server, calls the driver with the server's iceoryx2
/// namespace and Zenoh endpoint, and stops the server. The driver feeds it samples
/// and counts the allocations on counted threads (only the server's) per sample.
fn measure(serve: impl FnOnce(&mut dyn FnMut(IpcConfig, String))) -> PerSample {
    let mut result = None;
    serve(&mut |ipc, endpoint| {
        let mut d = Driver::new(&ipc, &endpoint);
        d.warm_up();
        let one_in_flight = fewest(|| counted(200, |n| d.one_in_flight(n)));
        let burst = SOURCES.len() as u64 * PER_SOURCE;
        let bursts = fewest(|| counted(2 * burst, |n| d.bursts(n / burst)));
        result = Some(PerSample {
            one_in_flight,
            bursts,
        });
    });
    result.expect("the driver ran")
}

/// The smallest of several measurements. A loaded machine adds allocations in the
/// libraries now and then (the raw loop shows them as much as ghnetd), never takes
/// any away, while an allocation of ghnetd's own per sample is in every measurement.
fn fewest(mut measure: impl FnMut() -> f64) -> f64 {
    (0..6).map(|_| measure()).fold(f64::INFINITY, f64::min)
}

/// Allocations on counted threads per sample while `run(samples)` answers them.
fn counted(samples: u64, run: impl FnOnce(u64)) -> f64 {
    // The server's last allocation for earlier samples (its Zenoh put) comes before
    // the notify that delivered the answer, so nothing of earlier work is counted.
    let before = allocations();
    run(samples);
    (allocations() - before) as f64 / samples as f64
}

/// The publishers and consumers around a server.
struct Driver {
    gnss: Vec<VelocityPublisher>,
    headings: Vec<HeadingSubscriber>,
    seq: u64,
    zenoh_seen: Arc<AtomicU64>,
    _zenoh: (zenoh::Session, zenoh::pubsub::Subscriber<()>),
}

impl Driver {
    fn new(ipc: &IpcConfig, endpoint: &str) -> Self {
        let headings = SOURCES.map(|s| HeadingSubscriber::new(ipc, s).unwrap());
        let gnss = SOURCES.map(|s| VelocityPublisher::new(ipc, s).unwrap());
        wait_until("the server on every source", || {
            gnss.iter().all(|g| g.subscriber_count() > 0)
                && headings.iter().all(|h| h.publisher_count() > 0)
        });
        // A Zenoh consumer too, so that the server's puts really go somewhere.
        let cfg = ghnet_client::peer_config(&[], &[endpoint.to_owned()]).unwrap();
        let session = zenoh::open(cfg).wait().unwrap();
        let zenoh_seen = Arc::new(AtomicU64::new(0));
        let seen = zenoh_seen.clone();
        let subscriber = session
            .declare_subscriber(format!("{}/*/heading", ipc.prefix()))
            .callback(move |_| {
                seen.fetch_add(1, Relaxed);
            })
            .wait()
            .unwrap();
        Self {
            gnss: gnss.into(),
            headings: headings.into(),
            seq: 0,
            zenoh_seen,
            _zenoh: (session, subscriber),
        }
    }

    fn sample(&mut self) -> VelocitySample {
        self.seq += 1;
        // Moving, stationary and invalid inputs: every branch of the answer path.
        let vn = [3.0, 0.0, f32::NAN][self.seq as usize % 3];
        VelocitySample::new(self.seq, self.seq, vn, 4.0, 0.0)
    }

    /// Until iceoryx2 has connected every port (lazily, on first use) and the Zenoh
    /// consumer receives headings.
    fn warm_up(&mut self) {
        self.one_in_flight(20);
        self.bursts(2);
        wait_until("headings over Zenoh", || {
            self.one_in_flight(1);
            self.zenoh_seen.load(Relaxed) > 0
        });
    }

    /// `n` samples on the first source, each sent when the previous one is answered.
    fn one_in_flight(&mut self, n: u64) {
        for _ in 0..n {
            let s = self.sample();
            self.gnss[0].send(s).unwrap();
            self.answer(0);
        }
    }

    /// `n` bursts: every source publishes [`PER_SOURCE`] samples, then each notifies,
    /// then every answer is awaited.
    fn bursts(&mut self, n: u64) {
        for _ in 0..n {
            for i in 0..SOURCES.len() {
                for _ in 0..PER_SOURCE {
                    let s = self.sample();
                    self.gnss[i].publish(s).unwrap();
                }
            }
            for g in &self.gnss {
                g.notify().unwrap();
            }
            for i in 0..SOURCES.len() {
                for _ in 0..PER_SOURCE {
                    self.answer(i);
                }
            }
        }
    }

    fn answer(&self, source: usize) -> HeadingEstimate {
        self.headings[source]
            .recv_timeout(WATCHDOG)
            .unwrap()
            .expect("watchdog: an answer")
    }
}

/// One source's ports in the raw server, opened without requesting limits (the
/// driver created the services).
struct RawPorts {
    subscriber:
        ghnet_client::iceoryx2::port::subscriber::Subscriber<ipc::Service, VelocitySample, ()>,
    listener: ghnet_client::iceoryx2::port::listener::Listener<ipc::Service>,
    publisher:
        ghnet_client::iceoryx2::port::publisher::Publisher<ipc::Service, HeadingEstimate, ()>,
    notifier: ghnet_client::iceoryx2::port::notifier::Notifier<ipc::Service>,
    batched: zenoh::pubsub::Publisher<'static>,
    express: zenoh::pubsub::Publisher<'static>,
}

impl RawPorts {
    /// `None` until the driver has created the services.
    fn open(
        node: &Node<ipc::Service>,
        ipc: &IpcConfig,
        zenoh: &zenoh::Session,
        source: &str,
    ) -> Option<Self> {
        let velocity = ServiceName::new(&ipc.velocity_service(source).unwrap()).unwrap();
        let heading = ServiceName::new(&ipc.heading_service(source).unwrap()).unwrap();
        let buffer = ghnet_client::SERVICE_SETTINGS.subscriber_buffer_size;
        let key = ipc.zenoh_heading_key(source).unwrap();
        let declare = |express| {
            zenoh
                .declare_publisher(key.clone())
                .congestion_control(zenoh::qos::CongestionControl::Drop)
                .priority(zenoh::qos::Priority::DataHigh)
                .express(express)
                .wait()
                .unwrap()
        };
        let input = node.service_builder(&velocity);
        let output = node.service_builder(&heading);
        let input_event = node.service_builder(&velocity).event().open().ok()?;
        let output_event = node.service_builder(&heading).event().open().ok()?;
        Some(Self {
            subscriber: (input.publish_subscribe::<VelocitySample>().open().ok()?)
                .subscriber_builder()
                .buffer_size(buffer)
                .create()
                .unwrap(),
            listener: input_event.listener_builder().create().unwrap(),
            publisher: (output.publish_subscribe::<HeadingEstimate>().open().ok()?)
                .publisher_builder()
                .create()
                .unwrap(),
            notifier: output_event.notifier_builder().create().unwrap(),
            batched: declare(false),
            express: declare(true),
        })
    }

    /// What `Receiver::try_recv` calls: receive; when empty, drain the listener and
    /// look once more.
    fn try_recv(&self) -> Option<VelocitySample> {
        if let Some(s) = self.subscriber.receive().unwrap() {
            return Some(*s);
        }
        self.listener.try_wait(|_| {}).unwrap();
        self.subscriber.receive().unwrap().map(|s| *s)
    }
}

/// The raw server: ghnetd's per-wake-up and per-sample calls into iceoryx2 and Zenoh,
/// with an echo instead of the model, on a counted thread.
fn raw_server(ipc: &IpcConfig, endpoint: &str, stop: &AtomicBool) {
    let node = NodeBuilder::new()
        .config(&ipc.iceoryx2_config())
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ipc::Service>()
        .unwrap();
    // ghnetd's Zenoh config (its transmit queue included), on the raw endpoint.
    let section = ghnetd::ZenohSection {
        listen: vec![endpoint.to_owned()],
        ..Default::default()
    };
    let session = zenoh::open(section.zenoh_config().unwrap()).wait().unwrap();
    let ports = SOURCES.map(|s| {
        let mut opened = None;
        wait_until("the driver's services", || {
            opened = RawPorts::open(&node, ipc, &session, s);
            opened.is_some()
        });
        opened.unwrap()
    });
    let waitset = WaitSetBuilder::new()
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ipc::Service>()
        .unwrap();
    let _tick = waitset.attach_interval(Duration::from_secs(60)).unwrap();
    let guards: Vec<_> = ports
        .iter()
        .map(|p| waitset.attach_notification(&p.listener).unwrap())
        .collect();
    let mut fired = Vec::with_capacity(ports.len());
    let mut round: Vec<(usize, VelocitySample)> = Vec::with_capacity(128);
    count_this_thread();
    while !stop.load(Relaxed) {
        fired.clear();
        wait_for_listeners(&waitset, &guards, Duration::from_millis(100), &mut fired).unwrap();
        round.clear();
        for &f in &fired {
            ports[f].listener.try_wait(|_| {}).unwrap();
            while let Some(s) = ports[f].try_recv() {
                round.push((f, s));
            }
        }
        let n = round.len();
        for (i, (f, s)) in round.iter().enumerate() {
            let p = &ports[*f];
            let mut answer = HeadingEstimate::from_le_bytes(&[0; HeadingEstimate::SIZE]);
            (answer.seq, answer.timestamp_ns) = (s.seq, s.timestamp_ns);
            p.publisher
                .loan_uninit()
                .unwrap()
                .write_payload(answer)
                .send()
                .unwrap();
            let zenoh = if i + 1 < n { &p.batched } else { &p.express };
            zenoh.put(encode_zenoh(&answer)).wait().unwrap();
        }
        for &f in &fired {
            ports[f].notifier.notify().unwrap();
        }
    }
}
