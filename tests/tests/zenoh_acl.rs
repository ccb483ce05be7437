//! Zenoh access control with the shipped example `daemon/zenoh-acl.example.json5`:
//! a real ghnetd loads it with `--zenoh-config`, a real Zenoh session connects. The
//! allowed source's headings arrive over Zenoh, the denied source's do not (while its
//! iceoryx2 headings do), the stats queryable is hidden and the model one answers
//! (the test kit's readiness check asks it).

use std::path::Path;
use std::time::Duration;

use ghnet_client::zenoh::Wait;
use ghnet_client::{
    HeadingStatus, HeadingSubscriber, VelocityPublisher, VelocitySample, ZenohHeadingSubscriber,
};
use ghnet_testkit::{now_ns, recv_answer, zenoh_barrier, Ghnetd, TestNamespace, WATCHDOG};

#[test]
fn acl_example_denies_one_source_and_the_stats_queryable_over_zenoh_only() {
    let acl = Path::new(env!("CARGO_MANIFEST_DIR")).join("../daemon/zenoh-acl.example.json5");
    let acl = acl.to_str().unwrap();
    let ns = TestNamespace::new("acl");
    // The example's keys use the default service prefix `ghnet`. Zenoh keys stay
    // isolated anyway: the test's session talks to this daemon's endpoint only.
    let ipc = ns.ipc();
    assert_eq!(ipc.prefix(), "ghnet");
    let daemon = (Ghnetd::builder(&ns).source("public").source("secret"))
        .discovery(false)
        .arg("--zenoh-config")
        .arg(acl)
        .start();
    let session = daemon.connect();
    let zen_public = ZenohHeadingSubscriber::new(&session, &ipc, "public").unwrap();
    let zen_secret = ZenohHeadingSubscriber::new(&session, &ipc, "secret").unwrap();
    assert_eq!(
        zen_secret.key(),
        "ghnet/secret/heading",
        "the key the example denies"
    );
    // The model query is allowed: it answers, and afterwards the daemon knows every
    // subscriber declared before it.
    zenoh_barrier(&session, &ipc);

    let mut gnss = Vec::new();
    let mut ice = Vec::new();
    for source in ["public", "secret"] {
        let p = VelocityPublisher::new(&ipc, source).unwrap();
        daemon.wait_serving(&p);
        gnss.push(p);
        ice.push(HeadingSubscriber::new(&ipc, source).unwrap());
    }
    let n = 50u64;
    let t0 = now_ns();
    for seq in 0..n {
        for (p, sub) in gnss.iter().zip(&ice) {
            p.send(VelocitySample::new(t0 + seq, seq, 3.0, 4.0, 0.0))
                .unwrap();
            // Both sources are answered on iceoryx2: the ACL is about Zenoh only.
            let h = recv_answer(sub, WATCHDOG).expect("iceoryx2 answer");
            assert_eq!(h.seq, seq);
        }
    }
    // Every public heading arrives over Zenoh; the secret ones were sent interleaved
    // with them, so by now they would have arrived too.
    let mut got = 0;
    while got < n {
        daemon.assert_running();
        let h = zen_public
            .recv_timeout(WATCHDOG)
            .expect("decodes")
            .unwrap_or_else(|| panic!("watchdog: {got} of {n} public headings over Zenoh"));
        if h.heading_status() != Some(HeadingStatus::Stale) {
            assert_eq!(h.seq, got);
            got += 1;
        }
    }
    assert!(
        zen_secret
            .recv_timeout(Duration::from_millis(500))
            .unwrap()
            .is_none(),
        "a heading of the denied source left ghnetd over Zenoh"
    );

    // The stats queryable is hidden: no reply (the query ends at its timeout at most).
    let replies = session
        .get(ipc.zenoh_stats_key())
        .timeout(Duration::from_secs(2))
        .wait()
        .unwrap();
    let mut ok_replies = 0;
    while let Ok(r) = replies.recv() {
        ok_replies += usize::from(r.result().is_ok());
    }
    assert_eq!(ok_replies, 0, "the stats queryable must not answer");
    // While the model queryable still does.
    let replies = session.get(ipc.zenoh_model_key()).wait().unwrap();
    let r = replies
        .recv_timeout(WATCHDOG)
        .unwrap()
        .expect("a model reply");
    assert!(r.result().is_ok());

    // ghnetd served the secret source like any other (every iceoryx2 answer above
    // arrived), it just did not show it over Zenoh.
    daemon.stop();
}
