//! Two "hosts" on one machine: ghnetd in one network namespace, a Zenoh subscriber in
//! another, joined by a veth pair. Every heading must cross.
//!
//! Needs root and `ip` (iproute2); skipped with a note otherwise. The namespaces and
//! the veth pair are created by the test (unique names), addresses are a /30 of
//! TEST-NET-1 (192.0.2.0/24) that exists only inside them, and everything is deleted
//! on drop. iceoryx2 is untouched by network namespaces (same `/dev/shm`), so this
//! test publishes velocity from its own process.

use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};
use std::sync::mpsc;

use ghnet_client::{encode_zenoh, HeadingSubscriber, VelocityPublisher, VelocitySample};
use ghnet_tests::{now_ns, unique_prefix, Daemon, Namespace, WATCHDOG};

const DAEMON_ADDR: &str = "192.0.2.1";
const CONSUMER_ADDR: &str = "192.0.2.2";

/// Two network namespaces joined by a veth pair; deleted on drop.
struct Hosts {
    daemon: String,
    consumer: String,
}

fn ip(args: &[&str]) -> Result<(), String> {
    let out = Command::new("ip")
        .args(args)
        .output()
        .map_err(|e| format!("ip: {e}"))?;
    if out.status.success() {
        Ok(())
    } else {
        Err(format!(
            "ip {}: {}",
            args.join(" "),
            String::from_utf8_lossy(&out.stderr).trim()
        ))
    }
}

impl Hosts {
    fn create(tag: &str) -> Result<Self, String> {
        let hosts = Self {
            daemon: format!("ghn{tag}d"),
            consumer: format!("ghn{tag}c"),
        };
        let (va, vb) = (format!("ghv{tag}a"), format!("ghv{tag}b"));
        ip(&["netns", "add", &hosts.daemon])?;
        ip(&["netns", "add", &hosts.consumer])?;
        ip(&["link", "add", &va, "type", "veth", "peer", "name", &vb])?;
        ip(&["link", "set", &va, "netns", &hosts.daemon])?;
        ip(&["link", "set", &vb, "netns", &hosts.consumer])?;
        for (ns, dev, addr) in [
            (&hosts.daemon, &va, DAEMON_ADDR),
            (&hosts.consumer, &vb, CONSUMER_ADDR),
        ] {
            ip(&["-n", ns, "addr", "add", &format!("{addr}/30"), "dev", dev])?;
            ip(&["-n", ns, "link", "set", dev, "up"])?;
            ip(&["-n", ns, "link", "set", "lo", "up"])?;
        }
        Ok(hosts)
    }
}

impl Drop for Hosts {
    fn drop(&mut self) {
        // Deleting a namespace deletes its end of the veth pair, and with it the peer.
        let _ = ip(&["netns", "del", &self.daemon]);
        let _ = ip(&["netns", "del", &self.consumer]);
    }
}

fn can_run() -> bool {
    // SAFETY: geteuid has no preconditions.
    if unsafe { libc::geteuid() } != 0 {
        eprintln!("SKIPPED: network namespaces need root");
        return false;
    }
    if Command::new("ip").arg("-V").output().is_err() {
        eprintln!("SKIPPED: `ip` (iproute2) is not installed");
        return false;
    }
    true
}

#[test]
fn every_heading_crosses_to_another_network_namespace() {
    if !can_run() {
        return;
    }
    let ns = Namespace::new();
    // Interface names are at most 15 bytes: "ghv" + 6 + 3 + "a".
    let tag = format!("{:x}{}", std::process::id() % 0xff_ffff, rand_suffix());
    let hosts = match Hosts::create(&tag) {
        Ok(h) => h,
        Err(e) => {
            eprintln!("SKIPPED: cannot create network namespaces: {e}");
            return;
        }
    };
    let prefix = unique_prefix("nn");
    let ipc = ns.ipc().with_prefix(&prefix).unwrap();
    let wrapper = ["ip", "netns", "exec", hosts.daemon.as_str()];
    let listen = format!("tcp/{DAEMON_ADDR}:0");
    let daemon = Daemon::start_wrapped(
        &ns,
        &wrapper,
        &[
            "--source",
            "nn",
            "--discovery",
            "false",
            "--service-prefix",
            &prefix,
            "--zenoh-listen",
            &listen,
        ],
    );
    let endpoint = daemon.zenoh_endpoint();
    assert!(
        endpoint.starts_with(&format!("tcp/{DAEMON_ADDR}:")),
        "{endpoint}"
    );

    // The consumer: this test binary again, running the ignored child test below in
    // the other namespace.
    let n = 200u64;
    let mut child = Command::new("ip")
        .args(["netns", "exec", &hosts.consumer])
        .arg(std::env::current_exe().unwrap())
        .args([
            "--exact",
            "netns::netns_child_subscriber",
            "--ignored",
            "--nocapture",
        ])
        .env("GHNET_NETNS_CONNECT", &endpoint)
        .env("GHNET_NETNS_PREFIX", &prefix)
        .env("GHNET_NETNS_COUNT", n.to_string())
        .stdout(Stdio::piped())
        .spawn()
        .expect("spawn the consumer");
    let (tx, rx) = mpsc::channel();
    let stdout = child.stdout.take().unwrap();
    std::thread::spawn(move || {
        for line in BufReader::new(stdout).lines().map_while(Result::ok) {
            if tx.send(line).is_err() {
                break;
            }
        }
    });
    let next = |what: &str| -> String {
        loop {
            let line = rx
                .recv_timeout(WATCHDOG)
                .unwrap_or_else(|_| panic!("watchdog: no {what} from the consumer"));
            if line.starts_with("READY") || line.starts_with("H ") {
                return line;
            }
        }
    };
    assert_eq!(next("ready line"), "READY");

    let ice = HeadingSubscriber::new(&ipc, "nn").unwrap();
    let gnss = VelocityPublisher::new(&ipc, "nn").unwrap();
    daemon.wait_serving(&gnss);
    let mut sent = Vec::new();
    let t0 = now_ns();
    for i in 0..n {
        gnss.send(VelocitySample::new(t0 + i, i, 2.0, i as f32 * 0.05, 0.0))
            .unwrap();
        let h = ice
            .recv_timeout(WATCHDOG)
            .unwrap()
            .expect("iceoryx2 answer");
        let hex: String = encode_zenoh(&h)
            .iter()
            .map(|b| format!("{b:02x}"))
            .collect();
        sent.push(format!("H {} {hex}", h.seq));
    }
    let mut received: Vec<String> = (0..n).map(|_| next("heading")).collect();
    received.sort_by_key(|l| l.split(' ').nth(1).unwrap().parse::<u64>().unwrap());
    assert_eq!(received, sent, "every heading crosses, byte for byte");
    let status = child.wait().unwrap();
    assert!(status.success());
    let (status, log) = daemon.terminate();
    assert!(status.success(), "{log}");
}

fn rand_suffix() -> String {
    use std::hash::{BuildHasher, Hasher};
    let r = std::collections::hash_map::RandomState::new()
        .build_hasher()
        .finish();
    format!("{:x}", r & 0xfff)
}

/// The consumer side of the test above; runs only when spawned by it.
#[test]
#[ignore = "spawned by every_heading_crosses_to_another_network_namespace"]
fn netns_child_subscriber() {
    let endpoint = std::env::var("GHNET_NETNS_CONNECT").expect("spawned by the parent test");
    let prefix = std::env::var("GHNET_NETNS_PREFIX").unwrap();
    let n: u64 = std::env::var("GHNET_NETNS_COUNT").unwrap().parse().unwrap();
    let ipc = ghnet_client::IpcConfig::new(&prefix).unwrap();
    let session = ghnet_tests::zenoh_session(&endpoint);
    let sub = ghnet_client::ZenohHeadingSubscriber::new(&session, &ipc, "nn").unwrap();
    ghnet_tests::zenoh_barrier(&session, &ipc);
    println!("READY");
    for _ in 0..n {
        let h = sub
            .recv_timeout(WATCHDOG)
            .unwrap()
            .expect("a heading within the watchdog");
        let hex: String = encode_zenoh(&h)
            .iter()
            .map(|b| format!("{b:02x}"))
            .collect();
        println!("H {} {hex}", h.seq);
    }
}
