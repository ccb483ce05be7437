//! The per-bin statistics of the evaluation tables: estimates, truth, binning by true
//! speed, error and σ statistics per bin and the comparisons to the references.

use serde::{Deserialize, Serialize};

use crate::sim::Sample;
pub use crate::table::EstimatorStats;
use crate::table::Tally;

/// Default name of the model-free baseline, ψ = atan2(v_E, v_N).
pub const ATAN2: &str = "atan2";
/// Default name of the prior-only baseline (atan2 clipped to the trained heading range).
pub const PRIOR_ONLY: &str = "prior-only";
/// Default name of the Bayes-optimal estimate for the simulated prior.
pub const BAYES: &str = "bayes";

/// Wraps an angle difference to (−180, 180] degrees.
///
/// Equal to atan2(sin Δ, cos Δ) but exact for representable inputs (no trigonometric
/// round-off), so 359 − 1 gives exactly −2 and −180 gives 180. NaN stays NaN.
pub fn wrap_deg(d: f32) -> f32 {
    let x = (d as f64).rem_euclid(360.0);
    let w = if x > 180.0 { x - 360.0 } else { x };
    w as f32
}

/// Heading of a velocity in degrees clockwise from north, in [0, 360).
///
/// This is the model-based estimate of the paper (ψ = atan2(v_E, v_N)). A zero velocity
/// gives 0° (north), which is what `atan2(0, 0)` returns; it carries no information.
pub fn atan2_heading_deg(vn: f32, ve: f32) -> f32 {
    let h = (ve as f64).atan2(vn as f64).to_degrees().rem_euclid(360.0) as f32;
    // A tiny negative angle wraps to 360 − ε, which rounds to 360.0 in f32.
    if h >= 360.0 {
        0.0
    } else {
        h
    }
}

/// Clips a heading to the arc from `lo` clockwise to `hi` (degrees); see
/// [`ghnet_inference::head::clip_to_range`]. Used for the prior-only baseline: a model trained on
/// headings in [0, 90] can at best learn to stay inside that range, so atan2 clipped to
/// it is the baseline any gain must be measured against. The same function clamps the
/// restricted-range heads' output, so baseline and model clip identically.
pub use ghnet_inference::head::clip_to_range;

/// One estimator's headings for a set of samples, in the order of the [`Truth`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Estimate {
    /// Name shown in tables and plots; references are recognised by name
    /// ([`EvalConfig::atan2`], [`EvalConfig::prior_only`], [`EvalConfig::bayes`]).
    pub name: String,
    /// Estimated heading per sample (deg); any value, errors are wrapped.
    pub heading_deg: Vec<f32>,
    /// Reported 1σ per sample (deg), if the estimator gives one; used for calibration.
    pub std_deg: Option<Vec<f32>>,
}

impl Estimate {
    /// The model-based baseline ψ = atan2(v_E, v_N) for each sample, named [`ATAN2`].
    pub fn atan2(samples: &[Sample]) -> Self {
        Self {
            name: ATAN2.to_owned(),
            heading_deg: samples
                .iter()
                .map(|s| atan2_heading_deg(s.v_north, s.v_east))
                .collect(),
            std_deg: None,
        }
    }

    /// The prior-only baseline, named [`PRIOR_ONLY`]: atan2 clipped to the heading arc
    /// [`lo`, `hi`] the model was trained on (see [`clip_to_range`]).
    pub fn prior_only(samples: &[Sample], lo: f32, hi: f32) -> Self {
        Self {
            name: PRIOR_ONLY.to_owned(),
            heading_deg: samples
                .iter()
                .map(|s| clip_to_range(atan2_heading_deg(s.v_north, s.v_east), lo, hi))
                .collect(),
            std_deg: None,
        }
    }
}

/// Ground truth per sample: what errors are measured against and what bins are made of.
#[derive(Clone, Debug, PartialEq, Default, Serialize, Deserialize)]
pub struct Truth {
    /// True heading (deg).
    pub heading_deg: Vec<f32>,
    /// True speed (m/s); the binning variable.
    pub speed: Vec<f32>,
}

impl Truth {
    /// Truth of simulated samples (`true_heading_deg`, `true_speed`).
    pub fn from_samples(samples: &[Sample]) -> Self {
        Self {
            heading_deg: samples.iter().map(|s| s.true_heading_deg).collect(),
            speed: samples.iter().map(|s| s.true_speed).collect(),
        }
    }
}

/// How to bin and which estimators are the references.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EvalConfig {
    /// Width of a speed bin (m/s). Bin k covers [k·w, (k+1)·w) and is labelled by its
    /// lower edge, like the paper ("<0.1" for the first).
    pub bin_width: f64,
    /// Every speed at or above this goes into one last bin labelled "≥max" (m/s).
    pub max_speed: f64,
    /// Extra summary rows over speed ranges [lo, hi) (m/s), like the paper's averages
    /// over 0.01–0.8 and 0.9–2 m/s.
    pub summary_ranges: Vec<(f64, f64)>,
    /// Name of the atan2 estimator: every other estimator gets "improvement over atan2".
    pub atan2: String,
    /// Name of the prior-only baseline: estimators other than atan2 and Bayes get
    /// "improvement over prior-only".
    pub prior_only: String,
    /// Name of the Bayes-optimal estimator: estimators other than atan2 get "gap to Bayes".
    pub bayes: String,
}

impl Default for EvalConfig {
    fn default() -> Self {
        Self {
            bin_width: 0.1,
            max_speed: 5.0,
            summary_ranges: vec![(0.0, 0.9), (0.9, 2.1)],
            atan2: ATAN2.to_owned(),
            prior_only: PRIOR_ONLY.to_owned(),
            bayes: BAYES.to_owned(),
        }
    }
}

/// Errors of [`evaluate`] and [`write_csv`](super::write_csv).
#[derive(Debug, thiserror::Error)]
pub enum EvalError {
    /// An estimator or the truth does not have one value per sample.
    #[error("{name}: {got} values for {expected} samples")]
    LengthMismatch {
        /// Estimator (or "truth speed").
        name: String,
        /// Number of truth samples.
        expected: usize,
        /// Number of values given.
        got: usize,
    },
    /// A heading, speed or σ is NaN or infinite (or σ negative); silently dropping it
    /// would bias the tables.
    #[error("{name}: invalid value {value} at sample {index}")]
    Invalid {
        /// Estimator (or "truth").
        name: String,
        /// Sample index.
        index: usize,
        /// Offending value.
        value: f32,
    },
    /// Two estimators share a name, so the tables could not tell them apart.
    #[error("two estimators are named {0:?}")]
    DuplicateName(String),
    /// Bin width or maximum speed is not positive and finite.
    #[error("invalid binning: bin_width {bin_width}, max_speed {max_speed}")]
    Binning {
        /// Configured bin width.
        bin_width: f64,
        /// Configured maximum speed.
        max_speed: f64,
    },
    /// Writing the CSV failed.
    #[error("writing {path}: {source}")]
    Csv {
        /// File involved.
        path: String,
        /// Underlying error.
        #[source]
        source: csv::Error,
    },
}

/// Whether a comparison is a gain over a baseline or a distance to the optimum.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ComparisonKind {
    /// 100·(1 − estimator/reference): positive is better than the reference (the
    /// paper's "improvement %").
    Improvement,
    /// 100·(estimator/reference − 1): how far above the Bayes limit; ≥ 0 up to noise.
    Gap,
}

/// An estimator measured against a reference estimator in one group.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Comparison {
    /// Estimator being compared.
    pub estimator: String,
    /// Reference (atan2, prior-only or Bayes).
    pub reference: String,
    /// Improvement or gap, see [`ComparisonKind`].
    pub kind: ComparisonKind,
    /// On MAE (%); None when the reference error is 0 and the estimator's is not.
    pub mae_pct: Option<f64>,
    /// On RMSE (%); None as for `mae_pct`.
    pub rmse_pct: Option<f64>,
}

/// Statistics of one group of samples: a speed bin, a summary range or everything.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Row {
    /// Label: "<0.1", "0.1", …, "≥5", a range "0–0.9", or "all".
    pub label: String,
    /// Lower speed edge (m/s).
    pub speed_lo: f64,
    /// Upper speed edge (exclusive) (m/s); None for open-ended groups.
    pub speed_hi: Option<f64>,
    /// Number of samples.
    pub count: usize,
    /// Mean true speed of the samples (m/s): where the plot puts the bin, since the
    /// samples of a bin need not be spread evenly in it (S1 speeds sit on bin edges).
    pub mean_speed: f64,
    /// One entry per estimator, in input order.
    pub stats: Vec<EstimatorStats>,
    /// Comparisons to the references present.
    pub comparisons: Vec<Comparison>,
}

impl Row {
    /// Statistics of the estimator called `name`, if evaluated.
    pub fn stats_of(&self, name: &str) -> Option<&EstimatorStats> {
        self.stats.iter().find(|s| s.name == name)
    }

    /// The comparison of `estimator` against `reference`, if made.
    pub fn comparison(&self, estimator: &str, reference: &str) -> Option<&Comparison> {
        self.comparisons
            .iter()
            .find(|c| c.estimator == estimator && c.reference == reference)
    }
}

/// The full evaluation; serialisable to JSON so that headline numbers can be tracked.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Report {
    /// Configuration used.
    pub config: EvalConfig,
    /// Estimator names in input order.
    pub estimators: Vec<String>,
    /// Non-empty speed bins in increasing speed.
    pub bins: Vec<Row>,
    /// Summary rows for [`EvalConfig::summary_ranges`] (empty ranges omitted).
    pub summary: Vec<Row>,
    /// All samples.
    pub overall: Row,
}

/// Samples of one group: per-estimator sums plus the speeds.
#[derive(Clone)]
struct Group {
    accs: Vec<Tally>,
    count: usize,
    sum_speed: f64,
}

impl Group {
    fn new(n_est: usize) -> Self {
        Self {
            accs: vec![Tally::default(); n_est],
            count: 0,
            sum_speed: 0.0,
        }
    }
}

/// Formats a speed edge without float noise (0.30000000000000004 → "0.3").
pub(super) fn fmt_speed(x: f64) -> String {
    let r = (x * 1e6).round() / 1e6;
    format!("{r}")
}

fn pct(est: f64, reference: f64, kind: ComparisonKind) -> Option<f64> {
    if reference == 0.0 {
        return (est == 0.0).then_some(0.0);
    }
    Some(match kind {
        ComparisonKind::Improvement => 100.0 * (1.0 - est / reference),
        ComparisonKind::Gap => 100.0 * (est / reference - 1.0),
    })
}

fn make_row(
    label: String,
    speed_lo: f64,
    speed_hi: Option<f64>,
    g: &Group,
    names: &[String],
    cfg: &EvalConfig,
) -> Row {
    let stats: Vec<EstimatorStats> = g
        .accs
        .iter()
        .zip(names)
        .map(|(a, n)| a.stats(n, a.has_sigma()))
        .collect();
    let find = |n: &str| stats.iter().find(|s| s.name == n);
    let mut comparisons = Vec::new();
    let refs = [
        (&cfg.atan2, ComparisonKind::Improvement),
        (&cfg.prior_only, ComparisonKind::Improvement),
        (&cfg.bayes, ComparisonKind::Gap),
    ];
    for (reference, kind) in refs {
        let Some(r) = find(reference) else { continue };
        for s in &stats {
            let skip = s.name == *reference
                || (*reference != cfg.atan2 && s.name == cfg.atan2)
                || (*reference == cfg.prior_only && s.name == cfg.bayes);
            if skip {
                continue;
            }
            comparisons.push(Comparison {
                estimator: s.name.clone(),
                reference: reference.clone(),
                kind,
                mae_pct: pct(s.mae_deg, r.mae_deg, kind),
                rmse_pct: pct(s.rmse_deg, r.rmse_deg, kind),
            });
        }
    }
    Row {
        label,
        speed_lo,
        speed_hi,
        count: g.count,
        mean_speed: g.sum_speed / g.count.max(1) as f64,
        stats,
        comparisons,
    }
}

/// Evaluates estimators against the truth, per speed bin, per summary range and overall.
///
/// Every estimator must give one finite heading (and, if any, one finite non-negative
/// σ) per truth sample; invalid values are an error rather than being skipped, since
/// skipping would flatter the estimator. Bins without samples are left out.
pub fn evaluate(
    truth: &Truth,
    estimates: &[Estimate],
    cfg: &EvalConfig,
) -> Result<Report, EvalError> {
    let names = validate(truth, estimates, cfg)?;
    let n = truth.heading_deg.len();

    // A relative tolerance keeps grid speeds stored as f32 (0.7 → 0.69999999) in their
    // own bin; it moves bin edges by 1e-4 bin widths, far below any receiver's noise.
    const EDGE_TOL: f64 = 1e-4;
    let last = (cfg.max_speed / cfg.bin_width - EDGE_TOL).ceil().max(0.0) as usize;
    let bin_of = |s: f32| -> usize {
        let k = (s as f64 / cfg.bin_width + EDGE_TOL).floor().max(0.0) as usize;
        k.min(last)
    };
    let mut bins = vec![Group::new(estimates.len()); last + 1];
    let mut summary = vec![Group::new(estimates.len()); cfg.summary_ranges.len()];
    let mut overall = Group::new(estimates.len());

    for i in 0..n {
        let speed = truth.speed[i] as f64;
        let truth_h = truth.heading_deg[i];
        let mut groups: Vec<&mut Group> = Vec::with_capacity(2 + summary.len());
        groups.push(&mut bins[bin_of(truth.speed[i])]);
        groups.push(&mut overall);
        for (g, &(lo, hi)) in summary.iter_mut().zip(&cfg.summary_ranges) {
            // Same edge tolerance as the bins so that a range [0, 0.9) is bins 0..=8.
            let x = speed / cfg.bin_width + EDGE_TOL;
            if x >= lo / cfg.bin_width && x < hi / cfg.bin_width {
                groups.push(g);
            }
        }
        for g in groups {
            g.count += 1;
            g.sum_speed += speed;
            for (acc, e) in g.accs.iter_mut().zip(estimates) {
                let err = wrap_deg(e.heading_deg[i] - truth_h) as f64;
                let std = e.std_deg.as_ref().map(|s| s[i] as f64);
                acc.add(err, std);
            }
        }
    }

    let w = cfg.bin_width;
    let bin_rows = bins
        .iter()
        .enumerate()
        .filter(|(_, g)| g.count > 0)
        .map(|(k, g)| {
            let lo = k as f64 * w;
            let (label, hi) = if k == last {
                (format!("≥{}", fmt_speed(cfg.max_speed)), None)
            } else if k == 0 {
                (format!("<{}", fmt_speed(w)), Some(w))
            } else {
                (fmt_speed(lo), Some((k + 1) as f64 * w))
            };
            let lo = if k == last { cfg.max_speed } else { lo };
            make_row(label, lo, hi, g, &names, cfg)
        })
        .collect();
    let summary_rows = summary
        .iter()
        .zip(&cfg.summary_ranges)
        .filter(|(g, _)| g.count > 0)
        .map(|(g, &(lo, hi))| {
            let label = format!("{}–{}", fmt_speed(lo), fmt_speed(hi));
            make_row(label, lo, Some(hi), g, &names, cfg)
        })
        .collect();
    let overall_row = make_row("all".into(), 0.0, None, &overall, &names, cfg);
    Ok(Report {
        config: cfg.clone(),
        estimators: names,
        bins: bin_rows,
        summary: summary_rows,
        overall: overall_row,
    })
}

/// Checks the inputs of [`evaluate`]: lengths, binning, finite values, unique names.
/// Returns the estimators' names in order.
fn validate(
    truth: &Truth,
    estimates: &[Estimate],
    cfg: &EvalConfig,
) -> Result<Vec<String>, EvalError> {
    let n = truth.heading_deg.len();
    if truth.speed.len() != n {
        return Err(EvalError::LengthMismatch {
            name: "truth speed".into(),
            expected: n,
            got: truth.speed.len(),
        });
    }
    let positive = |x: f64| x > 0.0 && x.is_finite();
    if !(positive(cfg.bin_width) && positive(cfg.max_speed)) {
        return Err(EvalError::Binning {
            bin_width: cfg.bin_width,
            max_speed: cfg.max_speed,
        });
    }
    let invalid = |name: &str, index: usize, value: f32| EvalError::Invalid {
        name: name.to_owned(),
        index,
        value,
    };
    for (i, (&h, &s)) in truth.heading_deg.iter().zip(&truth.speed).enumerate() {
        if !h.is_finite() {
            return Err(invalid("truth heading", i, h));
        }
        if !s.is_finite() {
            return Err(invalid("truth speed", i, s));
        }
    }
    let mut names: Vec<String> = Vec::with_capacity(estimates.len());
    for e in estimates {
        if names.contains(&e.name) {
            return Err(EvalError::DuplicateName(e.name.clone()));
        }
        names.push(e.name.clone());
        let lens = std::iter::once(e.heading_deg.len()).chain(e.std_deg.as_ref().map(Vec::len));
        for got in lens {
            if got != n {
                return Err(EvalError::LengthMismatch {
                    name: e.name.clone(),
                    expected: n,
                    got,
                });
            }
        }
        if let Some(i) = e.heading_deg.iter().position(|h| !h.is_finite()) {
            return Err(invalid(&e.name, i, e.heading_deg[i]));
        }
        if let Some(sd) = &e.std_deg {
            if let Some(i) = sd.iter().position(|s| !(s.is_finite() && *s >= 0.0)) {
                return Err(invalid(&e.name, i, sd[i]));
            }
        }
    }
    Ok(names)
}
