//! `ghnetd::run` as a library: on its own thread, stopped with a `ShutdownFlag`,
//! returning `Stats`. Real iceoryx2 in a private namespace.

use std::time::{Duration, Instant};

use ghnet_client::testing::TestNamespace;
use ghnet_client::{HeadingSubscriber, VelocityPublisher, VelocitySample};

#[test]
fn run_serves_until_the_flag_and_returns_stats() {
    let ns = TestNamespace::new("inproc");
    let mut config = ghnetd::Config::default();
    config.model.name = "paper-s1".into();
    config.ipc.iceoryx2_global_prefix = Some(ns.global_prefix().into());
    config.ipc.iceoryx2_root_path = Some(ns.root_path().into());
    config.sources.static_sources = vec!["a".into()];
    config.sources.discovery_interval_ms = 50;
    config.stats.interval_s = 0;
    // Zenoh on, on any free loopback port (tests run in parallel).
    config.zenoh.listen = vec!["tcp/127.0.0.1:0".into()];

    let shutdown = ghnetd::ShutdownFlag::new();
    // iceoryx2 ports are !Send: run() builds its own on the thread it runs on.
    let daemon = std::thread::spawn({
        let shutdown = shutdown.clone();
        move || ghnetd::run(config, shutdown)
    });

    let ipc = ns.ipc();
    let headings = HeadingSubscriber::new(&ipc, "a").unwrap();
    let gnss = VelocityPublisher::new(&ipc, "a").unwrap();
    let t0 = Instant::now();
    while gnss.subscriber_count() == 0 {
        assert!(
            t0.elapsed() < Duration::from_secs(20),
            "daemon never subscribed"
        );
        std::thread::sleep(Duration::from_millis(5));
    }
    for seq in 0..10 {
        gnss.send(VelocitySample::new(seq * 10, seq, 3.0, 4.0, 0.0))
            .unwrap();
    }
    gnss.send(VelocitySample::new(95, 12, f32::INFINITY, 0.0, 0.0)) // gap of 2, invalid
        .unwrap();
    for _ in 0..11 {
        headings
            .recv_timeout(Duration::from_secs(20))
            .unwrap()
            .expect("answer");
    }

    shutdown.request();
    let t0 = Instant::now();
    let stats = daemon.join().unwrap().unwrap();
    eprintln!("run() returned {:?} after the flag", t0.elapsed());
    let a = stats.sources["a"];
    assert_eq!((a.received, a.answered, a.invalid, a.gaps), (11, 11, 1, 2));
    assert_eq!(stats.total(), a);
    assert_eq!((stats.sources_added, stats.sources_removed), (1, 0));
}

#[test]
fn run_rejects_a_bad_config_before_touching_iceoryx2() {
    let mut config = ghnetd::Config::default();
    config.sources.static_sources = vec!["no/slash".into()];
    let err = ghnetd::run(config, ghnetd::ShutdownFlag::new()).unwrap_err();
    assert!(format!("{err:#}").starts_with("sources.static"), "{err:#}");
}
