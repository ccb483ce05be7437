//! The binary's start-up errors: a bad domain id or frame id is one clear error line
//! and a non-zero exit, before any network or shared memory is touched (so these run
//! anywhere, without a network namespace).

use std::process::Command;

/// Runs `ghnet-ros2` with `args` (and `env`), expecting it to fail; its stderr.
fn fails(args: &[&str], env: &[(&str, &str)]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_ghnet-ros2"))
        .args(args)
        .env_remove("ROS_DOMAIN_ID")
        .envs(env.iter().copied())
        .output()
        .expect("run ghnet-ros2");
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(
        !out.status.success(),
        "{args:?} {env:?} succeeded: {stderr}"
    );
    assert_eq!(stderr.trim_end().lines().count(), 1, "one line: {stderr}");
    stderr
}

#[test]
fn a_bad_domain_or_frame_id_is_one_error_line_and_a_failure() {
    let e = fails(&["--domain-id", "233"], &[]);
    assert!(
        e.starts_with("error: --domain-id: domain id 233 is out of range (0 to 232)"),
        "{e}"
    );
    let e = fails(&[], &[("ROS_DOMAIN_ID", "1000")]);
    assert!(e.contains("domain id 1000 is out of range"), "{e}");
    for bad in ["/gnss", "gnss antenna", "2gnss", "a__b", ""] {
        let e = fails(&["--frame-id", bad], &[]);
        assert!(
            e.starts_with(&format!(
                "error: --frame-id: frame id `{bad}` is not a valid ROS name"
            )),
            "{e}"
        );
    }
    let e = fails(&["--source", "gnss-a", "--source", "gnss_a"], &[]);
    assert!(
        e.contains("sources `gnss-a` and `gnss_a` both map to the ROS topic /ghnet/gnss_a/heading"),
        "{e}"
    );
}

#[test]
fn a_domain_id_that_is_not_a_number_is_refused_by_the_parser() {
    let out = Command::new(env!("CARGO_BIN_EXE_ghnet-ros2"))
        .env("ROS_DOMAIN_ID", "seven")
        .output()
        .expect("run ghnet-ros2");
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("invalid value 'seven'"), "{stderr}");
}
