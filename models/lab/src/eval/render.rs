//! The evaluation report as Markdown (full and compact) and as CSV.

use std::path::Path;

use serde::Serialize;

use crate::table::{fmt_opt, Markdown};

use super::stats::{fmt_speed, Comparison, ComparisonKind, EstimatorStats, EvalError, Report, Row};

fn comparison_header(c: &Comparison) -> String {
    match c.kind {
        ComparisonKind::Improvement => format!("{} vs {} [%]", c.estimator, c.reference),
        ComparisonKind::Gap => format!("{} gap to {} [%]", c.estimator, c.reference),
    }
}

/// A row's label for Markdown: summary and overall rows in bold.
fn row_label(bold: bool, row: &Row) -> String {
    if bold {
        format!("**{}**", row.label)
    } else {
        row.label.clone()
    }
}

/// All rows in table order: bins, then summaries, then overall.
fn all_rows(r: &Report) -> impl Iterator<Item = (bool, &Row)> {
    r.bins
        .iter()
        .map(|row| (false, row))
        .chain(r.summary.iter().map(|row| (true, row)))
        .chain(std::iter::once((true, &r.overall)))
}

/// Picks the MAE or RMSE percentage of a comparison.
type PctOf = fn(&Comparison) -> Option<f64>;

fn metric_table(
    out: &mut String,
    r: &Report,
    title: &str,
    value: impl Fn(&EstimatorStats) -> f64,
    pct_of: Option<PctOf>,
) {
    use std::fmt::Write as _;
    let comps = &r.overall.comparisons;
    let _ = writeln!(out, "### {title}\n");
    let mut header = vec!["Speed [m/s]".to_owned(), "N".to_owned()];
    header.extend(r.estimators.iter().cloned());
    if pct_of.is_some() {
        header.extend(comps.iter().map(comparison_header));
    }
    let mut table = Markdown::new(&header, false);
    for (bold, row) in all_rows(r) {
        let label = row_label(bold, row);
        let mut cells = vec![label, row.count.to_string()];
        cells.extend(row.stats.iter().map(|s| format!("{:.2}", value(s))));
        if let Some(f) = pct_of {
            cells.extend(
                comps
                    .iter()
                    .map(|c| fmt_opt(row.comparison(&c.estimator, &c.reference).and_then(f), 1)),
            );
        }
        table.row(&cells);
    }
    out.push_str(&table.finish());
    out.push('\n');
}

/// A compact Markdown table for one estimator: per bin (only bins with at least
/// `min_count` samples, plus the summary and overall rows) its MAE beside every other
/// estimator's, its improvement over atan2, its gap to the Bayes limit when present, and
/// its σ calibration. This is what the models' README shows; the full report has the rest.
pub fn to_markdown_compact(r: &Report, estimator: &str, min_count: usize) -> String {
    let mut header = vec!["Speed [m/s]".to_owned(), "N".to_owned()];
    for n in &r.estimators {
        header.push(format!("MAE {n}"));
    }
    header.push(format!("{estimator} vs {} [%]", r.config.atan2));
    let has_bayes = r.estimators.contains(&r.config.bayes);
    if has_bayes {
        header.push(format!("gap to {} [%]", r.config.bayes));
    }
    header.push("≤1σ [%]".into());
    header.push("≤2σ [%]".into());
    let mut table = Markdown::new(&header, false);
    for (bold, row) in all_rows(r) {
        if !bold && row.count < min_count {
            continue;
        }
        let label = row_label(bold, row);
        let mut cells = vec![label, row.count.to_string()];
        for s in &row.stats {
            cells.push(format!("{:.2}", s.mae_deg));
        }
        let pct = |reference: &str| {
            row.comparison(estimator, reference)
                .and_then(|c| c.mae_pct)
                .map_or("–".to_owned(), |v| format!("{v:.1}"))
        };
        cells.push(pct(&r.config.atan2));
        if has_bayes {
            cells.push(pct(&r.config.bayes));
        }
        let s = row.stats_of(estimator);
        cells.push(fmt_opt(
            s.and_then(|s| s.within_1sigma).map(|x| 100.0 * x),
            1,
        ));
        cells.push(fmt_opt(
            s.and_then(|s| s.within_2sigma).map(|x| 100.0 * x),
            1,
        ));
        table.row(&cells);
    }
    table.finish()
}

/// Renders the report as Markdown: MAE, RMSE and absolute-error std tables per speed
/// bin with summary rows, and a σ calibration table when an estimator reports σ.
pub fn to_markdown(r: &Report) -> String {
    use std::fmt::Write as _;
    let mut out = String::new();
    let _ = writeln!(
        out,
        "## Heading error per speed bin\n\n\
         Wrapped error atan2(sin Δ, cos Δ) against the true heading, binned by true speed \
         (bins of {} m/s labelled by their lower edge; N = {} samples). \
         \"A vs B\" is the improvement 100·(1 − A/B); \"gap to\" is 100·(A/B − 1), the \
         distance above the Bayes-optimal limit.\n",
        fmt_speed(r.config.bin_width),
        r.overall.count
    );
    metric_table(
        &mut out,
        r,
        "MAE [deg]",
        |s| s.mae_deg,
        Some(|c: &Comparison| c.mae_pct),
    );
    metric_table(
        &mut out,
        r,
        "RMSE [deg]",
        |s| s.rmse_deg,
        Some(|c: &Comparison| c.rmse_pct),
    );
    metric_table(
        &mut out,
        r,
        "Std of absolute error [deg]",
        |s| s.abs_err_std_deg,
        None,
    );

    let calibrated: Vec<usize> = r
        .overall
        .stats
        .iter()
        .enumerate()
        .filter(|(_, s)| s.within_1sigma.is_some())
        .map(|(i, _)| i)
        .collect();
    if !calibrated.is_empty() {
        let _ = writeln!(
            out,
            "### σ calibration: share of |error| within 1σ / 2σ [%] \
             (Gaussian and calibrated: 68.3 / 95.4)\n"
        );
        let mut header = vec!["Speed [m/s]".to_owned(), "N".to_owned()];
        for &i in &calibrated {
            let n = &r.estimators[i];
            header.push(format!("{n} ≤1σ"));
            header.push(format!("{n} ≤2σ"));
        }
        let mut table = Markdown::new(&header, false);
        for (bold, row) in all_rows(r) {
            let label = row_label(bold, row);
            let mut cells = vec![label, row.count.to_string()];
            for &i in &calibrated {
                let s = &row.stats[i];
                cells.push(fmt_opt(s.within_1sigma.map(|x| 100.0 * x), 1));
                cells.push(fmt_opt(s.within_2sigma.map(|x| 100.0 * x), 1));
            }
            table.row(&cells);
        }
        out.push_str(&table.finish());
        out.push('\n');
    }
    out
}

/// One line of the long-format CSV.
#[derive(Serialize)]
struct CsvLine<'a> {
    group: &'a str,
    label: &'a str,
    speed_lo: f64,
    speed_hi: Option<f64>,
    count: usize,
    mean_speed: f64,
    estimator: &'a str,
    mae_deg: f64,
    rmse_deg: f64,
    abs_err_std_deg: f64,
    within_1sigma: Option<f64>,
    within_2sigma: Option<f64>,
    vs_atan2_mae_pct: Option<f64>,
    vs_atan2_rmse_pct: Option<f64>,
    vs_prior_only_mae_pct: Option<f64>,
    vs_prior_only_rmse_pct: Option<f64>,
    gap_to_bayes_mae_pct: Option<f64>,
    gap_to_bayes_rmse_pct: Option<f64>,
}

/// Writes the report as long-format CSV: one line per (group, estimator), where group
/// is `bin`, `summary` or `overall`; empty cells where a value does not apply.
///
/// Long format so that plotting tools can filter by estimator without knowing how many
/// estimators there were.
pub fn write_csv(path: impl AsRef<Path>, r: &Report) -> Result<(), EvalError> {
    let path = path.as_ref();
    let err = |source| EvalError::Csv {
        path: path.display().to_string(),
        source,
    };
    let mut w = csv::Writer::from_path(path).map_err(err)?;
    let groups = r
        .bins
        .iter()
        .map(|row| ("bin", row))
        .chain(r.summary.iter().map(|row| ("summary", row)))
        .chain(std::iter::once(("overall", &r.overall)));
    for (group, row) in groups {
        for s in &row.stats {
            let c = |reference: &str| row.comparison(&s.name, reference);
            let (atan2, prior, bayes) = (
                c(&r.config.atan2),
                c(&r.config.prior_only),
                c(&r.config.bayes),
            );
            w.serialize(CsvLine {
                group,
                label: &row.label,
                speed_lo: row.speed_lo,
                speed_hi: row.speed_hi,
                count: row.count,
                mean_speed: row.mean_speed,
                estimator: &s.name,
                mae_deg: s.mae_deg,
                rmse_deg: s.rmse_deg,
                abs_err_std_deg: s.abs_err_std_deg,
                within_1sigma: s.within_1sigma,
                within_2sigma: s.within_2sigma,
                vs_atan2_mae_pct: atan2.and_then(|c| c.mae_pct),
                vs_atan2_rmse_pct: atan2.and_then(|c| c.rmse_pct),
                vs_prior_only_mae_pct: prior.and_then(|c| c.mae_pct),
                vs_prior_only_rmse_pct: prior.and_then(|c| c.rmse_pct),
                gap_to_bayes_mae_pct: bayes.and_then(|c| c.mae_pct),
                gap_to_bayes_rmse_pct: bayes.and_then(|c| c.rmse_pct),
            })
            .map_err(err)?;
        }
    }
    w.flush().map_err(|e| err(e.into()))?;
    Ok(())
}
