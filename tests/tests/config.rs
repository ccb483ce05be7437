//! Bad configuration: a one-line error on stderr and a non-zero exit, before any
//! iceoryx2 resource exists.

use std::ffi::OsString;

use ghnet_tests::{run_ghnetd, Namespace};

/// Runs ghnetd in a fresh namespace with `args`; asserts a non-zero exit and that
/// stderr is exactly one `error: ...` line; returns that line.
fn fails_with_one_line(args: &[OsString]) -> String {
    let ns = Namespace::new();
    let mut all = ns.daemon_args();
    all.extend_from_slice(args);
    let out = run_ghnetd(&all);
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(
        !out.status.success(),
        "{args:?} must fail; stderr:\n{stderr}"
    );
    assert_ne!(
        out.status.code(),
        None,
        "exit, not a crash: {:?}\n{stderr}",
        out.status
    );
    let lines: Vec<&str> = stderr.lines().collect();
    assert_eq!(lines.len(), 1, "exactly one line on stderr:\n{stderr}");
    assert!(lines[0].starts_with("error: "), "{stderr}");
    assert!(
        std::fs::read_dir(ns.root_path()).is_err(),
        "no iceoryx2 root created"
    );
    lines[0].to_owned()
}

#[test]
fn unknown_key_in_config_file() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("ghnetd.toml");
    std::fs::write(
        &file,
        "[sources]\ndiscovery = true\ndiscovry_interval_ms = 5\n",
    )
    .unwrap();
    let line = fails_with_one_line(&["--config".into(), file.clone().into()]);
    assert!(line.contains("discovry_interval_ms"), "{line}");
    assert!(
        line.contains(&*file.to_string_lossy()),
        "names the file: {line}"
    );
}

#[test]
fn invalid_values() {
    for (args, key) in [
        (
            &["--discovery-interval-ms", "0"][..],
            "sources.discovery_interval_ms",
        ),
        (&["--source", "a/b"][..], "sources.static"),
        (&["--max-speed=-1"][..], "model.max_speed"),
        (&["--service-prefix", "/x"][..], "ipc.service_prefix"),
        (&["--zenoh-mode", "server"][..], "zenoh.mode"),
        (&["--zenoh-listen", "nonsense"][..], "zenoh.listen"),
        (
            &["--zenoh-config", "/nonexistent/zenoh.json5"][..],
            "zenoh.config_file",
        ),
    ] {
        let args: Vec<OsString> = args.iter().map(Into::into).collect();
        let line = fails_with_one_line(&args);
        assert!(
            line.starts_with(&format!("error: {key}")),
            "{args:?}: {line}"
        );
    }
}

#[test]
fn missing_config_file() {
    let line = fails_with_one_line(&["--config".into(), "/nonexistent/ghnetd.toml".into()]);
    assert!(line.contains("/nonexistent/ghnetd.toml"), "{line}");
}

#[test]
fn missing_or_corrupt_model_file() {
    let line = fails_with_one_line(&["--model".into(), "/nonexistent/model.safetensors".into()]);
    assert!(line.starts_with("error: model.name"), "{line}");
    assert!(line.contains("/nonexistent/model.safetensors"), "{line}");

    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("garbage.safetensors");
    std::fs::write(&file, b"not a model at all, just some bytes to read").unwrap();
    let line = fails_with_one_line(&["--model".into(), file.clone().into()]);
    assert!(line.starts_with("error: model.name"), "{line}");
    assert!(line.contains(&*file.to_string_lossy()), "{line}");
}
