//! Test support: a private iceoryx2 namespace that cleans up after itself, also after
//! a crashed run.
//!
//! Tests that run in parallel collide on service names, service limits and dead-node
//! cleanup unless each has its own iceoryx2 global prefix (separates `/dev/shm`) and
//! root path (separates `/tmp/iceoryx2`). [`TestNamespace`] makes a unique pair and
//! removes what iceoryx2 leaves behind (it keeps a small per-prefix management
//! segment on purpose) when dropped. A run that is killed never drops its
//! namespaces, so the first namespace of a process also removes the leftovers of
//! processes that no longer exist (the process id is part of every name).
//!
//! This is the one namespace type of ghnet's tests: the daemon's in-process tests,
//! the cross-process test kit (`ghnet-testkit`), the soak and perf tools and the
//! demo's `--isolated` mode all use it. Beside it, what tests of several crates share:
//! [`foreign_service`], a service as a non-ghnet client makes it, and
//! [`assert_success`] for commands a test runs.

pub mod alloc;

use std::hash::{BuildHasher, Hasher};
use std::path::{Path, PathBuf};
use std::process::Output;
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::{Mutex, Once};

use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::publish_subscribe::PortFactory;

use crate::{IpcConfig, Message};

/// Starts every name this module makes, in `/dev/shm` and in the temp dir
/// (`ght<pid>x…`), so a sweep finds them and their process id. Short on purpose:
/// iceoryx2's event sockets are `<root path>/<global prefix><39 digits>.event`, and a
/// unix socket path has at most 107 bytes.
const TAG: &str = "ght";

static COUNTER: AtomicU32 = AtomicU32::new(0);

/// A unique iceoryx2 global prefix and root directory for one test.
///
/// Unique across parallel tests and across runs: process id, a counter and a random
/// part. Drop it only after every process using it has exited (reap spawned children
/// first: an unreaped zombie keeps its iceoryx2 liveness lock): it deletes the
/// namespace's files and its [scratch directories](Self::scratch_dir).
///
/// ```
/// use ghnet_client::testing::TestNamespace;
/// let ns = TestNamespace::new("doc");
/// let ipc = ns.ipc(); // pass to publishers/subscribers; for ghnetd see
///                     // `global_prefix()` and `root_path()`
/// assert_eq!(ipc.prefix(), "ghnet");
/// ```
#[derive(Debug)]
pub struct TestNamespace {
    global_prefix: String,
    root: PathBuf,
    tag: String,
    scratch: Mutex<Vec<PathBuf>>,
}

impl TestNamespace {
    /// A namespace unique to this process, call and run. `tag` (letters, digits, `_`)
    /// names its [scratch directories](Self::scratch_dir), to make them recognisable;
    /// it stays out of the iceoryx2 names (see the socket path limit above). The first
    /// namespace of a process also removes what crashed runs left behind.
    pub fn new(tag: &str) -> Self {
        static SWEEP: Once = Once::new();
        SWEEP.call_once(sweep_leftovers);
        let n = COUNTER.fetch_add(1, Ordering::Relaxed);
        let random = std::collections::hash_map::RandomState::new()
            .build_hasher()
            .finish() as u32;
        let tag: String = tag
            .chars()
            .filter(|c| c.is_ascii_alphanumeric() || *c == '_')
            .take(12)
            .collect();
        let id = format!("{TAG}{}x{n}r{random:08x}", std::process::id());
        Self {
            global_prefix: format!("{id}_"),
            root: std::env::temp_dir().join(id),
            tag,
            scratch: Mutex::new(Vec::new()),
        }
    }

    /// The iceoryx2 global prefix (file-name prefix in `/dev/shm`).
    pub fn global_prefix(&self) -> &str {
        &self.global_prefix
    }

    /// The iceoryx2 root path (node and service records).
    pub fn root_path(&self) -> &Path {
        &self.root
    }

    /// The flags that put a ghnet program (ghnetd, a bridge, the Python examples) in
    /// this namespace: `--iceoryx2-global-prefix PREFIX --iceoryx2-root-path DIR`.
    pub fn iceoryx2_flags(&self) -> [std::ffi::OsString; 4] {
        [
            "--iceoryx2-global-prefix".into(),
            self.global_prefix.clone().into(),
            "--iceoryx2-root-path".into(),
            self.root.clone().into(),
        ]
    }

    /// An [`IpcConfig`] with the default service prefix in this namespace.
    pub fn ipc(&self) -> IpcConfig {
        IpcConfig::isolated(&self.global_prefix, &self.root)
            .expect("generated names are always valid")
    }

    /// A plain iceoryx2 node in this namespace, as a foreign (non-ghnet) client would
    /// have, for [`foreign_service`].
    pub fn foreign_node(&self) -> Node<ipc::Service> {
        NodeBuilder::new()
            .config(&self.ipc().iceoryx2_config())
            .create::<ipc::Service>()
            .expect("an iceoryx2 node in the test namespace")
    }

    /// A fresh, empty directory next to the root path, for what a test keeps beside
    /// the namespace (a daemon's log, a Zenoh unix socket, config files). Removed
    /// with the namespace, and by the sweep after a crashed run; not inside the root
    /// path, which belongs to iceoryx2 and the daemon.
    pub fn scratch_dir(&self, name: &str) -> PathBuf {
        let mut dirs = self.scratch.lock().unwrap_or_else(|e| e.into_inner());
        let (root, k, tag) = (self.root.display(), dirs.len(), &self.tag);
        let dir = PathBuf::from(format!("{root}-{tag}.{k}-{name}"));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir)
            .unwrap_or_else(|e| panic!("cannot create {}: {e}", dir.display()));
        dirs.push(dir.clone());
        dir
    }
}

/// Opens or creates the publish-subscribe service `service` for `T` on `node` the way
/// a foreign iceoryx2 client would: under any name, even one ghnet's naming rules
/// refuse, and with iceoryx2's default settings instead of ghnet's
/// [`SERVICE_SETTINGS`](crate::SERVICE_SETTINGS). For tests of what ghnet makes of
/// services it did not create.
pub fn foreign_service<T: Message>(
    node: &Node<ipc::Service>,
    service: &str,
) -> PortFactory<ipc::Service, T, ()> {
    let name = ServiceName::new(service).expect("an iceoryx2 service name");
    node.service_builder(&name)
        .publish_subscribe::<T>()
        .open_or_create()
        .expect("a foreign service with iceoryx2's defaults")
}

/// Asserts that a child process (`what`: its name and the case, e.g. a capture's file)
/// exited successfully; the message carries its exit status and stderr, which is all
/// a failing command-line test has to be read by.
pub fn assert_success(out: &Output, what: &str) {
    assert!(
        out.status.success(),
        "{what}: {}\n{}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
}

impl Drop for TestNamespace {
    fn drop(&mut self) {
        remove_shm_files(|name| name.starts_with(&self.global_prefix));
        let _ = std::fs::remove_dir_all(&self.root);
        let dirs = self.scratch.get_mut().unwrap_or_else(|e| e.into_inner());
        for dir in dirs.iter() {
            let _ = std::fs::remove_dir_all(dir);
        }
    }
}

fn remove_shm_files(matches: impl Fn(&str) -> bool) {
    if let Ok(entries) = std::fs::read_dir("/dev/shm") {
        for e in entries.flatten() {
            if matches(&e.file_name().to_string_lossy()) {
                let _ = std::fs::remove_file(e.path());
            }
        }
    }
}

/// The process id in a name this module made (`ght<pid>x…`), if it is one.
fn owner_pid(name: &str) -> Option<u32> {
    let (pid, _) = name.strip_prefix(TAG)?.split_once('x')?;
    pid.parse().ok()
}

/// Removes the namespaces of processes that no longer exist (a test run killed
/// before its namespaces were dropped).
fn sweep_leftovers() {
    let dead = |name: &str| {
        owner_pid(name).is_some_and(|pid| {
            pid != std::process::id() && !Path::new(&format!("/proc/{pid}")).exists()
        })
    };
    remove_shm_files(dead);
    if let Ok(entries) = std::fs::read_dir(std::env::temp_dir()) {
        for e in entries.flatten() {
            if dead(&e.file_name().to_string_lossy()) {
                let _ = std::fs::remove_dir_all(e.path());
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_carry_the_pid_and_are_unique() {
        let (a, b) = (TestNamespace::new("a"), TestNamespace::new("a"));
        assert_ne!(a.global_prefix(), b.global_prefix());
        let pid = Some(std::process::id());
        assert_eq!(owner_pid(a.global_prefix()), pid);
        let root = a.root_path().file_name().unwrap().to_string_lossy();
        assert_eq!(owner_pid(&root), pid);
        assert_eq!(owner_pid("iox2_other"), None);
        assert_eq!(owner_pid("ghtabcx1"), None);
    }

    #[test]
    fn scratch_dirs_go_with_the_namespace() {
        let ns = TestNamespace::new("scratch");
        let (d1, d2) = (ns.scratch_dir("log"), ns.scratch_dir("log"));
        assert_ne!(d1, d2);
        assert!(d1.is_dir() && d2.is_dir());
        let name = d1.file_name().unwrap().to_string_lossy().into_owned();
        assert_eq!(owner_pid(&name), Some(std::process::id()), "{name}");
        drop(ns);
        assert!(!d1.exists() && !d2.exists());
    }
}
