//! `perf echo`: the raw transport baseline. It has ghnetd's shape without its
//! work: one iceoryx2 node, one `WaitSet` woken by each source's velocity listener,
//! drain every buffered sample, answer each with a `HeadingEstimate` that only echoes
//! `seq` and `timestamp_ns`, publish it on iceoryx2 and on Zenoh (same QoS as
//! ghnetd: drop, high priority, every heading of a drain batched but the last, which
//! is express), notify once per batch. The difference between its figures and
//! ghnetd's is what the daemon itself costs.

use std::path::PathBuf;
use std::time::Duration;

use anyhow::Context;
use ghnet_client::iceoryx2::prelude::*;
use ghnet_client::iceoryx2::waitset::WaitSetRunResult;
use ghnet_client::zenoh::{self, Wait};
use ghnet_client::{
    encode_zenoh, HeadingEstimate, HeadingPublisher, HeadingStatus, IpcConfig, VelocitySubscriber,
};

/// Where the echo lives: ghnetd's flags, so the test kit starts it like a ghnetd.
#[derive(clap::Args)]
pub struct EchoArgs {
    #[arg(long = "iceoryx2-global-prefix")]
    global_prefix: String,
    #[arg(long = "iceoryx2-root-path")]
    root: PathBuf,
    #[arg(long, default_value = ghnet_client::DEFAULT_PREFIX)]
    service_prefix: String,
    #[arg(long = "source")]
    sources: Vec<String>,
    #[arg(long)]
    zenoh_listen: Option<String>,
    #[arg(long)]
    zenoh_connect: Option<String>,
}

struct Ports {
    velocity: VelocitySubscriber,
    heading: HeadingPublisher,
    /// Batching and express publisher of the heading key, as in ghnetd.
    zenoh: Option<[zenoh::pubsub::Publisher<'static>; 2]>,
}

pub fn run(args: EchoArgs) -> anyhow::Result<()> {
    let ipc =
        IpcConfig::isolated(&args.global_prefix, &args.root)?.with_prefix(&args.service_prefix)?;
    let session = match (&args.zenoh_listen, &args.zenoh_connect) {
        (None, None) => None,
        (l, c) => {
            let listen: Vec<String> = l.iter().cloned().collect();
            let connect: Vec<String> = c.iter().cloned().collect();
            let mut config = ghnet_client::peer_config(&listen, &connect)
                .map_err(|e| anyhow::anyhow!("zenoh config: {e}"))?;
            // ghnetd's transmit queue, so the two lose (or not) alike.
            for (key, value) in ghnet_client::ZENOH_TX_QUEUE {
                config
                    .insert_json5(key, value)
                    .map_err(|e| anyhow::anyhow!("zenoh config {key}: {e}"))?;
            }
            Some(
                zenoh::open(config)
                    .wait()
                    .map_err(|e| anyhow::anyhow!("zenoh session: {e}"))?,
            )
        }
    };
    // Default signal handling: SIGTERM ends the WaitSet loop below.
    let node = NodeBuilder::new()
        .config(&ipc.iceoryx2_config())
        .create::<ipc::Service>()
        .context("iceoryx2 node")?;
    let mut ports = Vec::with_capacity(args.sources.len());
    for s in &args.sources {
        let zenoh = match &session {
            Some(session) => {
                let declare = |express: bool| -> anyhow::Result<_> {
                    session
                        .declare_publisher(ipc.zenoh_heading_key(s)?)
                        .congestion_control(zenoh::qos::CongestionControl::Drop)
                        .priority(zenoh::qos::Priority::DataHigh)
                        .express(express)
                        .wait()
                        .map_err(|e| anyhow::anyhow!("zenoh publisher: {e}"))
                };
                Some([declare(false)?, declare(true)?])
            }
            None => None,
        };
        ports.push(Ports {
            velocity: VelocitySubscriber::with_node(&node, &ipc, s)?,
            heading: HeadingPublisher::with_node(&node, &ipc, s)?,
            zenoh,
        });
    }
    let waitset = WaitSetBuilder::new()
        .create::<ipc::Service>()
        .context("WaitSet")?;
    let guards = ghnet_client::attach_listeners(&waitset, ports.iter().map(|p| &p.velocity))
        .context("attach")?;
    for p in &ports {
        serve(p);
    }
    loop {
        let on_event = |id: WaitSetAttachmentId<ipc::Service>| {
            if let Some(i) = guards.iter().position(|g| id.has_event_from(g)) {
                serve(&ports[i]);
            }
            CallbackProgression::Continue
        };
        match waitset.wait_and_process_once_with_timeout(on_event, Duration::from_millis(100)) {
            Ok(WaitSetRunResult::TerminationRequest | WaitSetRunResult::Interrupt) => break,
            Ok(_) => {}
            Err(e) => anyhow::bail!("WaitSet: {e:?}"),
        }
    }
    Ok(())
}

/// The echo's whole per-wake-up work: what ghnetd's `serve` does minus the model.
fn serve(p: &Ports) {
    let _ = p.velocity.drain_notifications();
    let mut any = false;
    // The last heading of the drain is known only when `try_recv` comes back empty,
    // so each Zenoh put waits for the next sample to say whether it was the last.
    let mut held: Option<HeadingEstimate> = None;
    while let Ok(Some(s)) = p.velocity.try_recv() {
        let h = HeadingEstimate {
            timestamp_ns: s.timestamp_ns,
            seq: s.seq,
            processing_ns: 0,
            heading_deg: 0.0,
            heading_std_deg: 0.0,
            atan2_deg: 0.0,
            speed: 0.0,
            model_id: 0,
            status: HeadingStatus::Ok.as_u32(),
            model_name: [0; ghnet_client::MODEL_NAME_LEN],
        };
        let _ = p.heading.publish(h);
        if let (Some([batched, _]), Some(prev)) = (&p.zenoh, held.replace(h)) {
            let _ = batched.put(encode_zenoh(&prev)).wait();
        }
        any = true;
    }
    if let (Some([_, express]), Some(last)) = (&p.zenoh, held) {
        let _ = express.put(encode_zenoh(&last)).wait();
    }
    if any {
        let _ = p.heading.notify();
    }
}
