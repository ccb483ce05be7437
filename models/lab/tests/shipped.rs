//! The shipped models load, and reproduce the headline numbers committed with them:
//! the metrics stored in each file's metadata and the overall rows of the committed
//! reports in `models/reports/` (regenerate both with the commands in models/README.md).

use std::sync::Arc;

use ghnet_inference::Model;
use ghnet_lab::eval::{Report, ATAN2};
use ghnet_lab::make::epoch::{self, DataSpec};

fn close(a: f64, b: f64, what: &str) {
    assert!(
        (a - b).abs() <= 1e-6 * (1.0 + b.abs()),
        "{what}: measured {a}, committed {b}"
    );
}

fn check(name: &str) {
    let model = Arc::new(Model::builtin(name).expect("embedded model loads"));
    assert_eq!(model.name(), name);
    let meta = model.meta();
    let data: DataSpec = serde_json::from_value(meta.training_data.clone()).unwrap();
    let max_speed = meta.training["eval_max_speed"].as_f64().unwrap();
    let (_, _, test) = epoch::split(&data.generate());
    assert_eq!(
        test.len() as u64,
        meta.metrics["test_samples"].as_u64().unwrap()
    );
    let report = epoch::evaluate(&model, &data, &test, max_speed).unwrap();
    let overall = report.overall.stats_of(name).unwrap();
    close(
        overall.mae_deg,
        meta.metrics["mae_deg"].as_f64().unwrap(),
        "metadata mae_deg",
    );
    close(
        overall.rmse_deg,
        meta.metrics["rmse_deg"].as_f64().unwrap(),
        "metadata rmse_deg",
    );
    close(
        overall.within_1sigma.unwrap(),
        meta.metrics["within_1sigma"].as_f64().unwrap(),
        "metadata within_1sigma",
    );
    let committed: Report = serde_json::from_str(
        &std::fs::read_to_string(format!(
            "{}/../reports/{name}.json",
            env!("CARGO_MANIFEST_DIR")
        ))
        .expect("committed report exists"),
    )
    .unwrap();
    assert_eq!(committed.bins.len(), report.bins.len());
    for (c, m) in committed
        .bins
        .iter()
        .zip(&report.bins)
        .chain([(&committed.overall, &report.overall)])
    {
        assert_eq!(c.count, m.count, "bin {}", c.label);
        for est in [name, ATAN2] {
            let (cs, ms) = (c.stats_of(est).unwrap(), m.stats_of(est).unwrap());
            close(
                ms.mae_deg,
                cs.mae_deg,
                &format!("{est} MAE in bin {}", c.label),
            );
            close(
                ms.rmse_deg,
                cs.rmse_deg,
                &format!("{est} RMSE in bin {}", c.label),
            );
        }
    }
}

#[test]
fn paper_s1_reproduces_its_committed_numbers() {
    check("paper-s1");
}

#[test]
fn ghnet_full_reproduces_its_committed_numbers() {
    check("ghnet-epoch");
}

/// The acceptance bars of the shipped models, checked on the committed reports so a
/// retrained model that misses them cannot be shipped silently.
#[test]
fn committed_reports_meet_the_accuracy_bars() {
    let read = |name: &str| -> Report {
        serde_json::from_str(
            &std::fs::read_to_string(format!(
                "{}/../reports/{name}.json",
                env!("CARGO_MANIFEST_DIR")
            ))
            .unwrap(),
        )
        .unwrap()
    };
    let s1 = read("paper-s1");
    for row in &s1.bins {
        let m = row.stats_of("paper-s1").unwrap().mae_deg;
        let b = row.stats_of("bayes").unwrap().mae_deg;
        let a = row.stats_of(ATAN2).unwrap().mae_deg;
        assert!(
            m <= (1.1 * b).max(b + 0.2),
            "paper-s1 bin {}: {m} vs bayes {b}",
            row.label
        );
        if row.speed_hi.is_some_and(|hi| hi <= 0.5 + 1e-9) {
            assert!(
                m < a,
                "paper-s1 bin {}: {m} not better than atan2 {a}",
                row.label
            );
        }
    }
    let full = read("ghnet-epoch");
    for row in full.bins.iter().filter(|r| r.count > 200) {
        let m = row.stats_of("ghnet-epoch").unwrap().mae_deg;
        let a = row.stats_of(ATAN2).unwrap().mae_deg;
        assert!(
            m <= 1.02 * a,
            "ghnet-epoch bin {}: {m} vs atan2 {a}",
            row.label
        );
    }
    // σ calibration. ghnet-epoch's 2σ share is short of 95% for reasons one sample cannot
    // fix (models/README.md, "Against the bars"); this bar keeps it from getting worse.
    for (r, name, two_sigma) in [
        (&s1, "paper-s1", 0.92..=0.98),
        (&full, "ghnet-epoch", 0.88..=0.98),
    ] {
        let o = r.overall.stats_of(name).unwrap();
        let (s1c, s2c) = (o.within_1sigma.unwrap(), o.within_2sigma.unwrap());
        assert!((0.63..=0.73).contains(&s1c), "{name}: {s1c} within 1σ");
        assert!(two_sigma.contains(&s2c), "{name}: {s2c} within 2σ");
    }
}

/// The shipped temporal model and `kf` load, and the temporal model reproduces the
/// held-out numbers stored in its metadata (streamed over its recipe's test tracks,
/// against the shipped `kf`).
#[test]
fn temporal_model_reproduces_its_committed_numbers() {
    use ghnet_lab::make::temporal::{held_out_metrics, held_out_tables};
    let model = Arc::new(Model::builtin("ghnet-temporal").expect("ghnet-temporal loads"));
    assert!(model.is_stateful());
    // What `ghnet restamp` would store now, against what is stored.
    let tables = held_out_tables(&model).expect("the model names its recipe");
    let all = tables.last().unwrap();
    let (now, stored) = (held_out_metrics(&model, &tables), &model.meta().metrics);
    for (path, what) in [
        ("/mae_deg", "temporal mae_deg"),
        ("/kf_mae_deg", "kf mae_deg"),
        ("/atan2_mae_deg", "atan2 mae_deg"),
        (
            "/after_first_motion/mae_deg",
            "temporal mae_deg after first motion",
        ),
        (
            "/after_first_motion/kf_mae_deg",
            "kf mae_deg after first motion",
        ),
        ("/test_epochs", "test epochs"),
    ] {
        let of = |v: &serde_json::Value| v.pointer(path).and_then(|x| x.as_f64()).unwrap();
        close(of(&now), of(stored), what);
    }
    // σ is honest in turns as on straights: every turn band of the cars at speed with
    // enough epochs keeps the 1σ share near a normal σ's and most of the tail within 2σ
    // (without the turn term: 51% and 40% within 1σ at 1.5–4 and ≥ 10 °/s, 71% within
    // 2σ at ≥ 10 °/s).
    let k = all.names.len() - 1;
    for r in all.turn_rows.iter().filter(|r| r.count >= 1000) {
        let (s1, s2) = (r.cells[k].within_1sigma, r.cells[k].within_2sigma);
        let (s1, s2) = (s1.unwrap(), s2.unwrap());
        assert!(
            (0.6..=0.8).contains(&s1),
            "turn {} °/s: {s1} within 1σ",
            r.label
        );
        assert!(s2 >= 0.85, "turn {} °/s: {s2} within 2σ", r.label);
    }
    // Counted once per stop (a held stop repeats one error), the held σ is honest too:
    // the epoch shares could hide stops the σ misses behind long ones it covers. A
    // platform's stand holds nothing (its heading random-walks while it stands, and a
    // course that moves it is no hold), so its table has next to no `Held` answers, and
    // its stops are bounded by that instead. The cars' 2σ bar is 89%: the 90% aimed at
    // was met only while course-following epochs of vehicles not yet known to be cars
    // were answered `Held` and counted as stops; the share on true holds is in
    // models/reports/ghnet-temporal.md.
    for t in &tables {
        let mem = t.memory.expect("the model has σ and status");
        let epochs = t
            .rows
            .iter()
            .find(|r| r.label == "**all**")
            .map_or(0, |r| r.count);
        if t.title.contains("platforms") {
            assert!(
                mem.held_epochs * 100 < epochs,
                "{}: {} of {epochs} epochs held",
                t.title,
                mem.held_epochs
            );
        } else {
            assert!(mem.stops >= 300, "{}: {} stops", t.title, mem.stops);
            let (s1, s2) = (mem.stops_within_1sigma, mem.stops_within_2sigma);
            assert!(
                (0.6..=0.76).contains(&s1),
                "{}: {s1} of stops within 1σ",
                t.title
            );
            assert!(s2 >= 0.89, "{}: {s2} of stops within 2σ", t.title);
        }
        // The median drive is calibrated too (its spread is reported, not bounded: one
        // drive has one receiver, mounting and route).
        let (d1, d2) = (mem.drives_within_1sigma, mem.drives_within_2sigma);
        let (d1, d2) = (d1.expect("≥ 10 drives")[1], d2.expect("≥ 10 drives")[1]);
        assert!(
            (0.6..=0.76).contains(&d1),
            "{}: median drive {d1} within 1σ",
            t.title
        );
        assert!(d2 >= 0.9, "{}: median drive {d2} within 2σ", t.title);
    }
}

/// The first table of the committed report `models/reports/{name}.md`: its header and
/// its rows, cells trimmed.
fn first_table(name: &str) -> (Vec<String>, Vec<Vec<String>>) {
    let text = std::fs::read_to_string(format!(
        "{}/../reports/{name}.md",
        env!("CARGO_MANIFEST_DIR")
    ))
    .unwrap();
    let split = |l: &str| -> Vec<String> {
        let l = l.trim().trim_start_matches('|').trim_end_matches('|');
        l.split('|').map(|c| c.trim().to_owned()).collect()
    };
    let mut lines = text
        .lines()
        .skip_while(|l| !l.starts_with('|'))
        .take_while(|l| l.starts_with('|'));
    let header = split(lines.next().expect("a table"));
    let rows = lines.skip(1).map(split).collect();
    (header, rows)
}

/// The cell of `row` under the column `name` of `header`, as a number.
fn cell(header: &[String], row: &[String], name: &str) -> f64 {
    let k = header.iter().position(|h| h == name);
    let k = k.unwrap_or_else(|| panic!("no column `{name}` in {header:?}"));
    row[k]
        .parse()
        .unwrap_or_else(|_| panic!("`{name}` in {row:?}"))
}

/// The committed report of the shared real drive (`models/reports/car-nagoya.md`,
/// written by `models/regenerate.sh` from `../shared/data/real/`, which this
/// repository does not carry) meets the bars: MAE at most 0.9 × the tuned
/// `kf`'s and 0.8 × atan2's, 60–76% of errors within 1σ, at least 90% within 2σ.
#[test]
fn committed_real_drive_report_meets_the_bars() {
    let (header, rows) = first_table("car-nagoya");
    let row = rows
        .iter()
        .find(|r| r[0] == "**all**")
        .expect("the report's overall row");
    let col = |name: &str| cell(&header, row, name);
    let (n, atan2, kf) = (col("N"), col("MAE atan2"), col("MAE kf"));
    let (model, s1, s2) = (col("MAE ghnet-temporal"), col("≤1σ [%]"), col("≤2σ [%]"));
    assert!(n > 1000.0, "{n} epochs");
    assert!(model <= 0.9 * kf && model <= 0.8 * atan2, "{row:?}");
    assert!((60.0..=76.0).contains(&s1), "{s1}% within 1σ");
    assert!(s2 >= 90.0, "{s2}% within 2σ");
}

/// Own-log training (`models/reports/ownlog.md`, written by `models/ownlog.sh`: each
/// log's first half trains, its second half tests) is never worse than the shipped
/// model on the held-out half, on any of the simulated logs or the shared real drive.
#[test]
fn committed_ownlog_report_never_loses_to_the_shipped_model() {
    let (header, rows) = first_table("ownlog");
    assert!(rows.len() >= 14, "{} logs", rows.len());
    for row in &rows {
        let (shipped, trained) = (
            cell(&header, row, "MAE shipped"),
            cell(&header, row, "MAE trained"),
        );
        assert!(trained <= shipped, "{}: {trained}° vs {shipped}°", row[0]);
    }
}
