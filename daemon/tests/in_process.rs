//! `ghnetd::run` as a library: on its own thread, stopped with a `ShutdownFlag`,
//! returning `Stats`. Real iceoryx2 in a private namespace.

mod common;

use common::{next_answer, InProcess};
use ghnet_client::{HeadingSubscriber, VelocityPublisher, VelocitySample};

#[test]
fn run_serves_until_the_flag_and_returns_stats() {
    let mut daemon = InProcess::start("inproc", |c| {
        c.sources.static_sources = vec!["a".into()];
    });
    let ipc = daemon.ipc();
    let headings = HeadingSubscriber::new(&ipc, "a").unwrap();
    let gnss = VelocityPublisher::new(&ipc, "a").unwrap();
    daemon.wait_serving(&gnss);
    for seq in 0..10 {
        gnss.send(VelocitySample::new(seq * 10, seq, 3.0, 4.0, 0.0))
            .unwrap();
    }
    gnss.send(VelocitySample::new(95, 12, f32::INFINITY, 0.0, 0.0)) // gap of 2, invalid
        .unwrap();
    for _ in 0..11 {
        next_answer(&headings);
    }

    let stats = daemon.stop();
    let a = stats.sources["a"];
    assert_eq!((a.received, a.answered, a.invalid, a.gaps), (11, 11, 1, 2));
    assert_eq!(stats.total(), a);
    assert_eq!((stats.sources_added, stats.sources_removed), (1, 0));
    assert!(stats.unserved.is_empty(), "{:?}", stats.unserved);
}

#[test]
fn run_rejects_a_bad_config_before_touching_iceoryx2() {
    let mut config = ghnetd::Config::default();
    config.sources.static_sources = vec!["no/slash".into()];
    let err = ghnetd::run(config, ghnetd::ShutdownFlag::new()).unwrap_err();
    assert!(format!("{err:#}").starts_with("sources.static"), "{err:#}");
}
