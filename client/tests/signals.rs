//! Ctrl-C with the helpers: once iceoryx2 captures SIGINT (at the latest from the
//! first `termination_requested()`), a publisher loop must poll it. Runs the publisher
//! as a child process (signals in the test process would hit every test).

use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use ghnet_client::testing::TestNamespace;
use ghnet_client::{IpcConfig, VelocityPublisher, VelocitySample};

const CHILD_ENV: &str = "GHNET_CLIENT_SIGNAL_CHILD";

#[test]
#[ignore = "spawned as a child process by sigint_stops_a_polling_publisher"]
fn child_polling_publisher() {
    let Ok(spec) = std::env::var(CHILD_ENV) else {
        return;
    };
    let (prefix, root) = spec.split_once('|').unwrap();
    let gnss = VelocityPublisher::new(&IpcConfig::isolated(prefix, root).unwrap(), "sig").unwrap();
    // The first poll installs iceoryx2's capturing handler (creating the publisher
    // need not have): a SIGINT before it would still kill the process the default way.
    let mut stop = ghnet_client::termination_requested();
    println!("ready");
    let mut seq = 0;
    while !stop {
        gnss.send(VelocitySample::new(0, seq, 1.0, 0.0, 0.0))
            .unwrap();
        seq += 1;
        std::thread::sleep(Duration::from_millis(5));
        stop = ghnet_client::termination_requested();
    }
    println!("stopped cleanly");
}

#[test]
fn sigint_stops_a_polling_publisher() {
    let ns = TestNamespace::new("sig");
    let mut child = Command::new(std::env::current_exe().unwrap())
        .args([
            "--exact",
            "child_polling_publisher",
            "--ignored",
            "--nocapture",
        ])
        .env(
            CHILD_ENV,
            format!("{}|{}", ns.global_prefix(), ns.root_path().display()),
        )
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    // Wait for the child to say it has sent (the publisher port alone appears before
    // iceoryx2 installs its handler), then interrupt it.
    let mut out = std::io::BufReader::new(child.stdout.take().unwrap());
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let mut all = String::new();
        let mut line = String::new();
        while std::io::BufRead::read_line(&mut out, &mut line).unwrap_or(0) > 0 {
            if line.trim() == "ready" {
                let _ = tx.send(None);
            }
            all.push_str(&line);
            line.clear();
        }
        let _ = tx.send(Some(all));
    });
    match rx.recv_timeout(Duration::from_secs(20)) {
        Ok(None) => {}
        other => {
            let _ = child.kill();
            let _ = child.wait(); // reap
            panic!("child never became ready: {other:?}");
        }
    }
    assert_eq!(unsafe { libc::kill(child.id() as i32, libc::SIGINT) }, 0);
    let t0 = Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        if t0.elapsed() > Duration::from_secs(20) {
            let _ = child.kill();
            let _ = child.wait(); // reap
            panic!("publisher ignored SIGINT");
        }
        std::thread::sleep(Duration::from_millis(5));
    };
    let stdout = rx
        .recv_timeout(Duration::from_secs(20))
        .ok()
        .flatten()
        .unwrap_or_default();
    assert!(status.success(), "{status:?}");
    assert!(stdout.contains("stopped cleanly"), "{stdout}");
}
