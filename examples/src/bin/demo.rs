//! `demo`: a simulated car drives, stops and backs up; ghnetd, in-process on the
//! embedded default model, answers every velocity sample over shared memory; the table
//! shows, once per simulated second, the truth beside atan2, a Kalman filter on atan2
//! (the `kf` model, run here on the same samples) and ghnet with its σ and status. It
//! ends with each one's mean error over the drive.
//!
//! ```text
//! cargo run --release -p ghnet-examples --bin demo                 # 60 s of driving in 10 s
//! cargo run --release -p ghnet-examples --bin demo -- --isolated   # private namespace
//! ```

use std::sync::Arc;
use std::time::Duration;

use clap::Parser;
use ghnet_client::{flags, IpcConfig, VelocitySample};
use ghnet_client::{HeadingEstimate, HeadingStatus, HeadingSubscriber, VelocityPublisher};
use ghnet_examples::{log_to_stderr, now_ns, pacing_node, wait_for_subscriber};
use ghnet_examples::{CarDrive, Pacer, PrivateNamespace};
use ghnet_inference::stream::{Epoch, StreamPredictor};
use ghnet_inference::Model;
use ghnet_lab::drive::DriveSample;

const SOURCE: &str = "demo";

fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    log_to_stderr(); // the daemon's log lines; the table goes to stdout
    let ns = args.isolated.then(|| PrivateNamespace::new("demo")); // removed at exit
    let ipc = ns
        .as_ref()
        .map_or(Ok(IpcConfig::default()), PrivateNamespace::ipc)?;

    // 1. The daemon on its own thread, serving our one source from the start. No
    // Zenoh, so the demo never competes with a running ghnetd for its port.
    let mut config = ghnetd::Config::default();
    (config.model.name, config.zenoh.enabled) = (args.model.clone(), false);
    (config.sources.static_sources, config.sources.discovery) = (vec![SOURCE.into()], false);
    config.ipc.iceoryx2_global_prefix = ns.as_ref().map(|ns| ns.global_prefix.clone());
    config.ipc.iceoryx2_root_path = ns.as_ref().map(|ns| ns.root_path.clone());
    let shutdown = ghnetd::ShutdownFlag::new();
    let stop = shutdown.clone();
    let daemon = std::thread::spawn(move || ghnetd::run(config, stop));

    // 2. Our ends of the two services; publish once the daemon has subscribed.
    let node = pacing_node(&ipc, "ghnet-demo")?;
    let gnss = VelocityPublisher::with_node(&node, &ipc, SOURCE)?;
    let headings = HeadingSubscriber::new(&ipc, SOURCE)?;
    let patience = Duration::from_secs(30);
    if let Err(e) = wait_for_subscriber(&node, &[&gnss], patience, || daemon.is_finished()) {
        // The daemon's own error (e.g. the model cannot be loaded) says more.
        let failed = daemon
            .is_finished()
            .then(|| daemon.join().expect("no panic"));
        return Err(failed.and_then(Result::err).unwrap_or(e));
    }

    // 3. The car, one sample in flight: send, read ghnet's answer, run the filter.
    let car = CarDrive::new(args.seed, args.rate, args.duration);
    let mut kf = StreamPredictor::new(Arc::new(Model::builtin("kf")?));
    let mut history = kf.history();
    let (mut score, t0) = (Score::default(), now_ns());
    let pacer = Pacer::new(f64::from(car.rate_hz) * args.speedup)?;
    println!("{HEADER}");
    for (seq, s) in car.samples.iter().enumerate() {
        let sample = velocity(s, seq as u64, t0);
        gnss.send(sample)?;
        let ghnet = answer(&headings, seq as u64)?;
        let epoch = Epoch {
            t_s: s.t_s,
            v_north: s.v_north,
            v_east: s.v_east,
            speed_acc: s.speed_acc,
        };
        let kf_deg = kf.predict(&mut history, &epoch).heading_deg;
        score.add(s, &ghnet, kf_deg);
        if (seq as u32).is_multiple_of(car.rate_hz) {
            println!("{}", row(s, &ghnet, kf_deg));
        }
        if pacer.wait_for_slot(&node, seq as u64 + 1).is_err() {
            break; // Ctrl-C: shut down in order below
        }
    }

    // 4. The daemon, then the verdict.
    shutdown.request();
    let stats = daemon.join().expect("no panic")?.total();
    println!("{} ({})", score.summary(), args.model);
    let (sent, answered) = (score.n, score.answered);
    let (received, invalid) = (stats.received, stats.invalid);
    println!(
        "demo: sent {sent}, answered {answered} (ghnetd: received {received}, invalid {invalid})"
    );
    Ok(())
}

/// A simulated car that drives, stops and backs up; ghnetd, atan2 and a Kalman filter
/// side by side.
#[derive(Parser)]
struct Args {
    /// Seconds of driving to show.
    #[arg(long, default_value_t = 60.0)]
    duration: f64,
    /// The receiver's rate, Hz.
    #[arg(long, default_value_t = 10)]
    rate: u32,
    /// How much faster than real time to play the drive (timestamps stay the drive's).
    #[arg(long, default_value_t = 6.0)]
    speedup: f64,
    /// Simulation seed: the first car tried (the next ones until one backs up).
    #[arg(long, default_value_t = 3)]
    seed: u64,
    /// Private iceoryx2 namespace (removed at exit) instead of the system one.
    #[arg(long)]
    isolated: bool,
    /// Model: built-in name or .safetensors path.
    #[arg(long, default_value = ghnet_inference::DEFAULT_MODEL)]
    model: String,
}

/// Epoch `s` on the wire, stamped with the drive's own time after `t0`.
fn velocity(s: &DriveSample, seq: u64, t0: u64) -> VelocitySample {
    let t = t0 + (s.t_s * 1e9) as u64;
    VelocitySample {
        speed_accuracy: s.speed_acc,
        flags: flags::SIMULATED,
        ..VelocitySample::new(t, seq, s.v_north, s.v_east, 0.0)
    }
}

/// ghnetd's answer to sample `seq` (skipping `Stale` messages).
fn answer(headings: &HeadingSubscriber, seq: u64) -> anyhow::Result<HeadingEstimate> {
    loop {
        let h = headings
            .recv_timeout(Duration::from_secs(5))?
            .ok_or_else(|| anyhow::anyhow!("ghnetd did not answer sample {seq}"))?;
        if h.seq == seq && h.heading_status() != Some(HeadingStatus::Stale) {
            return Ok(h);
        }
    }
}

const HEADER: &str = "    t s  speed m/s  motion     truth°  atan2°     kf°  ghnet°    σ°  status";

fn row(s: &DriveSample, h: &HeadingEstimate, kf_deg: f32) -> String {
    let motion = match (s.true_speed < 0.05, s.reversing) {
        (true, _) => "stopped",
        (false, true) => "reversing",
        (false, false) => "forward",
    };
    let status = h
        .heading_status()
        .map_or_else(|| h.status.to_string(), |st| format!("{st:?}"));
    format!(
        "{:7.1}  {:9.2}  {motion:<9}  {:6.1}  {:6.1}  {:6.1}  {:6.1}  {:4.1}  {status}",
        s.t_s, h.speed, s.truth_heading_deg, h.atan2_deg, kf_deg, h.heading_deg, h.heading_std_deg,
    )
}

/// Mean absolute wrapped errors against the truth, from the first moving epoch on
/// (before it, nothing knows where a parked car points).
#[derive(Default)]
struct Score {
    n: u64,
    answered: u64,
    moved: bool,
    counted: u64,
    sum: [f64; 3],
}

impl Score {
    fn add(&mut self, s: &DriveSample, h: &HeadingEstimate, kf_deg: f32) {
        self.n += 1;
        self.answered += 1;
        self.moved |= s.true_speed > 0.5;
        if !self.moved {
            return;
        }
        self.counted += 1;
        for (acc, est) in self
            .sum
            .iter_mut()
            .zip([h.atan2_deg, kf_deg, h.heading_deg])
        {
            let e = (est - s.truth_heading_deg).rem_euclid(360.0);
            *acc += f64::from(e.min(360.0 - e));
        }
    }

    fn summary(&self) -> String {
        let n = self.counted.max(1) as f64;
        let [a, k, g] = self.sum.map(|x| x / n);
        format!(
            "mean |error| over {} epochs from the first motion: atan2 {a:.1}°, kf {k:.1}°, ghnet {g:.1}°",
            self.counted
        )
    }
}
