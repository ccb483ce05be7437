//! End to end through the public API: simulate S1, round-trip the CSV, compute the
//! baselines and the Bayes limit, evaluate, render, plot.

use ghnet_lab::bayes::BayesS1;
use ghnet_lab::eval::{
    evaluate, to_markdown, Estimate, EvalConfig, Report, Truth, ATAN2, BAYES, PRIOR_ONLY,
};
use ghnet_lab::plot::plot_mae_vs_speed;
use ghnet_lab::sim::{read_csv, simulate_s1, write_csv, S1Params, Split};

#[test]
fn s1_pipeline_orders_the_baselines() {
    let params = S1Params {
        speed_max: 1.0,
        ..S1Params::default()
    };
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("s1.csv");
    write_csv(&csv, &simulate_s1(&params, 3)).unwrap();
    let test: Vec<_> = read_csv(&csv)
        .unwrap()
        .into_iter()
        .filter(|s| s.split == Split::Test)
        .collect();
    assert_eq!(test.len(), (0.2 * 11.0 * 181.0 * 10.0_f64).round() as usize);

    let bayes = BayesS1::new(&params).estimates(&test);
    let report = evaluate(
        &Truth::from_samples(&test),
        &[
            Estimate::atan2(&test),
            Estimate::prior_only(&test, 0.0, 90.0),
            bayes.median,
        ],
        &EvalConfig::default(),
    )
    .unwrap();
    let mae = |name| report.overall.stats_of(name).unwrap().mae_deg;
    // Knowing the prior helps, the Bayes estimate is the limit.
    assert!(mae(PRIOR_ONLY) < mae(ATAN2));
    assert!(mae(BAYES) < mae(PRIOR_ONLY));
    let gap = report.overall.comparison(PRIOR_ONLY, BAYES).unwrap();
    assert!(gap.mae_pct.unwrap() > 0.0);

    // serde_json's default float parsing may differ in the last ulp: compare numbers
    // with a tolerance, structure exactly.
    let back: Report = serde_json::from_str(&serde_json::to_string(&report).unwrap()).unwrap();
    assert_eq!(back.estimators, report.estimators);
    assert_eq!(back.bins.len(), report.bins.len());
    for (a, b) in back.bins.iter().zip(&report.bins) {
        assert_eq!((&a.label, a.count), (&b.label, b.count));
        for (x, y) in a.stats.iter().zip(&b.stats) {
            assert!((x.mae_deg - y.mae_deg).abs() <= 1e-12 * y.mae_deg.max(1.0));
        }
    }
    let md = to_markdown(&report);
    assert!(md.contains("| <0.1 |") && md.contains("| 1 |"));
    plot_mae_vs_speed(&report, dir.path().join("mae.svg")).unwrap();
}
