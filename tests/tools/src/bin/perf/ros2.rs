//! The ROS 2 bridge's cost (`--only ros2`, not part of the default run: it needs
//! root, `ip`, `ghnet-ros2` and the kit's `ghnet-test-publisher` next to this
//! executable, and python3 with the ROS 2 wheels
//! `ros-rclpy ros-rmw-fastrtps-cpp ros-sensor-msgs`).
//!
//! `--ros2-sources` kit publishers at 10 Hz each feed a real ghnetd; `ghnet-ros2`
//! (DDS) and an rclpy node (`client/ros2/tests/rclpy_listener.py`, Fast DDS) run in a
//! network namespace of their own with multicast on its loopback, so DDS discovery
//! stays inside it. This process receives ghnetd's answers on iceoryx2 too and notes
//! when each came (polled every 100 µs); the rclpy node prints when its callback ran.
//! Both read the system clock, so the difference is the bridge's added latency,
//! ghnetd answer → rclpy callback, good to about 0.1 ms. Over `--ros2-seconds`
//! (after 5 s of settling): that latency, the sample → callback latency, the bridge's
//! CPU share of one core and its resident memory.

use std::collections::HashMap;
use std::io::{BufRead, BufReader};
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{mpsc, Arc};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use anyhow::Context;
use ghnet_client::{HeadingStatus, HeadingSubscriber, IpcConfig};
use ghnet_testkit::{find_binary, ChildPublisher, Ghnetd, NetNamespace, TestNamespace};
use ghnet_tools::Percentiles;

use crate::target::{cpu_time_ns, Env};
use crate::{info, Args, Row};

/// Publishing rate of every source, Hz.
const RATE_HZ: u32 = 10;
/// Time before the measured window: DDS discovery, first answers.
const SETTLE: Duration = Duration::from_secs(5);

/// A child killed and reaped on drop.
struct Reaped(Child);

impl Drop for Reaped {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn unix_ns() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as u64)
}

/// When this process received each answer, by (source index, sample timestamp),
/// until `stop`. Ports are per thread: the subscribers are made on the thread.
fn answer_times(
    ipc: IpcConfig,
    sources: Vec<String>,
    stop: Arc<AtomicBool>,
) -> std::thread::JoinHandle<anyhow::Result<HashMap<(usize, u64), u64>>> {
    std::thread::spawn(move || {
        let subs = (sources.iter().map(|s| HeadingSubscriber::new(&ipc, s)))
            .collect::<Result<Vec<_>, _>>()?;
        let mut seen = HashMap::new();
        while !stop.load(Ordering::Relaxed) {
            for (i, sub) in subs.iter().enumerate() {
                while let Some(h) = sub.try_recv()? {
                    if h.heading_status() != Some(HeadingStatus::Stale) {
                        seen.insert((i, h.timestamp_ns), unix_ns());
                    }
                }
            }
            std::thread::sleep(Duration::from_micros(100));
        }
        Ok(seen)
    })
}

/// One Imu the rclpy node got: (topic, sample time, callback time), ns.
fn callbacks(child: &mut Child) -> anyhow::Result<mpsc::Receiver<(String, u64, u64)>> {
    let stdout = child.stdout.take().context("listener stdout")?;
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stdout).lines().map_while(Result::ok) {
            let parsed = serde_json::from_str::<serde_json::Value>(&line).ok();
            let imu = parsed.and_then(|v| {
                let stamp = v["stamp"].as_array()?;
                let t = stamp[0].as_u64()? * 1_000_000_000 + stamp[1].as_u64()?;
                Some((
                    v["topic"].as_str()?.to_owned(),
                    t,
                    v["received_ns"].as_u64()?,
                ))
            });
            let ready = line == "ready";
            let msg = imu.unwrap_or_else(|| (String::new(), u64::from(ready), 0));
            if tx.send(msg).is_err() {
                break;
            }
        }
    });
    Ok(rx)
}

fn listener_script() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../client/ros2/tests/rclpy_listener.py")
}

/// `p50 … ms, p99 … ms (n)` of `values_ns`.
fn ms_percentiles(values_ns: Vec<u64>) -> String {
    match Percentiles::of(values_ns) {
        Some(p) => format!(
            "p50 {:.2} ms, p99 {:.2} ms (n={})",
            crate::ms(p.p50),
            crate::ms(p.p99),
            p.count
        ),
        None => "no samples".into(),
    }
}

fn vm_kb(pid: u32, key: &str) -> anyhow::Result<u64> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status"))?;
    status
        .lines()
        .find_map(|l| {
            l.strip_prefix(key)?
                .trim()
                .strip_suffix(" kB")?
                .trim()
                .parse()
                .ok()
        })
        .with_context(|| format!("{key} of {pid}"))
}

/// Spawns `program args` in `host`; killed on drop.
fn in_host(
    host: &NetNamespace,
    program: &std::path::Path,
    args: &[String],
) -> anyhow::Result<Reaped> {
    let child = Command::new("ip")
        .args(host.exec().iter().skip(1))
        .arg(program)
        .args(args)
        .env("ROS_DOMAIN_ID", "21")
        .env("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp")
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .with_context(|| format!("{program:?} in {}", host.name()))?;
    Ok(Reaped(child))
}

/// `ghnet-ros2` on DDS in `host`, reading `ns`'s ghnetd.
fn spawn_bridge(ns: &TestNamespace, host: &NetNamespace) -> anyhow::Result<Reaped> {
    let flags = [
        "--iceoryx2-global-prefix".to_owned(),
        ns.global_prefix().to_owned(),
        "--iceoryx2-root-path".to_owned(),
        ns.root_path().display().to_string(),
        "--domain-id".to_owned(),
        "21".to_owned(),
    ];
    in_host(host, &find_binary("ghnet-ros2")?, &flags)
}

/// The rclpy node in `host`, subscribed to every source's topic and `/diagnostics`.
fn spawn_listener(host: &NetNamespace, sources: &[String]) -> anyhow::Result<Reaped> {
    let mut args = vec![
        listener_script().display().to_string(),
        "--wait-for".into(),
        "/diagnostics".into(),
        "--diagnostics".into(),
    ];
    for s in sources {
        args.extend(["--imu".to_owned(), format!("/ghnet/{s}/heading")]);
    }
    in_host(host, std::path::Path::new("python3"), &args)
}

/// (answer → callback, sample → callback) in ns, of the callbacks for samples from
/// `wall0` on.
fn latencies(
    heard: impl Iterator<Item = (String, u64, u64)>,
    answered: &HashMap<(usize, u64), u64>,
    sources: &[String],
    wall0: u64,
) -> (Vec<u64>, Vec<u64>) {
    let index: HashMap<String, usize> = (sources.iter().enumerate())
        .map(|(i, s)| (format!("/ghnet/{s}/heading"), i))
        .collect();
    let (mut added, mut total) = (Vec::new(), Vec::new());
    for (topic, stamp, called) in heard.filter(|(t, s, _)| !t.is_empty() && *s >= wall0) {
        total.push(called.saturating_sub(stamp));
        if let Some(at) = index.get(&topic).and_then(|i| answered.get(&(*i, stamp))) {
            added.push(called.saturating_sub(*at));
        }
    }
    (added, total)
}

/// The rows of the ROS 2 phase; see the module doc.
pub fn rows(args: &Args, env: &Env) -> anyhow::Result<Vec<Row>> {
    let ns = TestNamespace::new("perfros2");
    let host = NetNamespace::create("perfros2")?;
    host.enable_loopback_multicast()?;
    let daemon = (Ghnetd::builder(&ns).program(&env.ghnetd, &[]))
        .model(&env.model)
        .try_spawn()?;
    daemon.try_wait_ready(Duration::from_secs(60))?;
    let sources: Vec<String> = (0..args.ros2_sources).map(|i| format!("ros{i}")).collect();
    let stop = Arc::new(AtomicBool::new(false));
    let answers = answer_times(daemon.ipc().clone(), sources.clone(), stop.clone());
    let bridge = spawn_bridge(&ns, &host)?;
    let mut listener = spawn_listener(&host, &sources)?;
    let heard = callbacks(&mut listener.0)?;
    match heard.recv_timeout(Duration::from_secs(60)) {
        Ok((_, 1, 0)) => {}
        other => anyhow::bail!("rclpy listener not ready: {other:?}"),
    }
    let _publishers: Vec<ChildPublisher> = sources
        .iter()
        .map(|s| ChildPublisher::spawn(&ns, s, 0, RATE_HZ))
        .collect();
    std::thread::sleep(SETTLE);
    let pid = bridge.0.id();
    let (cpu0, t0, wall0) = (cpu_time_ns(pid)?, Instant::now(), unix_ns());
    std::thread::sleep(Duration::from_secs_f64(args.ros2_seconds));
    let (cpu1, elapsed) = (cpu_time_ns(pid)?, t0.elapsed());
    let (rss, peak) = (vm_kb(pid, "VmRSS:")?, vm_kb(pid, "VmHWM:")?);
    stop.store(true, Ordering::Relaxed);
    let answered = answers
        .join()
        .map_err(|_| anyhow::anyhow!("answer thread panicked"))??;
    let (added, total) = latencies(heard.try_iter(), &answered, &sources, wall0);
    let share = (cpu1 - cpu0).as_secs_f64() / elapsed.as_secs_f64();
    let load = format!("{} sources × {RATE_HZ} Hz, DDS", sources.len());
    Ok(vec![
        info(
            &format!("ROS 2 bridge: ghnetd answer → rclpy callback ({load})"),
            "–".into(),
            ms_percentiles(added),
        ),
        info(
            &format!("ROS 2 bridge: sample → rclpy callback ({load})"),
            "–".into(),
            ms_percentiles(total),
        ),
        info(
            &format!("ROS 2 bridge CPU ({load})"),
            "–".into(),
            format!("{:.1} % of one core", share * 100.0),
        ),
        info(
            "ROS 2 bridge resident memory",
            "–".into(),
            format!(
                "{:.1} MB (peak {:.1} MB)",
                rss as f64 / 1024.0,
                peak as f64 / 1024.0
            ),
        ),
    ])
}
