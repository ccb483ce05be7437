//! In-process publisher → subscriber tests on real iceoryx2 shared memory, each in its
//! own iceoryx2 namespace (global prefix + root path) so they run in parallel.

use std::time::{Duration, Instant};

use ghnet_client::testing::{foreign_service, TestNamespace};
use ghnet_client::{
    HeadingEstimate, HeadingPublisher, HeadingSubscriber, OpenError, Setting, VelocityPublisher,
    VelocitySample, VelocitySubscriber, SERVICE_SETTINGS,
};

/// A velocity publisher and subscriber on source `gnss0` in a namespace of their own
/// (keep the namespace alive as long as the ports).
fn velocity_pair(tag: &str) -> (TestNamespace, VelocityPublisher, VelocitySubscriber) {
    let ns = TestNamespace::new(tag);
    let ipc = ns.ipc();
    let publisher = VelocityPublisher::new(&ipc, "gnss0").unwrap();
    let subscriber = VelocitySubscriber::new(&ipc, "gnss0").unwrap();
    (ns, publisher, subscriber)
}

fn sample(seq: u64) -> VelocitySample {
    VelocitySample::new(1_000 + seq, seq, seq as f32, -(seq as f32), 0.5)
}

#[test]
fn burst_arrives_complete_and_in_order() {
    let (_ns, publisher, subscriber) = velocity_pair("burst");
    assert_eq!(publisher.subscriber_count(), 1);
    assert_eq!(subscriber.publisher_count(), 1);

    // A burst up to the subscriber buffer is delivered without loss.
    let n = SERVICE_SETTINGS.subscriber_buffer_size as u64;
    for seq in 0..n {
        publisher.publish(sample(seq)).unwrap();
    }
    publisher.notify().unwrap();
    for seq in 0..n {
        let got = subscriber
            .recv_timeout(Duration::from_secs(2))
            .unwrap()
            .expect("sample");
        assert_eq!(got.to_le_bytes(), sample(seq).to_le_bytes());
    }
    assert!(subscriber.try_recv().unwrap().is_none());
}

#[test]
fn overflow_drops_oldest_never_blocks_publisher() {
    let (_ns, publisher, subscriber) = velocity_pair("overflow");
    let n = SERVICE_SETTINGS.subscriber_buffer_size as u64 + 10;
    for seq in 0..n {
        publisher.send(sample(seq)).unwrap();
    }
    let first = subscriber.try_recv().unwrap().unwrap();
    assert_eq!(first.seq, 10, "the 10 oldest were overwritten");
}

#[test]
fn recv_timeout_times_out_and_recv_wakes_on_another_thread() {
    let ns = TestNamespace::new("wake");
    let ipc = ns.ipc();
    let subscriber = HeadingSubscriber::new(&ipc, "gnss0").unwrap();

    let t0 = Instant::now();
    assert!(subscriber
        .recv_timeout(Duration::from_millis(50))
        .unwrap()
        .is_none());
    assert!(t0.elapsed() >= Duration::from_millis(50));

    // Ports are !Send: the publisher lives entirely on its thread.
    let ipc2 = ipc.clone();
    let handle = std::thread::spawn(move || {
        let publisher = HeadingPublisher::new(&ipc2, "gnss0").unwrap();
        std::thread::sleep(Duration::from_millis(100));
        let mut h = HeadingEstimate::from_le_bytes(&[0; HeadingEstimate::SIZE]);
        h.seq = 99;
        publisher.send(h).unwrap();
        // Keep the publisher alive until the sample has surely been read.
        std::thread::sleep(Duration::from_millis(200));
    });
    let got = subscriber.recv().unwrap();
    assert_eq!(got.seq, 99);
    handle.join().unwrap();
}

#[test]
fn namespaces_and_sources_are_separate() {
    let ns_a = TestNamespace::new("sep_a");
    let ns_b = TestNamespace::new("sep_b");
    let pub_a = VelocityPublisher::new(&ns_a.ipc(), "gnss0").unwrap();
    let sub_b = VelocitySubscriber::new(&ns_b.ipc(), "gnss0").unwrap();
    let sub_a_other = VelocitySubscriber::new(&ns_a.ipc(), "gnss1").unwrap();
    pub_a.send(sample(1)).unwrap();
    assert!(sub_b.try_recv().unwrap().is_none());
    assert!(sub_a_other.try_recv().unwrap().is_none());
    assert_eq!(pub_a.subscriber_count(), 0);
}

#[test]
fn service_created_with_smaller_limits_is_refused() {
    // The failure mode SERVICE_SETTINGS exists for: a foreign client created the
    // service with iceoryx2 defaults (buffer 2); asking for more on open fails.
    let ns = TestNamespace::new("limits");
    let ipc = ns.ipc();
    let node = ns.foreign_node();
    let name = ipc.velocity_service("gnss0").unwrap();
    let _foreign = foreign_service::<VelocitySample>(&node, &name);
    let err = VelocityPublisher::new(&ipc, "gnss0")
        .err()
        .expect("open must fail");
    let msg = err.to_string();
    let OpenError::Mismatch { service, settings } = err else {
        panic!("unexpected error {msg}");
    };
    // Smaller limits than ours: the error names every setting to raise at once
    // (iceoryx2 itself reports only the first). iceoryx2's defaults: 2 publishers
    // (we ask 4), a buffer of 2 (we ask 128).
    assert_eq!(service, "ghnet/gnss0/velocity");
    let named: Vec<_> = settings.iter().map(|m| m.setting).collect();
    assert_eq!(
        named,
        [Setting::MaxPublishers, Setting::SubscriberBufferSize],
        "{msg}"
    );
    assert!(
        msg.contains(
            "fewer publisher slots than the 4 asked, created with 2 (ServiceSettings::max_publishers)"
        ) && msg.ends_with("created with 2 (ServiceSettings::subscriber_buffer_size)"),
        "{msg}"
    );
    // A program with names of its own for the settings (ghnetd: its config keys).
    let err = VelocityPublisher::new(&ipc, "gnss0").err().unwrap();
    let own = err.naming(|s| format!("my.{}", s.field()));
    assert!(
        own.ends_with("created with 2 (my.subscriber_buffer_size)"),
        "{own}"
    );
}

#[test]
fn bad_names_are_rejected_before_touching_iceoryx2() {
    let ns = TestNamespace::new("names");
    assert!(matches!(
        VelocityPublisher::new(&ns.ipc(), "a/b"),
        Err(OpenError::Name(_))
    ));
}
