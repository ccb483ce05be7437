//! `ghnet-test-publisher`: a GNSS source in its own process, for the crash tests
//! (`kill -9` of a publisher). Sends `VelocitySample`s (v_north 3, v_east 4, seq from
//! FIRST_SEQ up, real timestamps) at RATE_HZ until killed, on the service prefix of
//! the daemon it feeds (default `ghnet`).
//!
//! ```text
//! ghnet-test-publisher IOX2_GLOBAL_PREFIX IOX2_ROOT_PATH SOURCE FIRST_SEQ RATE_HZ [SERVICE_PREFIX]
//! ```

use std::time::{Duration, Instant};

use ghnet_client::{IpcConfig, VelocityPublisher, VelocitySample};

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (ipc, source, first_seq, rate) = match args.as_slice() {
        [prefix, root, source, first_seq, rate, service_prefix @ ..]
            if service_prefix.len() <= 1 =>
        {
            let ipc = IpcConfig::isolated(prefix, root).expect("namespace");
            let ipc = match service_prefix {
                [p] => ipc.with_prefix(p).expect("service prefix"),
                _ => ipc,
            };
            (ipc, source, first_seq, rate)
        }
        _ => {
            eprintln!("usage: ghnet-test-publisher IOX2_GLOBAL_PREFIX IOX2_ROOT_PATH SOURCE FIRST_SEQ RATE_HZ [SERVICE_PREFIX]");
            std::process::exit(2);
        }
    };
    let gnss = VelocityPublisher::new(&ipc, source).expect("publisher");
    let first_seq: u64 = first_seq.parse().expect("FIRST_SEQ");
    let period = Duration::from_secs_f64(1.0 / rate.parse::<f64>().expect("RATE_HZ"));
    let t0 = Instant::now();
    for (k, seq) in (first_seq..).enumerate() {
        let mut s = VelocitySample::new(ghnet_testkit::now_ns(), seq, 3.0, 4.0, 0.0);
        s.speed_accuracy = 0.1;
        gnss.send(s).expect("send");
        let next = t0 + period.mul_f64((k + 1) as f64);
        std::thread::sleep(next.saturating_duration_since(Instant::now()));
    }
}
