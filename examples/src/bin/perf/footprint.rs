//! Footprint: CPU while idle, and start-to-ready (spawn → Zenoh liveliness token seen
//! here and the iceoryx2 services opened).

use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use ghnet_client::zenoh::sample::SampleKind;
use ghnet_client::zenoh::{Session, Wait};
use ghnet_client::VelocityPublisher;

use crate::target::{cpu_time, Env, Kind, Spec, Target};

/// CPU share of one core each target used over `window` while `publishers` (one per
/// source, connected but silent) keep its sources alive.
pub fn idle_cpu(
    targets: &mut [&mut Target],
    publishers: &[Vec<VelocityPublisher>],
    settle: Duration,
    window: Duration,
) -> anyhow::Result<Vec<f64>> {
    for (t, pubs) in targets.iter_mut().zip(publishers) {
        t.wait_until("sources served", Duration::from_secs(30), || {
            pubs.iter().all(|p| p.subscriber_count() > 0)
        })?;
    }
    std::thread::sleep(settle);
    let before = targets
        .iter()
        .map(|t| cpu_time(t.pid()))
        .collect::<anyhow::Result<Vec<_>>>()?;
    let t0 = Instant::now();
    std::thread::sleep(window);
    let elapsed = t0.elapsed().as_secs_f64();
    let mut shares = Vec::new();
    for (t, b) in targets.iter_mut().zip(before) {
        t.check_running()?;
        shares.push((cpu_time(t.pid())? - b).as_secs_f64() / elapsed);
    }
    Ok(shares)
}

/// Spawn → ready, `runs` times: ready is when both the daemon's liveliness token
/// `<prefix>/@ghnetd/<zid>` has reached `session` (the daemon connects to it) and
/// its subscriber on a static source exists (iceoryx2 services opened). Polled every
/// 200 µs, so the figure is good to about that.
pub fn start_to_ready(
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
        let (mut target, (gnss, _tokens)) = Target::spawn_with(env, &spec, |ipc| {
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
