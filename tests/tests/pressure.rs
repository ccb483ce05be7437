//! Reliability under pressure: every pressure row of the reliability tables
//! (tests/tools/README.md) through real processes. Sources ghnetd cannot open are listed
//! in the stats with the reason and retried until served; descriptors and shared memory
//! running out are reported by name and never take ghnetd or the other sources down;
//! hostile model files, root paths, source names and `ghnet infer` arguments are refused
//! or reported in one line.

use std::ffi::OsString;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::Duration;

use ghnet_client::{
    HeadingSubscriber, ServiceSettings, VelocityPublisher, VelocitySample, VelocitySubscriber,
    SERVICE_SETTINGS,
};
use ghnet_testkit::{
    find_binary, foreign_service, moving_sample, round_trip, run_ghnetd, wait_until, Ghnetd,
    TestNamespace,
};

/// Waits until `daemon`'s stats satisfy `cond`; returns them.
fn stats_when(
    daemon: &Ghnetd,
    what: &str,
    cond: impl Fn(&serde_json::Value) -> bool,
) -> serde_json::Value {
    let mut last = serde_json::Value::Null;
    daemon.wait_until(what, || {
        last = daemon.stats();
        cond(&last)
    });
    last
}

/// Row 1: all subscriber slots of a velocity service held when ghnetd finds it, freed
/// later: listed as unserved with the reason and a retry count meanwhile, then served.
#[test]
fn a_source_with_its_slots_held_is_retried_and_served_once_they_free() {
    let ns = TestNamespace::new("prslots");
    let ipc = ns.ipc();
    let held: Vec<_> = (0..SERVICE_SETTINGS.max_subscribers)
        .map(|_| VelocitySubscriber::new(&ipc, "held").unwrap())
        .collect();
    let gnss = VelocityPublisher::new(&ipc, "held").unwrap();
    let daemon = Ghnetd::builder(&ns).start();
    let stats = stats_when(&daemon, "held unserved and retried", |s| {
        s["unserved"]["held"]["retries"].as_u64() >= Some(2)
    });
    let reason = stats["unserved"]["held"]["reason"].as_str().unwrap();
    assert!(reason.contains("subscriber slots in use"), "{reason}");
    assert!(stats["sources"].get("held").is_none(), "{stats}");

    drop(held);
    daemon.wait_serving(&gnss);
    let headings = HeadingSubscriber::new(&ipc, "held").unwrap();
    round_trip(&gnss, &headings, 0);
    stats_when(&daemon, "held served, no longer unserved", |s| {
        s["sources"]["held"]["served"] == true && s["unserved"].get("held").is_none()
    });
    let log = daemon.stop();
    assert_eq!(
        log.matches("cannot serve discovered source").count(),
        1,
        "warned once, retried quietly: {log}"
    );
    assert!(log.contains("source served after all"), "{log}");
}

/// ghnetd allowed 200 sources under `prlimit --nofile=<nofile>` (soft:hard), then
/// 150 sources with a publisher each, named `s<i>`.
fn ghnetd_and_150_publishers(ns: &TestNamespace, nofile: &str) -> (Ghnetd, Vec<VelocityPublisher>) {
    // ghnetd first: a child inherits the test process's iceoryx2 descriptors that
    // lack O_CLOEXEC (about 8 per port here), which would eat its budget.
    let daemon = Ghnetd::builder(ns)
        .wrapper(&["prlimit", &format!("--nofile={nofile}"), "--"])
        .arg("--max-sources")
        .arg("200")
        .start();
    let ipc = ns.ipc();
    let gnss = (0..150)
        .map(|i| VelocityPublisher::new(&ipc, &format!("s{i}")).unwrap())
        .collect();
    (daemon, gnss)
}

/// Row 2a: 150 sources under systemd's default soft descriptor limit (1024) with a
/// higher hard limit: ghnetd raises the soft limit and serves them all.
#[test]
fn with_a_higher_hard_limit_ghnetd_raises_the_soft_one_and_serves_150_sources() {
    let ns = TestNamespace::new("prfd150");
    let (daemon, gnss) = ghnetd_and_150_publishers(&ns, "1024:8192");
    stats_when(&daemon, "150 sources served", |s| {
        s["sources"].as_object().map(|m| m.len()) == Some(150)
    });
    for (i, p) in gnss.iter().enumerate() {
        p.send(moving_sample(0)).unwrap();
        daemon.wait_for_counters(&format!("s{i}"), |c| c["answered"] >= 1);
    }
    let log = daemon.stop();
    assert!(
        log.contains("raised the soft descriptor limit to the hard limit"),
        "{log}"
    );
    assert!(log.contains("fd_limit=8192"), "{log}");
    assert!(!log.contains("panicked"), "{log}");
}

/// Row 2b: the hard limit is 1024 too. The sources that fit are served; the rest are
/// listed naming descriptors (never an opaque InternalFailure) and retried; discovery
/// and Zenoh go on; a warning at start says the limit cannot cover max_sources.
#[test]
fn at_a_hard_limit_of_1024_the_sources_over_it_are_reported_naming_descriptors() {
    let ns = TestNamespace::new("prfd1024");
    let (daemon, gnss) = ghnetd_and_150_publishers(&ns, "1024:1024");
    let stats = stats_when(&daemon, "every source served or unserved", |s| {
        let served = s["sources"].as_object().map_or(0, |m| m.len());
        let unserved = s["unserved"].as_object().map_or(0, |m| m.len());
        served > 0 && served + unserved == 150
    });
    let served = stats["sources"].as_object().unwrap().len();
    assert!((30..150).contains(&served), "{served} served: {stats}");
    for (name, u) in stats["unserved"].as_object().unwrap() {
        let reason = u["reason"].as_str().unwrap();
        assert!(
            reason.contains("file descriptors (limit 1024)"),
            "{name}: {reason}"
        );
        assert!(!reason.contains("InternalFailure"), "{name}: {reason}");
    }
    // Served sources answer; the others are retried (the count grows).
    gnss[0].send(moving_sample(0)).unwrap();
    let first_served = stats["sources"].as_object().unwrap().keys().next().unwrap();
    daemon.wait_for_counters(first_served, |c| c["received"] >= 1);
    let some_unserved = stats["unserved"]
        .as_object()
        .unwrap()
        .keys()
        .next()
        .unwrap();
    let retries = stats["unserved"][some_unserved]["retries"]
        .as_u64()
        .unwrap();
    stats_when(&daemon, "retried again", |s| {
        s["unserved"][some_unserved]["retries"].as_u64() > Some(retries)
    });
    daemon.assert_running();
    let log = daemon.stop();
    assert!(
        log.contains("the descriptor limit cannot cover sources.max_sources"),
        "{log}"
    );
    assert!(!log.contains("panicked"), "{log}");
    assert!(!log.contains("InternalFailure"), "{log}");
}

/// Row 3 (outer): runs [`dev_shm_full_inner`] in a private mount namespace with a
/// small tmpfs on /dev/shm.
#[test]
#[ignore = "needs root (mount namespace)"]
fn a_full_dev_shm_is_reported_and_the_source_served_once_space_frees() {
    let exe = std::env::current_exe().unwrap();
    let script = "mount -t tmpfs -o size=16m tmpfs /dev/shm && exec \"$0\" \
                  pressure::dev_shm_full_inner --exact --include-ignored --nocapture";
    let out = Command::new("unshare")
        .args(["-m", "--propagation", "private", "sh", "-c", script])
        .arg(&exe)
        .env("GHNET_SHM_INNER", "1")
        .stdin(Stdio::null())
        .output()
        .unwrap();
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(out.status.success(), "{:?}\n{text}", out.status);
    assert!(text.contains("1 passed"), "{text}");
}

/// Bytes free on /dev/shm.
fn shm_free() -> u64 {
    let path = std::ffi::CString::new("/dev/shm").unwrap();
    // SAFETY: statvfs writes only into `st`.
    let mut st: libc::statvfs = unsafe { std::mem::zeroed() };
    assert_eq!(unsafe { libc::statvfs(path.as_ptr(), &mut st) }, 0);
    st.f_bavail as u64 * st.f_frsize as u64
}

/// Row 3 (inner; only does something under the outer test): ghnetd serves `a`; a
/// ballast file leaves less than a source needs; `b` is reported naming /dev/shm and
/// its free space, ghnetd and `a` go on (no SIGBUS); the ballast goes and `b` is served.
#[test]
#[ignore = "run by a_full_dev_shm_is_reported_and_the_source_served_once_space_frees"]
fn dev_shm_full_inner() {
    if std::env::var_os("GHNET_SHM_INNER").is_none() {
        return;
    }
    let ns = TestNamespace::new("prshm");
    let ipc = ns.ipc();
    let daemon = Ghnetd::builder(&ns).start();
    let (a, a_headings) = daemon.ends("a");
    round_trip(&a, &a_headings, 0);
    // What ghnetd says a source needs, from its budget line.
    let log = daemon.log();
    let need: u64 = log
        .split("shm_per_source=")
        .nth(1)
        .and_then(|r| r.split_whitespace().next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no shm_per_source in {log}"));
    // Leave about one source's worth: more than a publisher needs, less than ghnetd's
    // check with its margin.
    let ballast_path = Path::new("/dev/shm").join(format!("{}ballast", ns.global_prefix()));
    let keep = need + need / 8;
    let size = shm_free().saturating_sub(keep);
    std::fs::write(&ballast_path, vec![1u8; size as usize]).unwrap();
    let b = VelocityPublisher::new(&ipc, "b").unwrap();
    let stats = stats_when(&daemon, "b unserved", |s| s["unserved"]["b"].is_object());
    let reason = stats["unserved"]["b"]["reason"].as_str().unwrap();
    assert!(
        reason.contains("/dev/shm has") && reason.contains("bytes free"),
        "{reason}"
    );
    round_trip(&a, &a_headings, 1);
    daemon.assert_running();
    // Then not one byte left: a source opened earlier has its pages (iceoryx2 writes
    // every segment when it creates it), so answering `a` through all its slots again
    // and again must not SIGBUS.
    let rest_path = Path::new("/dev/shm").join(format!("{}rest", ns.global_prefix()));
    fill(&rest_path);
    assert_eq!(shm_free(), 0, "/dev/shm should be full");
    for seq in 2..130 {
        round_trip(&a, &a_headings, seq);
    }
    daemon.assert_running();
    std::fs::remove_file(&rest_path).unwrap();

    std::fs::remove_file(&ballast_path).unwrap();
    daemon.wait_serving(&b);
    let b_headings = HeadingSubscriber::new(&ipc, "b").unwrap();
    round_trip(&b, &b_headings, 0);
    round_trip(&a, &a_headings, 130);
    daemon.stop();
}

/// Writes `path` until the file system is full (the error that ends it is ENOSPC).
fn fill(path: &Path) {
    use std::io::Write;
    let mut f = std::fs::File::create(path).unwrap();
    let chunk = vec![1u8; 64 * 1024];
    let mut size = chunk.len();
    while size > 0 {
        match f.write(&chunk[..size]) {
            Ok(0) => size /= 2,
            Ok(_) => {}
            Err(e) if e.raw_os_error() == Some(28) => size /= 2,
            Err(e) => panic!("filling {}: {e}", path.display()),
        }
    }
}

/// Runs ghnetd with `--model path` to its exit; returns the one stderr line.
fn model_refused(ns: &TestNamespace, path: &Path) -> String {
    let args: Vec<OsString> = vec![
        "--model".into(),
        path.into(),
        "--zenoh".into(),
        "false".into(),
    ];
    let out = run_ghnetd(ns, &args);
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert_eq!(err.trim_end().lines().count(), 1, "one line: {err}");
    err
}

/// Rows 4-6: `/dev/zero`, a FIFO, a directory and a 2 GB sparse file as the model:
/// refused in one line, from the file's type and size, before reading (the FIFO has
/// no writer: reading it would block for ever; the sparse file would take 2 GB).
#[test]
fn model_paths_that_are_not_small_regular_files_are_refused_in_one_line() {
    let ns = TestNamespace::new("prmodel");
    let dir = ns.scratch_dir("models");
    let err = model_refused(&ns, Path::new("/dev/zero"));
    assert!(
        err.contains("is a character device, not a regular file"),
        "{err}"
    );
    let fifo = dir.join("fifo");
    let c = std::ffi::CString::new(fifo.to_str().unwrap()).unwrap();
    // SAFETY: mkfifo reads a valid C string.
    assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
    let err = model_refused(&ns, &fifo);
    assert!(err.contains("is a FIFO, not a regular file"), "{err}");
    let err = model_refused(&ns, &dir);
    assert!(err.contains("is a directory"), "{err}");
    let sparse = dir.join("sparse.safetensors");
    std::fs::File::create(&sparse)
        .unwrap()
        .set_len(2 << 30)
        .unwrap();
    let err = model_refused(&ns, &sparse);
    assert!(
        err.contains("is 2147483648 bytes, over the 67108864-byte limit"),
        "{err}"
    );
}

/// Row 4, signals: SIGTERM while ghnetd starts (here: loading a large model file)
/// ends it promptly, with a line, not after the load has run its course.
#[test]
fn sigterm_during_start_up_ends_ghnetd() {
    let ns = TestNamespace::new("prsigterm");
    let big = ns.scratch_dir("models").join("big.safetensors");
    std::fs::write(&big, vec![0u8; 60 << 20]).unwrap();
    let daemon = Ghnetd::builder(&ns).model(big.to_str().unwrap()).spawn();
    // Once its SIGTERM handler is installed (bit 15 of SigCgt), before or during the
    // model load.
    let status = format!("/proc/{}/status", daemon.pid());
    wait_until("ghnetd catches SIGTERM", || {
        let text = std::fs::read_to_string(&status).unwrap_or_default();
        let caught = text.lines().find_map(|l| l.strip_prefix("SigCgt:"));
        caught.is_some_and(|m| u64::from_str_radix(m.trim(), 16).unwrap_or(0) & (1 << 14) != 0)
    });
    daemon.signal(libc::SIGTERM);
    let (status, log) = daemon.wait_exit();
    // Either the load is refused first (exit 1, one error line) or the signal is
    // seen after it (exit 0); never killed by the signal, never hanging.
    assert!(matches!(status.code(), Some(0 | 1)), "{status:?}: {log}");
}

/// Row 7: two static sources, a consumer created one's heading service with smaller
/// limits: the other is served, ghnetd keeps running, the first is listed as unserved
/// and retried.
#[test]
fn a_static_source_that_cannot_be_opened_does_not_take_the_other_down() {
    let ns = TestNamespace::new("prstatic");
    let ipc = ns.ipc();
    let small = ipc
        .clone()
        .with_settings(ServiceSettings::with_limits(4, 2, 16, 64));
    let _consumer = HeadingSubscriber::new(&small, "tiny").unwrap();
    let daemon = Ghnetd::builder(&ns)
        .discovery(false)
        .source("tiny")
        .source("fine")
        .start();
    let (fine, fine_headings) = daemon.ends("fine");
    round_trip(&fine, &fine_headings, 0);
    let stats = stats_when(&daemon, "tiny unserved and retried", |s| {
        s["unserved"]["tiny"]["retries"].as_u64() >= Some(1)
    });
    let reason = stats["unserved"]["tiny"]["reason"].as_str().unwrap();
    assert!(reason.contains("(ipc.max_subscribers)"), "{reason}");
    daemon.assert_running();
    round_trip(&fine, &fine_headings, 1);
    let log = daemon.stop();
    assert!(log.contains("cannot serve static source"), "{log}");
}

/// Runs `ghnet` with `args` to its exit: (status code, stderr).
fn ghnet(args: &[&std::ffi::OsStr]) -> (Option<i32>, String) {
    let out = Command::new(find_binary("ghnet").unwrap())
        .args(args)
        .stdin(Stdio::null())
        .output()
        .unwrap();
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// Row 8: `ghnet infer --input X --output X`, and through a hard and a symbolic link:
/// refused before anything is created, X untouched.
#[test]
fn infer_refuses_an_output_that_is_the_input() {
    let dir = tempfile::tempdir().unwrap();
    let x = dir.path().join("x.csv");
    let text = "v_north,v_east\n1,1\n";
    std::fs::write(&x, text).unwrap();
    let hard = dir.path().join("hard.csv");
    std::fs::hard_link(&x, &hard).unwrap();
    let soft = dir.path().join("soft.csv");
    std::os::unix::fs::symlink(&x, &soft).unwrap();
    for out in [&x, &hard, &soft] {
        let (code, err) = ghnet(&[
            "infer".as_ref(),
            "--input".as_ref(),
            x.as_os_str(),
            "--output".as_ref(),
            out.as_os_str(),
        ]);
        assert_ne!(code, Some(0), "{err}");
        assert!(err.contains("is the input file"), "{err}");
        assert_eq!(std::fs::read_to_string(&x).unwrap(), text);
    }
}

/// Row 9: rows with too few or too many fields are `invalid`, and every output row has
/// the output header's width.
#[test]
fn infer_rows_with_a_wrong_field_count_are_invalid_and_aligned() {
    let dir = tempfile::tempdir().unwrap();
    let (input, output) = (dir.path().join("in.csv"), dir.path().join("out.csv"));
    std::fs::write(&input, "t,v_north,v_east\n1,3,4\n2,3\n3,3,4,5\n4,3,4\n").unwrap();
    let (code, err) = ghnet(&[
        "infer".as_ref(),
        "--input".as_ref(),
        input.as_os_str(),
        "--output".as_ref(),
        output.as_os_str(),
    ]);
    assert_eq!(code, Some(0), "{err}");
    let out = std::fs::read_to_string(&output).unwrap();
    let lines: Vec<&str> = out.lines().collect();
    assert_eq!(lines.len(), 5, "{out}");
    for l in &lines {
        assert_eq!(l.split(',').count(), 6, "{out}");
    }
    assert!(
        lines[2].ends_with(",invalid") && lines[3].ends_with(",invalid"),
        "{out}"
    );
    assert!(
        !lines[1].ends_with(",invalid") && !lines[4].ends_with(",invalid"),
        "{out}"
    );
}

/// Row 10: velocity services whose source name breaks the rules are logged once each,
/// at warn, with the rule, over several discovery passes.
#[test]
fn bad_source_names_are_logged_once_each_with_the_rule() {
    let ns = TestNamespace::new("prnames");
    let node = ns.foreign_node();
    let long = "x".repeat(65);
    let names = ["gnss.0", long.as_str(), "a b"];
    let _services: Vec<_> = names
        .iter()
        .map(|n| {
            let svc = foreign_service::<VelocitySample>(&node, &format!("ghnet/{n}/velocity"));
            let publisher = svc.publisher_builder().create().unwrap();
            (svc, publisher)
        })
        .collect();
    let daemon = Ghnetd::builder(&ns).start();
    let (ok, ok_headings) = daemon.ends("ok");
    round_trip(&ok, &ok_headings, 0);
    daemon.wait_for_log_count("its source name breaks the naming rules", 3);
    // Several more passes (one every 100 ms in tests, a full listing every 5 s).
    std::thread::sleep(Duration::from_secs(6));
    let log = daemon.stop();
    assert_eq!(
        log.matches("its source name breaks the naming rules")
            .count(),
        3,
        "{log}"
    );
    assert!(log.contains("WARN"), "{log}");
    assert!(log.contains("longer than 64 bytes"), "{log}");
    assert!(log.contains("gnss.0"), "{log}");
}

/// Row 11: a root path of `/` (and other directories ghnetd must not own) is a
/// config error: one line, exit 1, nothing created.
#[test]
fn a_root_path_ghnetd_may_not_own_is_a_config_error() {
    let ns = TestNamespace::new("prroot");
    let file = ns.scratch_dir("root").join("file");
    std::fs::write(&file, "").unwrap();
    let open = ns.scratch_dir("root").join("open");
    std::fs::create_dir(&open).unwrap();
    std::fs::set_permissions(&open, std::os::unix::fs::PermissionsExt::from_mode(0o777)).unwrap();
    let cases: [(&Path, &str); 4] = [
        (Path::new("/"), "is the filesystem root"),
        (Path::new("/proc/self"), "is under /proc"),
        (&file, "is not a directory"),
        (&open, "world-writable without the sticky bit"),
    ];
    for (root, expect) in cases {
        let before: Vec<_> = std::fs::read_dir("/")
            .unwrap()
            .flatten()
            .map(|e| e.path())
            .collect();
        let out = Command::new(find_binary("ghnetd").unwrap())
            .arg("--iceoryx2-global-prefix")
            .arg(ns.global_prefix())
            .arg("--iceoryx2-root-path")
            .arg(root)
            .args(["--zenoh", "false"])
            .env_remove("GHNETD_CONFIG")
            .stdin(Stdio::null())
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{}: {err}", root.display());
        assert_eq!(err.trim_end().lines().count(), 1, "{err}");
        assert!(
            err.contains("ipc.iceoryx2_root_path") && err.contains(expect),
            "{err}"
        );
        let after: Vec<_> = std::fs::read_dir("/")
            .unwrap()
            .flatten()
            .map(|e| e.path())
            .collect();
        assert_eq!(before, after, "nothing created in /");
        assert_eq!(std::fs::read_dir(&open).unwrap().count(), 0);
    }
}
