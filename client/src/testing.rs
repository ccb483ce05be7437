//! Test support: a private iceoryx2 namespace that cleans up after itself.
//!
//! Tests that run in parallel collide on service names, service limits and dead-node
//! cleanup unless each has its own iceoryx2 global prefix (separates `/dev/shm`) and
//! root path (separates `/tmp/iceoryx2`). [`TestNamespace`] makes a unique pair and
//! removes what iceoryx2 leaves behind (it keeps a small per-prefix management
//! segment on purpose) when dropped.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU32, Ordering};

use crate::IpcConfig;

static COUNTER: AtomicU32 = AtomicU32::new(0);

/// A unique iceoryx2 global prefix and root directory for one test.
///
/// Drop it only after every process using it has exited (reap spawned children
/// first): it deletes the namespace's files.
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
}

impl TestNamespace {
    /// A namespace unique to this process and call; `tag` (letters, digits, `_`) only
    /// makes leftovers recognisable.
    pub fn new(tag: &str) -> Self {
        let n = COUNTER.fetch_add(1, Ordering::Relaxed);
        let pid = std::process::id();
        let tag: String = tag
            .chars()
            .filter(|c| c.is_ascii_alphanumeric() || *c == '_')
            .take(16)
            .collect();
        let global_prefix = format!("ght{pid}x{n}{tag}_");
        let root = std::env::temp_dir().join(format!("ghnet-test-{pid}-{n}-{tag}"));
        Self {
            global_prefix,
            root,
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

    /// An [`IpcConfig`] with the default service prefix in this namespace.
    pub fn ipc(&self) -> IpcConfig {
        IpcConfig::isolated(&self.global_prefix, &self.root)
            .expect("generated names are always valid")
    }
}

impl Drop for TestNamespace {
    fn drop(&mut self) {
        if let Ok(entries) = std::fs::read_dir("/dev/shm") {
            for e in entries.flatten() {
                if e.file_name()
                    .to_string_lossy()
                    .starts_with(&self.global_prefix)
                {
                    let _ = std::fs::remove_file(e.path());
                }
            }
        }
        let _ = std::fs::remove_dir_all(&self.root);
    }
}
