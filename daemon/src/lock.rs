//! One ghnetd per service prefix: an exclusive lock file.
//!
//! Two daemons on the same services would both answer every sample (consumers would
//! see each answer twice) and fight over discovery. So the second one exits non-zero
//! with a message naming the first one's pid. The lock is an advisory `flock` on a
//! file keyed by the iceoryx2 namespace (root path + global prefix) and the service
//! prefix; the kernel drops it when its holder dies, so a `kill -9` leaves no stale
//! lock behind and the next ghnetd starts at once.
//!
//! The file is never deleted: unlinking on exit would let a daemon that opened the
//! old file before the unlink and one that creates a new file both "hold" a lock.

use std::fs::{File, OpenOptions, TryLockError};
use std::io::{Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::Context;

/// Held for the daemon's lifetime; dropping it releases the lock.
#[derive(Debug)]
pub(crate) struct InstanceLock {
    _file: File,
    path: PathBuf,
}

impl InstanceLock {
    /// Where the lock file lives.
    pub(crate) fn path(&self) -> &Path {
        &self.path
    }
}

/// The lock file of `service_prefix` in the iceoryx2 namespace (`root`,
/// `global_prefix`): `<root>/ghnetd-<global_prefix>-<service_prefix>.lock`, with `/` in
/// the service prefix written as `.` (never part of a prefix segment, so distinct
/// prefixes give distinct names).
pub(crate) fn lock_path(root: &Path, global_prefix: &str, service_prefix: &str) -> PathBuf {
    root.join(format!(
        "ghnetd-{global_prefix}-{}.lock",
        service_prefix.replace('/', ".")
    ))
}

/// Takes the lock for `service_prefix` or fails naming the holder's pid.
pub(crate) fn acquire(
    root: &Path,
    global_prefix: &str,
    service_prefix: &str,
) -> anyhow::Result<InstanceLock> {
    std::fs::create_dir_all(root).with_context(|| {
        format!(
            "cannot create the iceoryx2 root path {} for the instance lock",
            root.display()
        )
    })?;
    let path = lock_path(root, global_prefix, service_prefix);
    // No truncate on open: the file may be a running daemon's, holding its pid.
    let mut file = OpenOptions::new()
        .read(true)
        .write(true)
        .create(true)
        .truncate(false)
        .open(&path)
        .with_context(|| format!("cannot open the instance lock {}", path.display()))?;
    match file.try_lock() {
        Ok(()) => {}
        Err(TryLockError::WouldBlock) => {
            let pid = holder_pid(&mut file);
            anyhow::bail!(
                "another ghnetd (pid {pid}) already serves prefix `{service_prefix}` (lock {}); stop it or set ipc.service_prefix",
                path.display()
            );
        }
        Err(TryLockError::Error(e)) => {
            return Err(e).with_context(|| format!("cannot lock {}", path.display()));
        }
    }
    let write = |f: &mut File| -> std::io::Result<()> {
        f.set_len(0)?;
        f.seek(SeekFrom::Start(0))?;
        writeln!(f, "{}", std::process::id())?;
        f.flush()
    };
    write(&mut file).with_context(|| format!("cannot write the pid to {}", path.display()))?;
    Ok(InstanceLock { _file: file, path })
}

/// The pid in a locked file. The holder writes it right after locking, so a reader
/// that comes in between waits briefly; `unknown` if it never appears.
fn holder_pid(file: &mut File) -> String {
    let t0 = Instant::now();
    loop {
        let mut text = String::new();
        let read = file
            .seek(SeekFrom::Start(0))
            .and_then(|_| file.read_to_string(&mut text));
        if read.is_ok() {
            if let Ok(pid) = text.trim().parse::<u32>() {
                return pid.to_string();
            }
        }
        if t0.elapsed() > Duration::from_secs(1) {
            return "unknown".to_owned();
        }
        std::thread::sleep(Duration::from_millis(10));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn second_lock_names_the_first_pid_and_is_free_after_drop() {
        let dir = tempfile::tempdir().unwrap();
        let root = dir.path().join("iox");
        let first = acquire(&root, "p_", "site/ghnet").unwrap();
        assert_eq!(
            first.path(),
            root.join("ghnetd-p_-site.ghnet.lock").as_path()
        );
        let err = format!("{:#}", acquire(&root, "p_", "site/ghnet").unwrap_err());
        assert!(
            err.contains(&format!("another ghnetd (pid {})", std::process::id())),
            "{err}"
        );
        assert!(err.contains("ipc.service_prefix"), "{err}");
        // Other prefixes and namespaces are independent.
        let _other = acquire(&root, "p_", "site/ghnet2").unwrap();
        let _other_ns = acquire(&root, "q_", "site/ghnet").unwrap();
        drop(first);
        acquire(&root, "p_", "site/ghnet").unwrap();
    }
}
