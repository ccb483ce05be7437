//! The kit's bins: each prints its usage and exits 2 on wrong arguments, and
//! `find_binary` finds them where the cross-process tests look.
//!
//! Being an integration test of this package also makes `cargo test --workspace` build
//! the bins (cargo builds a package's bins for its integration tests), which the
//! cross-process tests of `ghnet-tests` find next to their own executable.

use std::process::Command;

#[test]
fn bins_print_their_usage_and_are_found_next_to_the_tests() {
    let bins = [
        (
            "ghnet-test-publisher",
            env!("CARGO_BIN_EXE_ghnet-test-publisher"),
        ),
        (
            "ghnet-test-subscriber",
            env!("CARGO_BIN_EXE_ghnet-test-subscriber"),
        ),
        ("ghnet-test-router", env!("CARGO_BIN_EXE_ghnet-test-router")),
    ];
    for (name, path) in bins {
        let out = Command::new(path).output().expect("run the bin");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{name}: {stderr}");
        assert!(
            stderr.starts_with(&format!("usage: {name}")),
            "{name}: {stderr}"
        );
        let found = ghnet_testkit::find_binary(name).expect("found");
        assert_eq!(
            found.canonicalize().unwrap(),
            std::path::Path::new(path).canonicalize().unwrap()
        );
    }
}
