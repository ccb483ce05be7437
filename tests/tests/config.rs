//! Bad configuration: a one-line error on stderr and a non-zero exit, before any
//! iceoryx2 resource exists.

use std::ffi::OsString;
use std::path::PathBuf;

use ghnet_testkit::{run_ghnetd, test_model, TestNamespace};

/// Runs ghnetd in a fresh namespace with `args`; asserts a non-zero exit and that
/// stderr is exactly one `error: ...` line; returns that line.
fn fails_with_one_line(args: &[OsString]) -> String {
    let ns = TestNamespace::new("config");
    let out = run_ghnetd(&ns, args);
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
    let line = config_file_fails(b"[sources]\ndiscovery = true\ndiscovry_interval_ms = 5\n");
    assert!(line.contains("discovry_interval_ms"), "{line}");
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

/// Writes `text` as a config file and runs ghnetd on it; returns the error line,
/// which must name the file.
fn config_file_fails(text: &[u8]) -> String {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("ghnetd.toml");
    std::fs::write(&file, text).unwrap();
    let line = fails_with_one_line(&["--config".into(), file.clone().into()]);
    assert!(
        line.contains(&*file.to_string_lossy()),
        "names the file: {line}"
    );
    line
}

#[test]
fn wrong_types_name_the_line_and_key() {
    for (text, line_no, key) in [
        ("[sources]\ndiscovery = \"yes\"\n", 2, "discovery"),
        ("[sources]\nmax_sources = -3\n", 2, "max_sources"),
        ("[sources]\nstatic = \"gnss0\"\n", 2, "static"),
        ("\n[model]\nmax_speed = \"fast\"\n", 3, "max_speed"),
        ("[stats]\ninterval_s = 1.5\n", 2, "interval_s"),
        ("[zenoh]\nlisten = \"tcp/127.0.0.1:0\"\n", 2, "listen"),
        ("[ipc]\nservice_prefix = 12\n", 2, "service_prefix"),
        ("sources = 5\n", 1, "sources"),
        ("[zenoh]\nenabled = 1\n", 2, "enabled"),
    ] {
        let line = config_file_fails(text.as_bytes());
        assert!(
            line.contains(&format!("line {line_no} ")),
            "{text:?}: {line}"
        );
        assert!(line.contains(key), "{text:?} must name `{key}`: {line}");
        assert!(line.contains("invalid"), "{text:?}: {line}");
    }
}

#[test]
fn unknown_keys_top_level_section_and_nested_are_named() {
    for (text, key) in [
        ("verbose = true\n", "verbose"),
        ("[zenohh]\nenabled = false\n", "zenohh"),
        ("[model]\nnmae = \"paper-s1\"\n", "nmae"),
        ("[zenoh]\nenabled = true\n[zenoh.extra]\nx = 1\n", "extra"),
    ] {
        let line = config_file_fails(text.as_bytes());
        assert!(line.contains(key), "{text:?} must name `{key}`: {line}");
        assert!(line.contains("unknown field"), "{text:?}: {line}");
    }
}

#[test]
fn toml_syntax_errors_and_non_utf8_files() {
    for text in [
        &b"[sources\n"[..],
        b"[sources]\nstatic = [\"a\"\n",
        b"= 3\n",
        b"\xff\xfe[sources]\n",
    ] {
        config_file_fails(text);
    }
}

#[test]
fn unreadable_config_path() {
    let dir = tempfile::tempdir().unwrap();
    // A directory where a file should be (root reads any mode, so no chmod test).
    let line = fails_with_one_line(&["--config".into(), dir.path().into()]);
    assert!(line.contains("cannot read config file"), "{line}");
    assert!(line.contains(&*dir.path().to_string_lossy()), "{line}");
}

#[test]
fn missing_model_file_named_in_the_config_file() {
    // The model is loaded after the config is read, so the line names the key and the
    // model path (not the config file).
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("ghnetd.toml");
    std::fs::write(&file, b"[model]\nname = \"/nonexistent/m.safetensors\"\n").unwrap();
    let line = fails_with_one_line(&["--config".into(), file.into()]);
    assert!(line.starts_with("error: model.name"), "{line}");
    assert!(line.contains("/nonexistent/m.safetensors"), "{line}");
}

/// Safetensors bytes of the test model with its weights replaced by `params`
/// (metadata unchanged), written through the models crate's weights API.
/// A built-in model with network tensors to break (the default, `kf`, has none).
fn network_model() -> ghnet_inference::Model {
    ghnet_inference::Model::builtin("ghnet-epoch").unwrap()
}

fn model_file(dir: &std::path::Path, params: &ghnet_inference::params::ParamSet) -> PathBuf {
    let meta = network_model().meta().clone();
    let file = dir.join("model.safetensors");
    ghnet_inference::weights::write(&file, params, &meta).unwrap();
    file
}

#[test]
fn model_file_with_wrong_shapes_names_the_tensor() {
    let dir = tempfile::tempdir().unwrap();
    let model = &network_model();
    // One more output of the first convolution: conv1.* get 1 more row than the
    // metadata's architecture says.
    let mut arch = model.meta().architecture.clone();
    arch.conv[0] += 1;
    let file = model_file(dir.path(), &ghnet_inference::params::ParamSet::zeros(&arch));
    let line = fails_with_one_line(&["--model".into(), file.clone().into()]);
    assert!(line.starts_with("error: model.name"), "{line}");
    assert!(line.contains(&*file.to_string_lossy()), "{line}");
    assert!(line.contains("tensor `conv1.weight` has shape"), "{line}");
}

#[test]
fn model_file_with_non_finite_weights_names_the_tensor() {
    let dir = tempfile::tempdir().unwrap();
    let mut params = network_model().params().clone();
    let r = params.range(params.index_of("fc1.bias").unwrap());
    params.data_mut()[r.start] = f32::NAN;
    let file = model_file(dir.path(), &params);
    let line = fails_with_one_line(&["--model".into(), file.into()]);
    assert!(
        line.contains("tensor `fc1.bias` contains non-finite"),
        "{line}"
    );
}

#[test]
fn model_path_that_is_not_a_model() {
    let dir = tempfile::tempdir().unwrap();
    let empty = dir.path().join("empty.safetensors");
    std::fs::write(&empty, b"").unwrap();
    let truncated = dir.path().join("truncated.safetensors");
    let bytes = test_model().model.to_safetensors();
    std::fs::write(&truncated, &bytes[..bytes.len() / 2]).unwrap();
    for path in [empty, truncated, dir.path().to_path_buf()] {
        let line = fails_with_one_line(&["--model".into(), path.clone().into()]);
        assert!(line.starts_with("error: model.name"), "{path:?}: {line}");
        assert!(line.contains(&*path.to_string_lossy()), "{line}");
    }
}

#[test]
fn print_config_prints_the_effective_toml() {
    let ns = TestNamespace::new("printcfg");
    let args = ["--print-config", "--source", "gnss0", "--max-speed", "50"];
    let out = run_ghnetd(&ns, &args.map(OsString::from));
    assert!(out.status.success(), "{out:?}");
    let text = String::from_utf8(out.stdout).unwrap();
    let cfg = ghnetd::Config::from_toml(&text).unwrap();
    assert_eq!(cfg.sources.static_sources, vec!["gnss0"]);
    assert_eq!(cfg.model.max_speed, 50.0);
    assert_eq!(
        cfg.ipc.iceoryx2_global_prefix.as_deref(),
        Some(ns.global_prefix())
    );
}
