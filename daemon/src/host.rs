//! What the host offers a ghnetd: the shared-memory filesystem's size and free
//! space, and whether a directory is one ghnetd may own.
//!
//! These are the checks that ask the operating system; they take plain values, not
//! the config, so `config` (start-up checks) and `pressure` (per-source budget) both
//! use them without depending on each other.

use std::path::Path;

use anyhow::bail;

/// Where POSIX shared memory lives on Linux; iceoryx2 0.10 creates its segments there
/// (`shm_open`), whatever its root path.
pub(crate) const SHM_DIR: &str = "/dev/shm";

/// Refuses an iceoryx2 root path ghnetd must not own: ghnetd writes its lock file,
/// node and service records there and makes it owner-only, so `/`, a pseudo
/// filesystem, a file, another user's directory or a world-writable directory without
/// the sticky bit (anyone could replace ghnetd's records) are configuration errors,
/// reported before anything is created. A path that does not exist yet is created.
pub(crate) fn check_root_path(root: &Path) -> anyhow::Result<()> {
    use std::os::unix::fs::MetadataExt;
    let shown = root.display();
    let canonical = root.canonicalize().unwrap_or_else(|_| root.to_owned());
    if canonical == Path::new("/") {
        bail!("`{shown}` is the filesystem root; use a directory of its own, e.g. /tmp/iceoryx2");
    }
    for pseudo in ["/proc", "/sys", "/dev"] {
        if canonical.starts_with(pseudo) {
            bail!("`{shown}` is under {pseudo}, not a directory ghnetd may own");
        }
    }
    let meta = match std::fs::metadata(&canonical) {
        Ok(m) => m,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(()),
        Err(e) => bail!("`{shown}`: {e}"),
    };
    if !meta.is_dir() {
        bail!("`{shown}` is not a directory");
    }
    // SAFETY: geteuid cannot fail and touches no memory.
    let me = unsafe { libc::geteuid() };
    if meta.uid() != me {
        bail!(
            "`{shown}` is owned by uid {}, not by this user (uid {me})",
            meta.uid()
        );
    }
    let mode = meta.mode();
    if mode & 0o002 != 0 && mode & 0o1000 == 0 {
        bail!(
            "`{shown}` is world-writable without the sticky bit (mode {:o})",
            mode & 0o7777
        );
    }
    Ok(())
}

/// Refuses `need` bytes of shared memory for one source when the whole of
/// [`SHM_DIR`] is smaller: such settings would end the first source in SIGBUS rather
/// than in an error. The message says how much is needed and how much there is.
pub(crate) fn check_shm_fits(need: u64) -> anyhow::Result<()> {
    let dir = Path::new(SHM_DIR);
    match fs_size(dir) {
        Some(size) if need > size => bail!(
            "one source needs about {need} bytes of shared memory with these values, more than {} holds ({size} bytes)",
            dir.display()
        ),
        _ => Ok(()),
    }
}

/// Bytes free for an unprivileged writer on the filesystem of `dir`.
pub(crate) fn shm_free(dir: &Path) -> Option<u64> {
    fs_space(dir).map(|(free, _)| free)
}

/// Size of the filesystem of `dir`, bytes.
pub(crate) fn fs_size(dir: &Path) -> Option<u64> {
    fs_space(dir).map(|(_, size)| size)
}

/// Bytes free for an unprivileged writer and the size, of the filesystem of `dir`
/// (statvfs(3)); `None` when it cannot be asked (no such directory).
fn fs_space(dir: &Path) -> Option<(u64, u64)> {
    use std::os::unix::ffi::OsStrExt;
    let path = std::ffi::CString::new(dir.as_os_str().as_bytes()).ok()?;
    // SAFETY: statvfs writes only into `st`; `path` is a valid C string.
    let mut st: libc::statvfs = unsafe { std::mem::zeroed() };
    if unsafe { libc::statvfs(path.as_ptr(), &mut st) } != 0 {
        return None;
    }
    let block = st.f_frsize as u64;
    Some((st.f_bavail as u64 * block, st.f_blocks as u64 * block))
}

/// Shared memory one source's services take when ghnetd creates all of them (its
/// four services' management segments, the heading data segment, the connections),
/// from the four `ipc.*` limits. Fitted to the `/dev/shm` files iceoryx2 0.10 made
/// for one source as its settings varied (the test below holds the measurements;
/// 16 subscriber slots × 130 samples of 116 bytes each are most of it at the
/// defaults), plus the connection segments consumers and the velocity publisher add.
pub(crate) fn shm_need(publishers: u64, subscribers: u64, nodes: u64, buffer: u64) -> u64 {
    const PAGE: u64 = 4096;
    // Four services' dynamic configs grow with the ports and the nodes.
    let dynamic = 4 * (512 + 140 * (publishers + subscribers) + 32 * nodes);
    let event = PAGE;
    // The heading data segment: every subscriber's buffer plus 2 borrowed samples.
    let data = 116 * subscribers * (buffer + 2) + PAGE;
    // One connection per subscriber of the heading service, one for the velocity one.
    let connections = (subscribers + 1) * (16 * buffer + PAGE);
    dynamic + event + data + connections
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Sizes of the `/dev/shm` files ghnetd made for one static source (no
    /// publisher, no consumer), measured with `ls -l /dev/shm`.
    #[test]
    fn shm_need_covers_what_one_source_was_measured_to_take() {
        for ((p, s, n, b), measured) in [
            ((4, 8, 16, 128), 133_073),
            ((4, 64, 16, 128), 1_008_017),
            ((4, 8, 16, 4096), 3_815_377),
            ((4, 8, 256, 128), 163_793),
            ((64, 8, 16, 128), 166_673),
        ] {
            let need = shm_need(p, s, n, b);
            assert!(
                need >= measured && need < 2 * measured,
                "{p} {s} {n} {b}: {need} vs {measured}"
            );
        }
    }

    #[test]
    fn root_path_checks() {
        assert!(check_root_path(Path::new("/")).is_err());
        assert!(check_root_path(Path::new("/proc/self")).is_err());
        let dir = tempfile::tempdir().unwrap();
        check_root_path(dir.path()).unwrap();
        check_root_path(&dir.path().join("not-yet")).unwrap();
        let file = dir.path().join("f");
        std::fs::write(&file, b"").unwrap();
        assert!(check_root_path(&file)
            .unwrap_err()
            .to_string()
            .contains("not a directory"));
        assert!(check_shm_fits(u64::MAX).is_err());
        check_shm_fits(1).unwrap();
    }
}
