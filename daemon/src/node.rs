//! The daemon's one iceoryx2 node: made after cleaning up what dead processes left,
//! and the hardening of what iceoryx2 creates in /dev/shm.

use anyhow::Context;
use ghnet_client::iceoryx2::config::Config as IoxConfig;
use ghnet_client::iceoryx2::prelude::*;
use tracing::{debug, info};

/// The daemon's one iceoryx2 node, after cleaning up what dead processes left.
pub(crate) fn open_node(iox_config: &IoxConfig) -> anyhow::Result<Node<ipc::Service>> {
    // Signals belong to the embedding program; iceoryx2 must not consume them.
    let node = NodeBuilder::new()
        .name(&NodeName::new("ghnetd").expect("valid node name"))
        .config(iox_config)
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ipc::Service>()
        .context("cannot create the iceoryx2 node (check permissions of /dev/shm and the iceoryx2 root path)")?;
    restrict_global_segment(iox_config);
    // Node creation already cleans up after dead nodes (iceoryx2 default); this
    // makes it explicit and visible after a kill -9.
    let cleanup = node.try_cleanup_dead_nodes();
    if cleanup.cleanups > 0 || cleanup.failed_cleanups > 0 {
        info!(
            cleaned = cleanup.cleanups,
            failed = cleanup.failed_cleanups,
            "removed stale iceoryx2 resources of dead processes"
        );
    }
    Ok(node)
}

/// iceoryx2 0.10 creates its per-prefix management segment
/// (`/dev/shm/<global prefix>…global_mgmt`) with mode 0666, unaffected by the umask;
/// everything else it creates is owner-only or below the (owner-only) root path.
/// Narrow it to the owner when this process owns it; failures only cost the
/// hardening, so they are logged, not fatal.
fn restrict_global_segment(iox: &IoxConfig) {
    use std::os::unix::fs::PermissionsExt;
    let prefix = iox.global.prefix.to_string();
    let Ok(entries) = std::fs::read_dir("/dev/shm") else {
        return;
    };
    for e in entries.flatten() {
        let name = e.file_name().to_string_lossy().into_owned();
        if name.starts_with(&prefix) && name.ends_with("global_mgmt") {
            let perms = std::fs::Permissions::from_mode(0o600);
            if let Err(err) = std::fs::set_permissions(e.path(), perms) {
                debug!(file = %e.path().display(), error = %err, "cannot restrict iceoryx2 management segment");
            }
        }
    }
}
