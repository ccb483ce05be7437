//! The Zenoh output: every heading sent on iceoryx2 also arrives on Zenoh with the
//! same bytes; presence, stats and model queryables; loopback-only sockets.

use std::collections::BTreeMap;
use std::time::Duration;

use ghnet_client::zenoh::Wait;
use ghnet_client::{HeadingEstimate, VelocitySample, ZenohHeadingSubscriber};
use ghnet_testkit::{
    now_ns, run_ghnetd, test_model, Ghnetd, Listen, OneSource, TestNamespace, WATCHDOG,
};

/// ghnetd serving one static source, seen through a velocity publisher and a heading
/// subscriber on each output.
struct ZenohSource {
    // Field order = drop order: the subscriber and session before the daemon.
    zen: ZenohHeadingSubscriber,
    session: ghnet_client::zenoh::Session,
    one: OneSource,
}

impl ZenohSource {
    /// Starts ghnetd for `source` and warms it up: sends samples until one comes back
    /// over Zenoh too (the subscriber's declaration has reached the daemon), then
    /// drains both subscribers.
    fn start(source: &str) -> Self {
        let one = OneSource::start(source, |b| b);
        let session = one.daemon.connect();
        let zen = ZenohHeadingSubscriber::new(&session, one.daemon.ipc(), source).unwrap();
        let mut seq = 0;
        loop {
            one.daemon.assert_running();
            assert!(seq < 2_000, "no heading over Zenoh after {seq} samples");
            (one.gnss
                .send(VelocitySample::new(now_ns(), seq, 1.0, 1.0, 0.0)))
            .unwrap();
            let answer = one.headings.recv_timeout(WATCHDOG).unwrap();
            answer.expect("iceoryx2 answer");
            seq += 1;
            if zen
                .recv_timeout(Duration::from_millis(20))
                .unwrap()
                .is_some()
            {
                break;
            }
        }
        while zen
            .recv_timeout(Duration::from_millis(200))
            .unwrap()
            .is_some()
        {}
        Self { zen, session, one }
    }
}

/// The next heading over Zenoh, `got` of `of` so far; after [`WATCHDOG`] without
/// one, panics with the daemon's log.
fn next_zenoh(
    zen: &ZenohHeadingSubscriber,
    daemon: &Ghnetd,
    got: usize,
    of: usize,
) -> HeadingEstimate {
    daemon.assert_running();
    zen.recv_timeout(WATCHDOG)
        .expect("decodes")
        .unwrap_or_else(|| {
            panic!(
                "watchdog: {got} of {of} headings over Zenoh; log:\n{}",
                daemon.log()
            )
        })
}

#[test]
fn every_heading_arrives_on_zenoh_with_the_same_bytes_and_queryables_answer() {
    let ZenohSource { zen, session, one } = ZenohSource::start("z0");
    let ipc = one.daemon.ipc().clone();
    assert_eq!(zen.key(), "ghnet/z0/heading");

    // Valid, stationary, invalid (NaN) and fast inputs; large sequence numbers.
    let n = 400u64;
    let first = 1u64 << 40;
    let mut from_ice = BTreeMap::new();
    let t0 = now_ns();
    for i in 0..n {
        let (vn, ve) = match i % 4 {
            0 => (0.0, 0.0),
            1 => (f32::NAN, 1.0),
            2 => (60.0, -20.0),
            _ => (i as f32 * 0.1, 3.0),
        };
        one.gnss
            .send(VelocitySample::new(t0 + i, first + i, vn, ve, 0.0))
            .unwrap();
        let h = one
            .headings
            .recv_timeout(WATCHDOG)
            .unwrap()
            .expect("iceoryx2 answer");
        from_ice.insert(h.seq, h.to_le_bytes());
    }
    let mut from_zenoh: BTreeMap<u64, [u8; 64]> = BTreeMap::new();
    while from_zenoh.len() < n as usize {
        let h = next_zenoh(&zen, &one.daemon, from_zenoh.len(), n as usize);
        assert!(h.seq >= first, "warm-up heading after the drain: {h:?}");
        assert!(
            from_zenoh.insert(h.seq, h.to_le_bytes()).is_none(),
            "duplicate {}",
            h.seq
        );
    }
    // Same sequence numbers, byte for byte the same headings (NaN payloads included).
    assert_eq!(from_zenoh, from_ice);
    assert!(zen
        .recv_timeout(Duration::from_millis(200))
        .unwrap()
        .is_none());

    // Stats: the loop refreshes the snapshot per wake-up; the last one is in.
    let z0 = one
        .daemon
        .wait_for_counters("z0", |c| c.get("last_seq") == Some(&(first + n - 1)));
    let received = z0["received"];
    assert_eq!(z0["answered"], received, "{z0:?}");
    assert!(received >= n, "{z0:?}");
    assert!(z0["invalid"] >= n / 4, "{z0:?}");
    let stats = one.daemon.stats();
    let processing = &stats["sources"]["z0"]["processing"];
    assert!(processing["p50_ns"].as_u64().unwrap() > 0, "{stats}");
    assert!(
        processing["p99_ns"].as_u64() >= processing["p50_ns"].as_u64(),
        "{stats}"
    );
    assert_eq!(
        stats["daemon"]["pid"].as_u64(),
        Some(one.daemon.pid() as u64)
    );
    eprintln!("stats: {stats}");

    // Model metadata.
    let replies = session.get(ipc.zenoh_model_key()).wait().unwrap();
    let reply = replies.recv_timeout(WATCHDOG).unwrap().expect("a reply");
    let meta: serde_json::Value =
        serde_json::from_slice(&reply.result().expect("ok").payload().to_bytes()).unwrap();
    assert_eq!(
        meta["name"].as_str(),
        Some(test_model().model.name()),
        "{meta}"
    );

    // Presence: one token under <prefix>/@ghnetd/, named by the daemon's zid.
    let zid = stats["daemon"]["zid"].as_str().unwrap().to_owned();
    let tokens = session
        .liveliness()
        .get(ipc.zenoh_presence_key("*"))
        .wait()
        .unwrap();
    let token = tokens.recv_timeout(WATCHDOG).unwrap().expect("a token");
    assert_eq!(
        token.result().expect("ok").key_expr().as_str(),
        ipc.zenoh_presence_key(&zid)
    );
    one.daemon.stop();
}

/// A source that delivers in bursts (publish many, notify once) is drained in one
/// go; its headings go out over Zenoh batched but the last, which is express. Every
/// heading must still arrive, once, in the order sent, byte for byte as on
/// iceoryx2 (two publishers share the key; they must not reorder).
#[test]
fn bursts_arrive_on_zenoh_complete_and_in_order() {
    let ZenohSource {
        zen,
        session: _session,
        one,
    } = ZenohSource::start("b0");

    // Bursts of 1 to 120 samples (the buffers hold 128), valid and invalid mixed.
    let first = 1u64 << 32;
    let mut seq = first;
    let mut from_ice = Vec::new();
    let t0 = now_ns();
    for burst in [120u64, 1, 2, 64, 3, 120, 17, 100] {
        let end = seq + burst;
        for s in seq..end {
            let (vn, ve) = if s % 7 == 0 {
                (f32::NAN, 0.0)
            } else {
                (5.0, 0.01 * (s % 100) as f32)
            };
            one.gnss
                .publish(VelocitySample::new(t0 + s, s, vn, ve, 0.0))
                .unwrap();
        }
        one.gnss.notify().unwrap();
        while seq < end {
            let h = one
                .headings
                .recv_timeout(WATCHDOG)
                .unwrap()
                .unwrap_or_else(|| {
                    panic!(
                        "watchdog: no iceoryx2 answer to {seq}; log:\n{}",
                        one.daemon.log()
                    )
                });
            assert_eq!(h.seq, seq, "iceoryx2 answers in order");
            from_ice.push(h.to_le_bytes());
            seq += 1;
        }
    }
    let mut from_zenoh = Vec::new();
    while from_zenoh.len() < from_ice.len() {
        let h = next_zenoh(&zen, &one.daemon, from_zenoh.len(), from_ice.len());
        assert_eq!(
            h.seq,
            first + from_zenoh.len() as u64,
            "Zenoh headings in order, none missing"
        );
        from_zenoh.push(h.to_le_bytes());
    }
    assert!(from_zenoh == from_ice, "the same bytes on both outputs");
    assert!(
        zen.recv_timeout(Duration::from_millis(200))
            .unwrap()
            .is_none(),
        "no extra heading"
    );
    one.daemon.stop();
}

/// Socket inodes of `pid`'s open file descriptors.
fn socket_inodes(pid: u32) -> Vec<String> {
    std::fs::read_dir(format!("/proc/{pid}/fd"))
        .unwrap()
        .flatten()
        .filter_map(|e| std::fs::read_link(e.path()).ok())
        .filter_map(|t| {
            let t = t.to_string_lossy().into_owned();
            Some(t.strip_prefix("socket:[")?.strip_suffix(']')?.to_owned())
        })
        .collect()
}

/// Rows of `/proc/<pid>/net/<table>` whose inode is one of `inodes`:
/// (local address hex, state hex).
fn rows(pid: u32, table: &str, inodes: &[String]) -> Vec<(String, String)> {
    let text = std::fs::read_to_string(format!("/proc/{pid}/net/{table}")).unwrap_or_default();
    text.lines()
        .skip(1)
        .filter_map(|l| {
            let f: Vec<&str> = l.split_whitespace().collect();
            (f.len() > 9 && inodes.iter().any(|i| i == f[9]))
                .then(|| (f[1].to_owned(), f[3].to_owned()))
        })
        .collect()
}

/// With the shipped defaults (only the port changed, so tests run in parallel) the
/// daemon listens on 127.0.0.1 only and has no UDP socket at all: no multicast
/// scouting. `ss -tulpn | grep ghnetd` shows the same by hand.
#[test]
fn default_zenoh_listens_on_loopback_only_and_opens_no_udp_socket() {
    let ns = TestNamespace::new("loopback");
    let daemon = Ghnetd::builder(&ns).listen(Listen::Tcp).start();
    // The kit's session is connected, so established sockets exist too.
    let pid = daemon.pid();
    let inodes = socket_inodes(pid);
    let listening: Vec<_> = rows(pid, "tcp", &inodes)
        .into_iter()
        .chain(rows(pid, "tcp6", &inodes))
        .filter(|(_, state)| state == "0A")
        .collect();
    assert!(!listening.is_empty(), "ghnetd listens somewhere");
    for (addr, _) in &listening {
        // 127.0.0.1 in /proc's little-endian hex.
        assert!(addr.starts_with("0100007F:"), "listening on {addr}");
    }
    let udp: Vec<_> = rows(pid, "udp", &inodes)
        .into_iter()
        .chain(rows(pid, "udp6", &inodes))
        .collect();
    assert!(udp.is_empty(), "UDP sockets (scouting?): {udp:?}");
    daemon.stop();
}

/// A Zenoh port already taken: ghnetd exits non-zero and says which key to change.
#[test]
fn busy_zenoh_port_is_a_clear_start_up_error() {
    let ns = TestNamespace::new("busyport");
    let taken = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let endpoint = format!("tcp/{}", taken.local_addr().unwrap());
    let mut args = vec!["--zenoh-listen".into(), endpoint.clone().into()];
    if let Some(name) = test_model().flag {
        args.extend(["--model".into(), name.into()]);
    }
    let out = run_ghnetd(&ns, &args);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{stderr}");
    let last = stderr.lines().last().unwrap_or_default();
    assert!(last.starts_with("error: zenoh.listen"), "{stderr}");
    assert!(last.contains(&endpoint), "{stderr}");
}

/// `--zenoh false`: no Zenoh session at all, iceoryx2 unaffected.
#[test]
fn zenoh_can_be_disabled() {
    let one = OneSource::start("off", |b| b.listen(Listen::Off));
    one.gnss
        .send(VelocitySample::new(1, 1, 1.0, 0.0, 0.0))
        .unwrap();
    assert!(one.headings.recv_timeout(WATCHDOG).unwrap().is_some());
    let pid = one.daemon.pid();
    let inodes = socket_inodes(pid);
    assert!(rows(pid, "tcp", &inodes).is_empty() && rows(pid, "tcp6", &inodes).is_empty());
    let log = one.daemon.stop();
    assert!(log.contains("zenoh output disabled"), "{log}");
}
