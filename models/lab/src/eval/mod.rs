//! Evaluation tables: heading error per speed bin, as in the GHNet paper, and more.
//!
//! The input is decoupled from any network: each estimator is an [`Estimate`] (a name,
//! one heading per sample and optionally a reported 1σ), and the truth is a [`Truth`]
//! (true heading and true speed per sample). [`evaluate`] bins by true speed
//! (0.1 m/s bins labelled like the paper, "<0.1", "0.1", …, and a last bin "≥ max"),
//! and gives per bin and overall: sample count, MAE and RMSE of the wrapped error,
//! mean and standard deviation of the absolute error (the band of the paper's Fig. 7),
//! σ calibration (share of errors within 1σ and 2σ) for estimators that report a σ,
//! and comparisons to the references: improvement over atan2 and over the prior-only
//! baseline, and gap to the Bayes-optimal estimate (the physical limit).
//!
//! Errors are always wrapped ([`wrap_deg`]): 359° against 1° is 2°, not 358°.

mod render;
mod stats;

pub use render::{to_markdown, to_markdown_compact, write_csv};
pub use stats::*;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wrap_edges() {
        assert_eq!(wrap_deg(359.0 - 1.0), -2.0);
        assert_eq!(wrap_deg(1.0 - 359.0), 2.0);
        assert_eq!(wrap_deg(180.0), 180.0);
        assert_eq!(wrap_deg(-180.0), 180.0);
        assert_eq!(wrap_deg(540.0), 180.0);
        assert_eq!(wrap_deg(-190.0), 170.0);
        assert_eq!(wrap_deg(0.0), 0.0);
        assert_eq!(wrap_deg(720.5), 0.5);
        assert!(wrap_deg(f32::NAN).is_nan());
    }

    #[test]
    fn atan2_heading_conventions() {
        assert_eq!(atan2_heading_deg(1.0, 0.0), 0.0);
        assert!((atan2_heading_deg(0.0, 1.0) - 90.0).abs() < 1e-5);
        assert!((atan2_heading_deg(-1.0, 0.0) - 180.0).abs() < 1e-5);
        assert!((atan2_heading_deg(0.0, -1.0) - 270.0).abs() < 1e-5);
        assert!((atan2_heading_deg(1.0, 1.0) - 45.0).abs() < 1e-5);
        assert_eq!(atan2_heading_deg(0.0, 0.0), 0.0);
        // Just west of north must not round up to 360.
        let h = atan2_heading_deg(1.0, -1e-12);
        assert!((0.0..360.0).contains(&h), "{h}");
    }

    #[test]
    fn clip_edges() {
        assert_eq!(clip_to_range(45.0, 0.0, 90.0), 45.0);
        assert_eq!(clip_to_range(0.0, 0.0, 90.0), 0.0);
        assert_eq!(clip_to_range(90.0, 0.0, 90.0), 90.0);
        assert_eq!(clip_to_range(359.0, 0.0, 90.0), 0.0);
        assert_eq!(clip_to_range(100.0, 0.0, 90.0), 90.0);
        assert_eq!(clip_to_range(224.0, 0.0, 90.0), 90.0);
        assert_eq!(clip_to_range(226.0, 0.0, 90.0), 0.0);
        assert_eq!(clip_to_range(-10.0, 0.0, 90.0), 0.0);
        // An arc across north.
        assert_eq!(clip_to_range(5.0, 350.0, 10.0), 5.0);
        assert_eq!(clip_to_range(355.0, 350.0, 10.0), 355.0);
        assert_eq!(clip_to_range(20.0, 350.0, 10.0), 10.0);
        assert_eq!(clip_to_range(340.0, 350.0, 10.0), 350.0);
        // The full circle leaves headings alone.
        assert_eq!(clip_to_range(200.0, 0.0, 360.0), 200.0);
    }

    fn est(name: &str, h: &[f32], sd: Option<&[f32]>) -> Estimate {
        Estimate {
            name: name.into(),
            heading_deg: h.to_vec(),
            std_deg: sd.map(<[f32]>::to_vec),
        }
    }

    /// Four samples, two bins, errors chosen by hand (including wrap across north).
    #[test]
    fn hand_computed_example() {
        let truth = Truth {
            heading_deg: vec![1.0, 10.0, 350.0, 90.0],
            speed: vec![0.05, 0.05, 0.15, 0.7f32],
        };
        // Errors: atan2 −2 (359 vs 1), 4, −6, 0 ; model 1, −1, 2, 0 (σ 1.5 each).
        let a = est(ATAN2, &[359.0, 14.0, 344.0, 90.0], None);
        let m = est("model", &[2.0, 9.0, 352.0, 90.0], Some(&[1.5; 4]));
        let cfg = EvalConfig {
            summary_ranges: vec![(0.0, 0.2)],
            ..EvalConfig::default()
        };
        let r = evaluate(&truth, &[a, m], &cfg).unwrap();
        assert_eq!(r.bins.len(), 3);
        let labels: Vec<_> = r.bins.iter().map(|b| b.label.as_str()).collect();
        // 0.7 as f32 is 0.69999999: it still belongs to bin "0.7".
        assert_eq!(labels, ["<0.1", "0.1", "0.7"]);
        let b0 = &r.bins[0];
        assert_eq!(b0.count, 2);
        let (sa, sm) = (b0.stats_of(ATAN2).unwrap(), b0.stats_of("model").unwrap());
        assert!((sa.mae_deg - 3.0).abs() < 1e-9);
        assert!((sa.rmse_deg - 10f64.sqrt()).abs() < 1e-9);
        assert!((sa.abs_err_std_deg - 1.0).abs() < 1e-9);
        assert!((sm.mae_deg - 1.0).abs() < 1e-9);
        assert_eq!(sm.within_1sigma, Some(1.0));
        assert_eq!(sa.within_1sigma, None);
        let c = b0.comparison("model", ATAN2).unwrap();
        assert!((c.mae_pct.unwrap() - 100.0 * (1.0 - 1.0 / 3.0)).abs() < 1e-9);

        let o = &r.overall;
        assert_eq!(o.count, 4);
        let (oa, om) = (o.stats_of(ATAN2).unwrap(), o.stats_of("model").unwrap());
        assert!((oa.mae_deg - 3.0).abs() < 1e-9); // (2+4+6+0)/4
        assert!((oa.rmse_deg - 14f64.sqrt()).abs() < 1e-9); // (4+16+36)/4
        assert!((om.mae_deg - 1.0).abs() < 1e-9); // (1+1+2+0)/4
        assert!((om.rmse_deg - 1.5f64.sqrt()).abs() < 1e-9); // (1+1+4)/4
        assert_eq!(om.within_1sigma, Some(0.75));
        assert_eq!(om.within_2sigma, Some(1.0));
        // Exact zero error in bin 0.7 for both: 0 % rather than a division by zero.
        let c07 = r.bins[2].comparison("model", ATAN2).unwrap();
        assert_eq!(c07.mae_pct, Some(0.0));

        assert_eq!(r.summary.len(), 1);
        assert_eq!(r.summary[0].count, 3);
        assert!((r.overall.mean_speed - (0.05 + 0.05 + 0.15 + 0.7) / 4.0).abs() < 1e-6);
    }

    #[test]
    fn last_bin_collects_high_speeds_and_references_compare() {
        let truth = Truth {
            heading_deg: vec![0.0; 4],
            speed: vec![4.95, 5.0, 12.0, 0.0],
        };
        let a = est(ATAN2, &[4.0, 4.0, 4.0, 4.0], None);
        let p = est(PRIOR_ONLY, &[2.0, 2.0, 2.0, 2.0], None);
        let b = est(BAYES, &[1.0, 1.0, 1.0, 1.0], None);
        let m = est("m", &[1.5, 1.5, 1.5, 1.5], None);
        let r = evaluate(&truth, &[a, p, b, m], &EvalConfig::default()).unwrap();
        let labels: Vec<_> = r.bins.iter().map(|b| b.label.as_str()).collect();
        assert_eq!(labels, ["<0.1", "4.9", "≥5"]);
        assert_eq!(r.bins[2].count, 2);
        assert_eq!(r.bins[2].speed_hi, None);
        let o = &r.overall;
        assert!((o.comparison("m", ATAN2).unwrap().mae_pct.unwrap() - 62.5).abs() < 1e-9);
        assert!((o.comparison("m", PRIOR_ONLY).unwrap().mae_pct.unwrap() - 25.0).abs() < 1e-9);
        let gap = o.comparison("m", BAYES).unwrap();
        assert_eq!(gap.kind, ComparisonKind::Gap);
        assert!((gap.mae_pct.unwrap() - 50.0).abs() < 1e-9);
        // The Bayes limit against atan2 is reported; atan2 is never compared to others.
        assert!(o.comparison(BAYES, ATAN2).is_some());
        assert!(o.comparison(ATAN2, BAYES).is_none());
        assert!(o.comparison(BAYES, PRIOR_ONLY).is_none());
        assert!(o.comparison(PRIOR_ONLY, BAYES).is_some());
    }

    #[test]
    fn invalid_inputs_are_errors() {
        let truth = Truth {
            heading_deg: vec![0.0, 1.0],
            speed: vec![0.0, 1.0],
        };
        let cfg = EvalConfig::default();
        let short = est("x", &[0.0], None);
        assert!(matches!(
            evaluate(&truth, &[short], &cfg),
            Err(EvalError::LengthMismatch { .. })
        ));
        let nan = est("x", &[0.0, f32::NAN], None);
        assert!(matches!(
            evaluate(&truth, &[nan], &cfg),
            Err(EvalError::Invalid { index: 1, .. })
        ));
        let neg_sd = est("x", &[0.0, 0.0], Some(&[1.0, -1.0]));
        assert!(evaluate(&truth, &[neg_sd], &cfg).is_err());
        let dup = [est("x", &[0.0, 0.0], None), est("x", &[0.0, 0.0], None)];
        assert!(matches!(
            evaluate(&truth, &dup, &cfg),
            Err(EvalError::DuplicateName(_))
        ));
    }

    #[test]
    fn markdown_csv_and_json() {
        let truth = Truth {
            heading_deg: vec![10.0, 20.0, 30.0],
            speed: vec![0.0, 0.25, 6.0],
        };
        let a = est(ATAN2, &[12.0, 18.0, 31.0], None);
        let m = est("ghnet", &[11.0, 20.5, 30.0], Some(&[2.0, 1.0, 0.5]));
        let r = evaluate(&truth, &[a, m], &EvalConfig::default()).unwrap();
        let md = to_markdown(&r);
        for needle in [
            "| <0.1 | 1 |",
            "| 0.2 | 1 |",
            "| ≥5 | 1 |",
            "| **all** | 3 |",
            "ghnet vs atan2 [%]",
            "ghnet ≤1σ",
            "### RMSE [deg]",
        ] {
            assert!(md.contains(needle), "missing {needle:?} in\n{md}");
        }
        // Structure survives JSON exactly; floats to within serde_json's last-ulp parsing.
        let json = serde_json::to_string(&r).unwrap();
        let back: Report = serde_json::from_str(&json).unwrap();
        assert_eq!(back.estimators, r.estimators);
        let labels = |r: &Report| r.bins.iter().map(|b| b.label.clone()).collect::<Vec<_>>();
        assert_eq!(labels(&back), labels(&r));
        let (x, y) = (
            back.overall.stats_of("ghnet").unwrap(),
            r.overall.stats_of("ghnet").unwrap(),
        );
        assert!((x.rmse_deg - y.rmse_deg).abs() < 1e-12);
        assert_eq!(x.within_1sigma, y.within_1sigma);

        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("r.csv");
        write_csv(&path, &r).unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        let lines: Vec<_> = text.lines().collect();
        assert!(lines[0].starts_with("group,label,speed_lo,speed_hi,count,mean_speed,estimator"));
        // 3 bins + 1 summary (0–0.9 holds two samples; 0.9–2.1 is empty) + overall, × 2.
        assert_eq!(lines.len(), 1 + (3 + 1 + 1) * 2);
    }
}
