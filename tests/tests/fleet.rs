//! A fleet: two vehicles, each with its own ghnetd (prefixes `fleet/truck1` and
//! `fleet/truck2`, each in its own iceoryx2 namespace), connected to a real Zenoh
//! router. A consumer attached only to the router gets every heading of both vehicles
//! with one wildcard subscription, queries each vehicle's stats through the router,
//! and after the router restarts headings resume without touching the daemons.

use std::collections::BTreeMap;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use ghnet_client::zenoh::{self, Wait};
use ghnet_client::{decode_zenoh, peer_config, VelocityPublisher, VelocitySample};
use ghnet_testkit::{free_tcp_port, now_ns, Ghnetd, TestNamespace, WATCHDOG};

const VEHICLES: [&str; 2] = ["fleet/truck1", "fleet/truck2"];
const SOURCE: &str = "gnss0";

/// A Zenoh router on `endpoint` (the zenoh crate in router mode, as `zenohd` runs it),
/// loopback only, no scouting.
fn router(endpoint: &str) -> zenoh::Session {
    let mut c = peer_config(&[endpoint.to_owned()], &[]).unwrap();
    c.insert_json5("mode", "\"router\"").unwrap();
    zenoh::open(c).wait().expect("router session")
}

/// A consumer that knows only the router: a Zenoh *client* (a peer attached only to a
/// router with gossip off is not routed to; clients are), reconnecting quickly when
/// the router goes away.
fn consumer(router: &str) -> zenoh::Session {
    let mut c = peer_config(&[], &[router.to_owned()]).unwrap();
    c.insert_json5("mode", "\"client\"").unwrap();
    c.insert_json5("connect/retry", "{period_init_ms: 50, period_max_ms: 500}")
        .unwrap();
    zenoh::open(c).wait().expect("consumer session")
}

/// The highest seq received per vehicle prefix, and the number of headings.
type Seen = Arc<Mutex<BTreeMap<String, (u64, u64)>>>;

/// One vehicle: its namespace, its ghnetd (connected to the router) and its receiver.
struct Vehicle {
    gnss: VelocityPublisher,
    daemon: Ghnetd,
    _ns: TestNamespace,
}

impl Vehicle {
    fn start(prefix: &str, router: &str) -> Self {
        let ns = TestNamespace::new("fleet");
        let daemon = Ghnetd::builder(&ns)
            .prefix(prefix)
            .source(SOURCE)
            .discovery(false)
            .arg("--zenoh-connect")
            .arg(router)
            .start();
        let gnss = VelocityPublisher::new(daemon.ipc(), SOURCE).unwrap();
        daemon.wait_serving(&gnss);
        Self {
            gnss,
            daemon,
            _ns: ns,
        }
    }

    fn send(&self, seq: u64) {
        let s = VelocitySample::new(now_ns(), seq, 3.0, 4.0, 0.0);
        self.gnss.send(s).unwrap();
    }
}

/// Sends from both vehicles, one sample each per 20 ms from `first` on, until the
/// consumer has seen a heading with `seq >= first` from each; returns the next seq.
fn send_until_seen(vehicles: &[Vehicle], seen: &Seen, first: u64) -> u64 {
    let t0 = Instant::now();
    let mut seq = first;
    loop {
        let done = {
            let s = seen.lock().unwrap();
            VEHICLES
                .iter()
                .all(|v| s.get(*v).is_some_and(|&(max, _)| max >= first))
        };
        if done {
            return seq;
        }
        assert!(
            t0.elapsed() < WATCHDOG,
            "no heading via the router: {seen:?}"
        );
        for v in vehicles {
            v.daemon.assert_running();
            v.send(seq);
        }
        seq += 1;
        std::thread::sleep(Duration::from_millis(20));
    }
}

#[test]
fn a_consumer_on_the_router_sees_the_whole_fleet_and_survives_a_router_restart() {
    let endpoint = format!("tcp/127.0.0.1:{}", free_tcp_port());
    let mut hub = router(&endpoint);
    let vehicles: Vec<Vehicle> = VEHICLES
        .iter()
        .map(|p| Vehicle::start(p, &endpoint))
        .collect();
    let session = consumer(&endpoint);
    let seen: Seen = Arc::default();
    let _sub = session
        .declare_subscriber("fleet/*/*/heading")
        .callback({
            let seen = seen.clone();
            move |sample| {
                let key = sample.key_expr().as_str();
                let vehicle = key.rsplitn(3, '/').nth(2).unwrap_or_default().to_owned();
                let h = decode_zenoh(&sample.payload().to_bytes()).expect("a heading");
                let mut s = seen.lock().unwrap();
                let e = s.entry(vehicle).or_insert((0, 0));
                (e.0, e.1) = (e.0.max(h.seq), e.1 + 1);
            }
        })
        .wait()
        .unwrap();

    // Both vehicles through one wildcard subscription, every heading once sent.
    let next = send_until_seen(&vehicles, &seen, 0);
    let burst = next..next + 50;
    for seq in burst.clone() {
        vehicles.iter().for_each(|v| v.send(seq));
        std::thread::sleep(Duration::from_millis(2));
    }
    let want = burst.end - 1;
    ghnet_testkit::wait_until("the burst over the router", || {
        let s = seen.lock().unwrap();
        VEHICLES
            .iter()
            .all(|v| s.get(*v).is_some_and(|&(max, _)| max == want))
    });
    for v in VEHICLES {
        let c = seen.lock().unwrap()[v];
        assert!(c.1 >= 50, "{v}: {c:?} headings");
    }

    // Each vehicle's stats, queried through the router.
    for (prefix, v) in VEHICLES.iter().zip(&vehicles) {
        let key = v.daemon.ipc().zenoh_stats_key();
        assert_eq!(key, format!("{prefix}/@ghnetd/stats"));
        let reply = session.get(&key).timeout(WATCHDOG).wait().unwrap();
        let reply = reply.recv().expect("a stats reply via the router");
        let stats: serde_json::Value =
            serde_json::from_slice(&reply.result().unwrap().payload().to_bytes()).unwrap();
        let answered = stats["sources"][SOURCE]["answered"].as_u64().unwrap();
        assert!(answered > want, "{prefix}: {stats}");
    }

    // The router goes away and comes back on the same endpoint; the daemons are not
    // touched and headings flow again.
    drop(hub);
    std::thread::sleep(Duration::from_millis(500));
    hub = router(&endpoint);
    send_until_seen(&vehicles, &seen, want + 1);
    drop(hub);
}
