//! Stateful models through a real ghnetd: each source keeps its own history, a stopped
//! car is `Held`, the daemon answers exactly what the in-process `StreamPredictor`
//! answers, and gaps, time going backwards and restarted publishers reset the history
//! and are counted in `@ghnetd/stats`.

use std::sync::Arc;

use ghnet_client::{
    HeadingEstimate, HeadingStatus, HeadingSubscriber, VelocityPublisher, VelocitySample,
};
use ghnet_inference::stream::{Epoch, StreamPredictor};
use ghnet_inference::{Model, Prediction, Status};
use ghnet_lab::drive::{simulate, DriveParams};
use ghnet_testkit::{now_ns, recv_answer, Ghnetd, OneSource, TestNamespace, WATCHDOG};

const SECOND: u64 = 1_000_000_000;

/// Publishes `s` and returns its answer (one sample in flight).
fn ask(
    gnss: &VelocityPublisher,
    headings: &HeadingSubscriber,
    s: VelocitySample,
) -> HeadingEstimate {
    gnss.send(s).unwrap();
    let h = recv_answer(headings, WATCHDOG).expect("an answer");
    assert_eq!(h.seq, s.seq, "answers in order");
    h
}

/// A sample `t_s` seconds after `t0`, `speed` m/s towards `course_deg`, receiver
/// speed accuracy 0.1 m/s.
fn moving(t0: u64, seq: u64, t_s: f64, speed: f32, course_deg: f32) -> VelocitySample {
    let (s, c) = course_deg.to_radians().sin_cos();
    let mut v = VelocitySample::new(t0 + (t_s * 1e9) as u64, seq, speed * c, speed * s, 0.0);
    v.speed_accuracy = 0.1;
    v
}

/// Drives 6 m/s towards `course_deg` for 10 s (1 Hz, sequence numbers from
/// `first_seq`) and stops: the history knows a heading, so the stop is `Held`.
fn drive_and_stop(
    gnss: &VelocityPublisher,
    headings: &HeadingSubscriber,
    t0: u64,
    first_seq: u64,
    course_deg: f32,
) {
    for i in 0..10 {
        ask(
            gnss,
            headings,
            moving(t0, first_seq + i, i as f64, 6.0, course_deg),
        );
    }
    let held = ask(gnss, headings, moving(t0, first_seq + 10, 10.0, 0.0, 0.0));
    assert_eq!(held.heading_status(), Some(HeadingStatus::Held), "{held:?}");
}

/// A new publisher on `source` (another process, after [`drive_and_stop`]) is served,
/// and its first sample, still at 11 s, is `Stationary`: the old history was not
/// carried over, so there is nothing to hold. Returns the publisher to keep it alive.
fn back_with_a_fresh_history(
    daemon: &Ghnetd,
    source: &str,
    headings: &HeadingSubscriber,
    t0: u64,
    seq: u64,
) -> VelocityPublisher {
    let gnss = VelocityPublisher::new(daemon.ipc(), source).unwrap();
    daemon.wait_serving(&gnss);
    let fresh = ask(&gnss, headings, moving(t0, seq, 11.0, 0.0, 0.0));
    assert_eq!(
        fresh.heading_status(),
        Some(HeadingStatus::Stationary),
        "{fresh:?}"
    );
    gnss
}

/// What ghnetd feeds the model for a sample: time in seconds from `timestamp_ns`.
fn epoch(s: &VelocitySample) -> Epoch {
    Epoch {
        t_s: s.timestamp_ns as f64 * 1e-9,
        v_north: s.v_north,
        v_east: s.v_east,
        speed_acc: s.speed_accuracy,
    }
}

/// The daemon's answer equals the in-process prediction to the bit.
fn assert_same(h: &HeadingEstimate, want: &Prediction, ctx: &str) {
    let status = match want.status {
        Status::Ok => HeadingStatus::Ok,
        Status::LowSpeed => HeadingStatus::LowSpeed,
        Status::Stationary => HeadingStatus::Stationary,
        Status::Invalid => HeadingStatus::InvalidInput,
        Status::Held => HeadingStatus::Held,
    };
    assert_eq!(h.heading_status(), Some(status), "{ctx}: {h:?} vs {want:?}");
    for (a, b) in [
        (h.heading_deg, want.heading_deg),
        (h.heading_std_deg, want.std_deg),
        (h.atan2_deg, want.atan2_deg),
        (h.speed, want.speed),
    ] {
        assert_eq!(a.to_bits(), b.to_bits(), "{ctx}: {h:?} vs {want:?}");
    }
}

/// The model these tests run: the default, `ghnet-temporal`, whose car holds its
/// heading at a stop once it has driven like a car (above 2.5 m/s for 5 s); the history
/// rules are the daemon's and the same for every stateful model, and
/// `daemon_equals_in_process_stream_predictor_bit_for_bit` also runs `kf` (whose tuned
/// random walk, 120 °/√s, gives up a held heading within a second).
fn stateful_model() -> (Arc<Model>, Option<&'static str>) {
    (
        Arc::new(Model::builtin("ghnet-temporal").unwrap()),
        Some("ghnet-temporal"),
    )
}

fn start(source: &str, model: Option<&str>, args: &[&str]) -> OneSource {
    OneSource::start(source, |b| {
        let b = args.iter().fold(b, |b, a| b.arg(*a));
        match model {
            Some(m) => b.model(m),
            None => b,
        }
    })
}

/// (1) A car drives east for 10 s, stops and stays for 12 minutes (1 Hz): while
/// stopped the answers are `Held` at the last moving heading, with a σ that never
/// shrinks and grows with the time stopped (slowly: a parked car's heading does not
/// drift, so the calibration keeps the held σ nearly flat for minutes).
#[test]
fn a_stopped_car_is_held_with_a_growing_sigma() {
    let (_, flag) = stateful_model();
    let one = start("held", flag, &[]);
    let t0 = now_ns();
    let mut seq = 0;
    // Sample at `t` s, the next sequence number.
    let mut at = |t: u64, speed: f32, course_deg: f32| {
        let s = moving(t0, seq, t as f64, speed, course_deg);
        seq += 1;
        ask(&one.gnss, &one.headings, s)
    };
    for t in 0..10 {
        let h = at(t, 8.0, 90.0);
        assert_ne!(h.heading_status(), Some(HeadingStatus::Held), "{h:?}");
    }
    let mut stds = Vec::new();
    for t in 10..730 {
        let h = at(t, 0.01, 200.0);
        assert_eq!(
            h.heading_status(),
            Some(HeadingStatus::Held),
            "t {t}: {h:?}"
        );
        assert!((h.heading_deg - 90.0).abs() < 3.0, "t {t}: {h:?}");
        if let Some(&last) = stds.last() {
            assert!(h.heading_std_deg >= last, "t {t}: σ shrank: {h:?}");
        }
        stds.push(h.heading_std_deg);
    }
    let (first, last) = (stds[0], stds[stds.len() - 1]);
    assert!(
        last > first,
        "σ after 12 min {last} against {first} at the stop"
    );
}

/// `n` simulated drives of `secs` seconds each, a share of them slow platforms.
fn drives(n: usize, platform_share: f64, secs: f64, seed: u64) -> Vec<ghnet_lab::drive::Track> {
    let params = DriveParams {
        tracks: n,
        platform_share,
        track_min_s: secs,
        track_max_s: secs,
        ..DriveParams::default()
    };
    simulate(&params, seed)
}

/// (2) The daemon's headings for a simulated drive (stops, reversing, fix gaps, a
/// receiver with or without speed accuracy) equal the in-process `StreamPredictor`'s
/// for the same stream, bit for bit: for the shipped default and for `kf`.
#[test]
fn daemon_equals_in_process_stream_predictor_bit_for_bit() {
    let tracks = drives(2, 0.0, 60.0, 14);
    let (default, flag) = stateful_model();
    let kf = Arc::new(Model::builtin("kf").unwrap());
    for (model, flag) in [(default, flag), (kf, Some("kf"))] {
        let one = start("bits", flag, &[]);
        let mut sp = StreamPredictor::new(model.clone());
        let mut history = sp.history();
        let (t0, mut seq) = (now_ns(), 0);
        for (k, track) in tracks.iter().enumerate() {
            // The second track starts after a pause longer than any gap limit.
            let start = t0 + k as u64 * 1000 * SECOND;
            for d in track.samples.iter().take(200) {
                let mut s = VelocitySample::new(
                    start + (d.t_s * 1e9) as u64,
                    seq,
                    d.v_north,
                    d.v_east,
                    0.0,
                );
                s.speed_accuracy = d.speed_acc;
                let h = ask(&one.gnss, &one.headings, s);
                let want = sp.predict(&mut history, &epoch(&s));
                assert_same(&h, &want, &format!("{} seq {seq}", model.name()));
                seq += 1;
            }
        }
        eprintln!("{}: {seq} answers equal to the bit", model.name());
    }
}

/// (3) A time step longer than the gap limit and a timestamp that goes backwards
/// each clear the history (a stopped car is then `Stationary`, not `Held`) and are
/// counted once in the stats.
#[test]
fn a_gap_and_time_going_backwards_reset_the_history_and_are_counted() {
    let (_, flag) = stateful_model();
    let one = start("resets", flag, &["--history-max-gap-s", "5"]);
    let t0 = now_ns();
    let mut seq = 0;
    let mut at = |t: f64, speed: f32| {
        seq += 1;
        ask(&one.gnss, &one.headings, moving(t0, seq, t, speed, 45.0))
    };
    for t in 0..10 {
        at(t as f64, 6.0);
    }
    let held = at(10.0, 0.0);
    assert_eq!(held.heading_status(), Some(HeadingStatus::Held), "{held:?}");
    // 6 s without a sample (the limit is 5 s): the history is gone.
    let after_gap = at(16.0, 0.0);
    assert_eq!(
        after_gap.heading_status(),
        Some(HeadingStatus::Stationary),
        "{after_gap:?}"
    );
    for t in 17..25 {
        at(t as f64, 6.0);
    }
    let back = at(20.0, 6.0);
    assert_eq!(
        back.heading_status(),
        Some(HeadingStatus::InvalidInput),
        "{back:?}"
    );
    let after_back = at(21.0, 0.0);
    assert_eq!(
        after_back.heading_status(),
        Some(HeadingStatus::Stationary),
        "{after_back:?}"
    );
    let c = one
        .daemon
        .wait_for_counters("resets", |c| c["received"] == seq);
    let got = [
        "resets_gap",
        "resets_backwards",
        "resets_restart",
        "backwards",
    ]
    .map(|k| c[k]);
    assert_eq!(got, [1, 1, 0, 1], "{c:?}");
}

/// (4) A publisher that restarts (a new process counting from seq 0 again) gets a
/// fresh history, counted as `resets_restart`; and a discovered source that is
/// dropped and comes back starts afresh too.
#[test]
fn a_restarted_publisher_gets_a_fresh_history() {
    let (_, flag) = stateful_model();
    let one = start("restart", flag, &[]);
    let t0 = now_ns();
    drive_and_stop(&one.gnss, &one.headings, t0, 100, 300.0);
    let OneSource {
        ns: _ns,
        daemon,
        gnss,
        headings,
    } = one;
    drop(gnss);
    let _gnss = back_with_a_fresh_history(&daemon, "restart", &headings, t0, 0);
    let c = daemon.wait_for_counters("restart", |c| c["received"] == 12);
    assert_eq!((c["resets_restart"], c["resets_gap"]), (1, 0), "{c:?}");
}

/// (4b) A discovered source whose publisher is gone is dropped with its history
/// (counted as `resets_restart`); when a publisher comes back it starts afresh.
#[test]
fn a_dropped_source_comes_back_with_a_fresh_history() {
    let (_, flag) = stateful_model();
    let ns = TestNamespace::new("comeback");
    let mut b = Ghnetd::builder(&ns).arg("--stale-after-ms").arg("100");
    if let Some(m) = flag {
        b = b.model(m);
    }
    let daemon = b.start();
    let t0 = now_ns();
    let (gnss, headings) = daemon.ends("comeback");
    drive_and_stop(&gnss, &headings, t0, 0, 10.0);
    drop(gnss);
    daemon.wait_until("the source is dropped", || {
        daemon.stats()["sources"]["comeback"]["served"] == false
    });
    let _gnss = back_with_a_fresh_history(&daemon, "comeback", &headings, t0, 11);
    let c = daemon.wait_for_counters("comeback", |c| c["received"] == 12);
    assert_eq!(c["resets_restart"], 1, "{c:?}");
}

/// (5) Two sources interleaved sample by sample (10 Hz) keep separate histories: each gets
/// exactly what an in-process `StreamPredictor` gives it alone, and when both stop
/// each is held at its own heading.
#[test]
fn interleaved_sources_keep_separate_histories() {
    let (model, flag) = stateful_model();
    let ns = TestNamespace::new("twosrc");
    let mut b = Ghnetd::builder(&ns)
        .source("east")
        .source("north")
        .discovery(false);
    if let Some(m) = flag {
        b = b.model(m);
    }
    let daemon = b.start();
    let ends = [daemon.ends("east"), daemon.ends("north")];
    let mut sp = StreamPredictor::new(model);
    let mut histories = [sp.history(), sp.history()];
    let t0 = now_ns();
    let mut last = [None, None];
    for i in 0..80u64 {
        for (k, (gnss, sub)) in ends.iter().enumerate() {
            let (speed, course) = if i < 70 {
                (5.0 + k as f32, 90.0 * (1 - k) as f32)
            } else {
                (0.0, 0.0)
            };
            // The two receivers are 33 ms apart.
            let s = moving(
                t0 + k as u64 * SECOND / 30,
                i,
                i as f64 / 10.0,
                speed,
                course,
            );
            let h = ask(gnss, sub, s);
            let want = sp.predict(&mut histories[k], &epoch(&s));
            assert_same(&h, &want, &format!("source {k} sample {i}"));
            last[k] = Some(h);
        }
    }
    let [east, north] = last.map(|h| h.unwrap());
    assert_eq!(east.heading_status(), Some(HeadingStatus::Held), "{east:?}");
    assert_eq!(
        north.heading_status(),
        Some(HeadingStatus::Held),
        "{north:?}"
    );
    assert!((east.heading_deg - 90.0).abs() < 3.0, "{east:?}");
    let d = north.heading_deg.min(360.0 - north.heading_deg);
    assert!(d < 3.0, "{north:?}");
}

/// (6) Several sources whose samples pile up (bursts of 1 to 8 published before one
/// wake-up each, all sources before any wake-up) go through ghnet-temporal in staged
/// passes, the convolutions of many sources in one call: every answer still equals,
/// to the bit, what an in-process `StreamPredictor` gives that source alone, in order.
#[test]
fn sources_answered_together_equal_each_alone_bit_for_bit() {
    let tracks = drives(6, 0.3, 30.0, 21);
    let names: Vec<String> = (0..tracks.len()).map(|k| format!("burst{k}")).collect();
    let ns = TestNamespace::new("passes");
    let b = (names.iter())
        .fold(Ghnetd::builder(&ns), |b, n| b.source(n))
        .discovery(false)
        .model("ghnet-temporal");
    let daemon = b.start();
    let ends: Vec<_> = names.iter().map(|n| daemon.ends(n)).collect();
    let model = Arc::new(Model::builtin("ghnet-temporal").unwrap());
    let mut sp = StreamPredictor::new(model);
    let mut histories: Vec<_> = tracks.iter().map(|_| sp.history()).collect();
    let t0 = now_ns();
    let mut next = vec![0usize; tracks.len()];
    let (mut round, mut answered) = (0usize, 0usize);
    while next.iter().zip(&tracks).any(|(&i, t)| i < t.samples.len()) {
        // Publish every source's burst first, then wake the daemon source by source.
        let mut sent: Vec<Vec<VelocitySample>> = vec![];
        for (k, ((gnss, _), t)) in ends.iter().zip(&tracks).enumerate() {
            let len = (1 + (round * 3 + k) % 8).min(t.samples.len() - next[k]);
            let burst: Vec<VelocitySample> = (next[k]..next[k] + len)
                .map(|i| {
                    let d = &t.samples[i];
                    let at = t0 + (d.t_s * 1e9) as u64;
                    let mut s = VelocitySample::new(at, i as u64, d.v_north, d.v_east, 0.0);
                    s.speed_accuracy = d.speed_acc;
                    s
                })
                .collect();
            burst.iter().for_each(|s| gnss.publish(*s).unwrap());
            next[k] += len;
            sent.push(burst);
        }
        ends.iter().for_each(|(gnss, _)| gnss.notify().unwrap());
        for (k, burst) in sent.iter().enumerate() {
            for s in burst {
                let h = recv_answer(&ends[k].1, WATCHDOG).expect("an answer");
                assert_eq!(h.seq, s.seq, "source {k}: answers in order");
                let want = sp.predict(&mut histories[k], &epoch(s));
                assert_same(&h, &want, &format!("source {k} seq {}", s.seq));
                answered += 1;
            }
        }
        round += 1;
    }
    eprintln!(
        "{answered} answers of {} sources equal to the bit",
        tracks.len()
    );
}

/// (8) `--platform` and `--source-platform` reach the source's history: a robot source
/// (`--source-platform bot=robot`, over a `car` default) drives fast, stops while it
/// turns in place and drives off; ghnetd answers every sample exactly as the in-process
/// predictor on `robot`, and not as one on `car` (which holds the stop).
#[test]
fn a_source_platform_override_reaches_its_history() {
    let one = start(
        "bot",
        Some("ghnet-temporal"),
        &["--platform", "car", "--source-platform", "bot=robot"],
    );
    let model = Arc::new(Model::builtin("ghnet-temporal").unwrap());
    let on = |p| {
        let sp = StreamPredictor::new(model.clone()).with_platform(Some(p));
        let h = sp.history();
        (sp, h)
    };
    let (mut robot, mut robot_h) = on(ghnet_inference::Platform::Robot);
    let (mut car, mut car_h) = on(ghnet_inference::Platform::Car);
    let t0 = now_ns();
    let mut differs = 0;
    for seq in 0..60u64 {
        let t = seq as f64;
        let s = match seq {
            0..20 => moving(t0, seq, t, 4.0, 10.0),
            20..40 => moving(t0, seq, t, 0.0, 0.0),
            _ => moving(t0, seq, t, 1.5, 100.0),
        };
        let h = ask(&one.gnss, &one.headings, s);
        let want = robot.predict(&mut robot_h, &epoch(&s));
        assert_same(&h, &want, &format!("seq {seq}"));
        let as_car = car.predict(&mut car_h, &epoch(&s));
        differs += usize::from(as_car.status != want.status);
    }
    assert!(differs > 10, "a car would have answered alike: {differs}");
}
