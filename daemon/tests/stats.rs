//! What `<prefix>/@ghnetd/stats` and `<prefix>/@ghnetd/model` tell, against what
//! ghnetd did: a dropped source stays listed with its counters, a source that comes
//! back continues its counters but not its sequence, a source that cannot be served
//! is listed with the reason, and the model answer names its daemon. In-process
//! ghnetd, real iceoryx2, real Zenoh on the test's own unix socket.

mod common;

use common::{next_answer, query_json, stats_when, InProcess};
use ghnet_client::{
    HeadingStatus, HeadingSubscriber, ServiceSettings, VelocityPublisher, VelocitySample,
};
use serde_json::Value;

fn sample(seq: u64) -> VelocitySample {
    VelocitySample::new(1_000 + seq, seq, 3.0, 4.0, 0.0)
}

fn u(v: &Value) -> u64 {
    v.as_u64().unwrap_or_else(|| panic!("not a count: {v}"))
}

/// A discovered source is dropped when its publisher leaves (after its one Stale
/// message) and stays in the stats, `served: false`, with what it counted, `stale`
/// included. When a publisher comes back under the same name, the counters go on
/// from there, while the sequence tracking starts afresh: a new publisher may
/// restart at 0 without counting duplicates.
#[test]
fn a_dropped_source_keeps_its_counters_and_a_returning_one_continues_them() {
    let mut daemon = InProcess::start("statsback", |c| c.sources.stale_after_ms = 100);
    let ipc = daemon.ipc();
    let zenoh = daemon.zenoh();
    let headings = HeadingSubscriber::new(&ipc, "a").unwrap();

    let gnss = VelocityPublisher::new(&ipc, "a").unwrap();
    daemon.wait_serving(&gnss);
    for seq in 10..13 {
        gnss.send(sample(seq)).unwrap();
        next_answer(&headings);
    }
    drop(gnss);
    let stats = stats_when(&zenoh, &ipc, "a dropped", |s| {
        s["sources"]["a"]["served"] == false
    });
    let a = &stats["sources"]["a"];
    assert_eq!((u(&a["received"]), u(&a["answered"])), (3, 3), "{stats}");
    assert_eq!(
        u(&a["stale"]),
        1,
        "the Stale message before the drop: {stats}"
    );
    assert_eq!(u(&stats["sources_removed"]), 1, "{stats}");
    let stale = headings.recv_timeout(common::WATCHDOG).unwrap().unwrap();
    assert_eq!(stale.heading_status(), Some(HeadingStatus::Stale));

    // The same source again, its sequence restarted.
    let gnss = VelocityPublisher::new(&ipc, "a").unwrap();
    daemon.wait_serving(&gnss);
    for seq in 0..2 {
        gnss.send(sample(seq)).unwrap();
        next_answer(&headings);
    }
    let stats = stats_when(&zenoh, &ipc, "a served again", |s| {
        s["sources"]["a"]["served"] == true && s["sources"]["a"]["received"] == 5
    });
    let a = &stats["sources"]["a"];
    assert_eq!(u(&a["answered"]), 5, "{stats}");
    assert_eq!((u(&a["duplicates"]), u(&a["gaps"])), (0, 0), "{stats}");
    assert_eq!(u(&a["stale"]), 1, "{stats}");
    assert_eq!(u(&stats["sources_added"]), 2, "{stats}");

    let end = daemon.stop();
    let a = end.sources["a"];
    assert_eq!(
        (a.received, a.answered, a.stale, a.duplicates),
        (5, 5, 1, 0)
    );
    assert_eq!((end.sources_added, end.sources_removed), (2, 1));
}

/// A consumer created `x`'s heading service first, with smaller limits than
/// ghnetd's: ghnetd cannot publish there. The source is listed as unserved, with a
/// reason naming every smaller setting; the other sources are served.
#[test]
fn a_source_that_cannot_be_opened_is_listed_unserved_with_the_reason() {
    let mut daemon = InProcess::start("statsunserved", |_| {});
    let ipc = daemon.ipc();
    let zenoh = daemon.zenoh();
    let small = ipc
        .clone()
        .with_settings(ServiceSettings::with_limits(4, 2, 16, 64));
    let _consumer = HeadingSubscriber::new(&small, "x").unwrap();
    let _x = VelocityPublisher::new(&ipc, "x").unwrap();

    let headings = HeadingSubscriber::new(&ipc, "ok").unwrap();
    let gnss = VelocityPublisher::new(&ipc, "ok").unwrap();
    daemon.wait_serving(&gnss);
    gnss.send(sample(0)).unwrap();
    next_answer(&headings);

    let stats = stats_when(&zenoh, &ipc, "x unserved", |s| {
        s["unserved"]["x"].is_object()
    });
    let reason = stats["unserved"]["x"]["reason"].as_str().unwrap();
    assert!(reason.starts_with("service `ghnet/x/heading`"), "{reason}");
    for key in ["(ipc.max_subscribers)", "(ipc.subscriber_buffer)"] {
        assert!(reason.contains(key), "{key} in {reason}");
    }
    assert!(stats["sources"].get("x").is_none(), "{stats}");
    assert_eq!(stats["sources"]["ok"]["served"], true, "{stats}");

    let end = daemon.stop();
    assert_eq!(end.unserved.get("x").map(String::as_str), Some(reason));
}

/// Over `sources.max_sources`, a source waits, listed with that reason, and is
/// served once a slot frees.
#[test]
fn a_source_over_max_sources_is_listed_and_served_when_a_slot_frees() {
    let mut daemon = InProcess::start("statsmax", |c| {
        c.sources.max_sources = 1;
        c.sources.stale_after_ms = 0;
    });
    let ipc = daemon.ipc();
    let zenoh = daemon.zenoh();
    let first = VelocityPublisher::new(&ipc, "first").unwrap();
    daemon.wait_serving(&first);
    let second = VelocityPublisher::new(&ipc, "second").unwrap();
    let stats = stats_when(&zenoh, &ipc, "second unserved", |s| {
        s["unserved"]["second"].is_object()
    });
    assert_eq!(
        stats["unserved"]["second"]["reason"], "sources.max_sources (1) reached",
        "{stats}"
    );
    drop(first);
    daemon.wait_serving(&second);
    stats_when(&zenoh, &ipc, "second served", |s| {
        s["sources"]["second"]["served"] == true && s["unserved"].get("second").is_none()
    });
}

/// The model answer carries the metadata, the `model_id` the headings carry, and
/// the daemon that answers (the same zid as in the stats).
#[test]
fn the_model_answer_names_its_daemon_and_model_id() {
    let mut daemon = InProcess::start("statsmodel", |c| {
        c.sources.static_sources = vec!["m".into()];
    });
    let ipc = daemon.ipc();
    let zenoh = daemon.zenoh();
    let headings = HeadingSubscriber::new(&ipc, "m").unwrap();
    let gnss = VelocityPublisher::new(&ipc, "m").unwrap();
    daemon.wait_serving(&gnss);
    gnss.send(sample(0)).unwrap();
    let heading = next_answer(&headings);

    let model = query_json(&zenoh, &ipc.zenoh_model_key());
    assert_eq!(model["name"], "paper-s1", "{model}");
    assert_eq!(
        u(&model["model_id"]),
        u64::from(heading.model_id),
        "{model}"
    );
    let stats = query_json(&zenoh, &ipc.zenoh_stats_key());
    for who in [&model["daemon"], &stats["daemon"]] {
        assert_eq!(who["prefix"], "ghnet", "{who}");
        assert_eq!(u(&who["pid"]), u64::from(std::process::id()), "{who}");
    }
    assert_eq!(model["daemon"]["zid"], stats["daemon"]["zid"]);
    assert!(model["daemon"]["zid"]
        .as_str()
        .is_some_and(|z| !z.is_empty()));
    daemon.stop();
}
