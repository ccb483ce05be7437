//! [`NetNamespace`]: a network namespace as a "host" of its own, for tests that need
//! several hosts on one machine (a daemon and a consumer, vehicles and a router), and
//! [`NetNamespace::link`], a veth pair between two of them.
//!
//! Needs root and `ip` (iproute2); tests using it are `#[ignore = "needs root and ip"]`.
//!
//! Names are `ghnet-<pid>-<n>-<role>`: unique among the tests running now, in this
//! process and in others, so they run in parallel. A namespace is deleted on drop
//! (also when the test panics), and with it every veth end inside it, which takes
//! the peer end down too. A run that was killed cannot drop anything: the first
//! namespace a process creates deletes those whose process is gone.
//!
//! Veth ends are created directly inside their namespaces (`ip link add … netns …`),
//! so nothing ever appears in the machine's own namespace: addresses can be fixed
//! per test (private, or TEST-NET), they exist only between the namespaces that hold
//! them.

use std::process::Command;
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::Once;

/// The start of every namespace name the kit makes (and sweeps).
const NAME_PREFIX: &str = "ghnet-";

/// Runs `ip ARGS…`; an error with `ip`'s own message if it fails.
pub fn ip(args: &[&str]) -> anyhow::Result<()> {
    let out = Command::new("ip")
        .args(args)
        .output()
        .map_err(|e| anyhow::anyhow!("cannot run ip: {e}"))?;
    anyhow::ensure!(
        out.status.success(),
        "ip {}: {}",
        args.join(" "),
        String::from_utf8_lossy(&out.stderr).trim()
    );
    Ok(())
}

/// A network namespace with its loopback up, deleted on drop.
#[derive(Debug)]
pub struct NetNamespace {
    name: String,
    role: String,
}

impl NetNamespace {
    /// A new namespace for `role` (e.g. `hub`, `truck1`; at most 12 bytes, it names
    /// the veth ends that lead to this namespace: `to-<role>`).
    pub fn create(role: &str) -> anyhow::Result<Self> {
        static SWEEP: Once = Once::new();
        static COUNT: AtomicU32 = AtomicU32::new(0);
        anyhow::ensure!(
            !role.is_empty() && role.len() <= 12 && role.bytes().all(|b| b.is_ascii_alphanumeric()),
            "namespace role `{role}`: 1 to 12 ASCII letters or digits"
        );
        SWEEP.call_once(sweep_stale);
        let n = COUNT.fetch_add(1, Ordering::Relaxed);
        let name = format!("{NAME_PREFIX}{}-{n}-{role}", std::process::id());
        ip(&["netns", "add", &name])?;
        // From here on, drop deletes it, whatever fails next.
        let ns = Self {
            name,
            role: role.to_owned(),
        };
        ip(&["-n", &ns.name, "link", "set", "lo", "up"])?;
        Ok(ns)
    }

    /// Lets multicast run on this namespace's loopback (flag `MULTICAST` on `lo`, a
    /// route for 224.0.0.0/4 through it): DDS discovery (SPDP) is multicast, and in
    /// a namespace of its own no packet of it leaves the namespace.
    pub fn enable_loopback_multicast(&self) -> anyhow::Result<()> {
        ip(&["-n", &self.name, "link", "set", "lo", "multicast", "on"])?;
        ip(&["-n", &self.name, "route", "add", "224.0.0.0/4", "dev", "lo"])
    }

    /// The namespace's name (as `ip netns` lists it).
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The command that runs a program in this namespace: `ip netns exec <name>`, for
    /// the kit's `wrapper` arguments.
    pub fn exec(&self) -> [&str; 4] {
        ["ip", "netns", "exec", &self.name]
    }

    /// A veth pair from this namespace to `other`: the end here is `to-<other role>`
    /// with address `here` (CIDR, e.g. `10.13.1.1/30`), the end there `to-<this role>`
    /// with `there`; both up.
    pub fn link(&self, here: &str, other: &NetNamespace, there: &str) -> anyhow::Result<()> {
        let (dev_here, dev_there) = (format!("to-{}", other.role), format!("to-{}", self.role));
        ip(&[
            "link",
            "add",
            &dev_here,
            "netns",
            &self.name,
            "type",
            "veth",
            "peer",
            "name",
            &dev_there,
            "netns",
            &other.name,
        ])?;
        for (ns, dev, addr) in [(self, &dev_here, here), (other, &dev_there, there)] {
            ip(&["-n", &ns.name, "addr", "add", addr, "dev", dev])?;
            ip(&["-n", &ns.name, "link", "set", dev, "up"])?;
        }
        Ok(())
    }
}

impl Drop for NetNamespace {
    fn drop(&mut self) {
        // Deleting a namespace deletes its veth ends, and with each its peer.
        let _ = ip(&["netns", "del", &self.name]);
    }
}

/// Deletes the kit's namespaces whose process no longer exists (a killed test run);
/// best effort, a namespace of a live process is never touched.
fn sweep_stale() {
    let Ok(out) = Command::new("ip").args(["netns", "list"]).output() else {
        return;
    };
    let listing = String::from_utf8_lossy(&out.stdout);
    // Lines are `<name>` or `<name> (id: N)`.
    for name in listing.lines().filter_map(|l| l.split_whitespace().next()) {
        let pid = name
            .strip_prefix(NAME_PREFIX)
            .and_then(|rest| rest.split('-').next())
            .and_then(|pid| pid.parse::<u32>().ok());
        if pid.is_some_and(|pid| !std::path::Path::new(&format!("/proc/{pid}")).exists()) {
            let _ = ip(&["netns", "del", name]);
        }
    }
}
