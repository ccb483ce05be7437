//! Footprint: CPU while idle, and start-to-ready (spawn → Zenoh liveliness token seen
//! here and the iceoryx2 services opened).

use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use ghnet_client::zenoh::sample::SampleKind;
use ghnet_client::zenoh::{Session, Wait};
use ghnet_client::VelocityPublisher;

use anyhow::Context;
use ghnet_tools::Percentiles;

use crate::target::{cpu_time_ns, Env, Kind, Spec, Target};
use crate::{ms, row, Args, Row};

/// CPU share of one core each target used over `window` while `publishers` (one per
/// source, connected but silent) keep its sources alive.
fn idle_cpu(
    targets: &[&Target],
    publishers: &[Vec<VelocityPublisher>],
    settle: Duration,
    window: Duration,
) -> anyhow::Result<Vec<f64>> {
    for (t, pubs) in targets.iter().zip(publishers) {
        t.wait_until("sources served", Duration::from_secs(30), || {
            pubs.iter().all(|p| p.subscriber_count() > 0)
        })?;
    }
    std::thread::sleep(settle);
    let before = targets
        .iter()
        .map(|t| cpu_time_ns(t.pid()))
        .collect::<anyhow::Result<Vec<_>>>()?;
    let t0 = Instant::now();
    std::thread::sleep(window);
    let elapsed = t0.elapsed().as_secs_f64();
    let mut shares = Vec::new();
    for (t, b) in targets.iter().zip(before) {
        t.check_running()?;
        // saturating: a thread that exited in the window took its time along.
        let used = cpu_time_ns(t.pid())?.saturating_sub(b);
        shares.push(used.as_secs_f64() / elapsed);
    }
    Ok(shares)
}

/// Spawn → ready, `runs` times: ready is when both the daemon's liveliness token
/// `<prefix>/@ghnetd/<zid>` has reached `session` (the daemon connects to it) and
/// its subscriber on a static source exists (iceoryx2 services opened). Polled every
/// 200 µs, so the figure is good to about that.
fn start_to_ready(
    env: &Env,
    session: &Session,
    session_endpoint: &str,
    runs: usize,
) -> anyhow::Result<Vec<Duration>> {
    let mut ready = Vec::with_capacity(runs);
    for _ in 0..runs {
        let spec = Spec {
            kind: Kind::Ghnetd,
            sources: vec!["ready0".into()],
            discovery: true,
            zenoh_connect: Some(session_endpoint.to_owned()),
        };
        let token_at: Arc<Mutex<Option<Instant>>> = Arc::default();
        let seen = token_at.clone();
        // Both watchers exist before the spawn, so the clock starts with the spawn.
        let mut t0 = Instant::now();
        let (target, (gnss, _tokens)) = Target::spawn_with(env, &spec, |ipc| {
            let gnss = VelocityPublisher::new(ipc, "ready0")?;
            let tokens = session
                .liveliness()
                .declare_subscriber(ipc.zenoh_presence_key("*"))
                .callback(move |s| {
                    if s.kind() == SampleKind::Put {
                        let mut at = seen.lock().unwrap_or_else(|e| e.into_inner());
                        at.get_or_insert_with(Instant::now);
                    }
                })
                .wait()
                .map_err(|e| anyhow::anyhow!("liveliness subscriber: {e}"))?;
            t0 = Instant::now();
            Ok((gnss, tokens))
        })?;
        let mut ice_at = None;
        target.wait_until("readiness", Duration::from_secs(30), || {
            if ice_at.is_none() && gnss.subscriber_count() > 0 {
                ice_at = Some(Instant::now());
            }
            ice_at.is_some() && token_at.lock().map(|t| t.is_some()).unwrap_or(false)
        })?;
        let token = token_at
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .expect("seen");
        let ice = ice_at.expect("seen");
        ready.push(token.max(ice) - t0);
        drop(gnss);
        target.stop()?;
    }
    Ok(ready)
}

/// Phases 4 and 5: idle CPU (both targets at once, each with silent connected
/// sources; ghnetd as deployed, with discovery finding them) and start-to-ready.
pub fn rows(args: &Args, env: &Env, session: &Session, endpoint: &str) -> anyhow::Result<Vec<Row>> {
    let idle_names: Vec<String> = (0..args.idle_sources).map(|i| format!("idle{i}")).collect();
    let echo_t = Target::spawn(
        env,
        &Spec {
            kind: Kind::Echo,
            sources: idle_names.clone(),
            discovery: false,
            zenoh_connect: None,
        },
    )?;
    let daemon_t = Target::spawn(
        env,
        &Spec {
            kind: Kind::Ghnetd,
            sources: Vec::new(),
            discovery: true,
            zenoh_connect: None,
        },
    )?;
    let publishers = [&echo_t, &daemon_t]
        .iter()
        .map(|t| {
            idle_names
                .iter()
                .map(|n| VelocityPublisher::new(t.ipc(), n))
                .collect::<Result<Vec<_>, _>>()
        })
        .collect::<Result<Vec<_>, _>>()?;
    let idle = idle_cpu(
        &[&echo_t, &daemon_t],
        &publishers,
        Duration::from_secs(1),
        Duration::from_secs_f64(args.idle_seconds),
    )?;
    drop(publishers);
    echo_t.stop()?;
    daemon_t.stop()?;
    eprintln!(
        "idle CPU: raw {:.3}%  ghnetd {:.3}%",
        idle[0] * 100.0,
        idle[1] * 100.0
    );

    let ready = start_to_ready(env, session, endpoint, args.ready_runs)?;
    let ready_p =
        Percentiles::of(ready.iter().map(|d| d.as_nanos() as u64).collect()).context("no start")?;
    eprintln!("start-to-ready: {ready_p}");
    Ok(vec![
        row(
            &format!(
                "idle CPU, {} silent sources, {:.0} s (share of one core)",
                args.idle_sources, args.idle_seconds
            ),
            format!("{:.3}%", idle[0] * 100.0),
            format!("{:.3}%", idle[1] * 100.0),
            "< 0.5%".into(),
            Some(idle[1] < 0.005),
        ),
        row(
            &format!(
                "start-to-ready (spawn → liveliness token + iceoryx2 services), median / max of {}",
                ready.len()
            ),
            "–".into(),
            format!("{:.1} ms / {:.1} ms", ms(ready_p.p50), ms(ready_p.max)),
            "median < 250 ms".into(),
            Some(ready_p.p50 < Duration::from_millis(250)),
        ),
    ])
}
