//! The table engine of `ghnet eval`: one [`Tally`] of wrapped errors and σ coverage
//! per estimator and group of samples (a speed bin or band, a turn-rate band, a
//! summary range, everything), and one [`Markdown`] writer for the tables.
//!
//! The per-epoch tables ([`crate::eval`]) and the streamed ones ([`crate::streval`])
//! group their samples differently (bins of true speed against bands with stops of
//! their own) but count the same way, so a figure means the same in both.

use std::fmt::Write as _;

use serde::{Deserialize, Serialize};

/// Running sums of one estimator's errors over one group of samples; f64 so long sums
/// do not drift.
#[derive(Clone, Debug)]
pub struct Tally {
    n: usize,
    sum_abs: f64,
    sum_sq: f64,
    n_sigma: usize,
    in1: usize,
    in2: usize,
}

impl Default for Tally {
    fn default() -> Self {
        Self {
            n: 0,
            // −0.0, the neutral element of a float sum: an empty group's MAE prints as
            // Rust's sum over no errors does.
            sum_abs: -0.0,
            sum_sq: 0.0,
            n_sigma: 0,
            in1: 0,
            in2: 0,
        }
    }
}

/// Error statistics of one estimator over one group of samples.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EstimatorStats {
    /// Estimator name.
    pub name: String,
    /// Mean absolute wrapped error (deg) (also the mean of the band in the plot).
    pub mae_deg: f64,
    /// Root mean square wrapped error (deg).
    pub rmse_deg: f64,
    /// Standard deviation of the absolute wrapped error (deg) (population, ÷N): the
    /// half-width of the band in the paper's Fig. 7.
    pub abs_err_std_deg: f64,
    /// Share (0..1) of samples whose |error| ≤ the reported 1σ; None without σ.
    /// A Gaussian, well calibrated σ gives 0.683.
    pub within_1sigma: Option<f64>,
    /// Share (0..1) of samples whose |error| ≤ 2σ; Gaussian: 0.954.
    pub within_2sigma: Option<f64>,
}

impl Tally {
    /// Count one wrapped error `err` (degrees) with its reported σ, if any.
    pub fn add(&mut self, err: f64, std: Option<f64>) {
        self.n += 1;
        self.sum_abs += err.abs();
        self.sum_sq += err * err;
        if let Some(s) = std {
            self.n_sigma += 1;
            self.in1 += usize::from(err.abs() <= s);
            self.in2 += usize::from(err.abs() <= 2.0 * s);
        }
    }

    /// The statistics so far of the estimator `name`. `with_sigma` says whether it
    /// reports σ: an estimator with σ over an empty group has 0 errors within it (not
    /// `None`), so that its column stays filled.
    pub fn stats(&self, name: &str, with_sigma: bool) -> EstimatorStats {
        let n = self.n.max(1) as f64;
        let mae = self.sum_abs / n;
        let ms = self.sum_sq / n;
        let share = |k: usize| with_sigma.then(|| k as f64 / self.n_sigma.max(1) as f64);
        EstimatorStats {
            name: name.to_owned(),
            mae_deg: mae,
            rmse_deg: ms.sqrt(),
            abs_err_std_deg: (ms - mae * mae).max(0.0).sqrt(),
            within_1sigma: share(self.in1),
            within_2sigma: share(self.in2),
        }
    }

    /// Whether any counted error came with a σ.
    pub fn has_sigma(&self) -> bool {
        self.n_sigma > 0
    }
}

/// A Markdown table: a header, then rows of cells, every column right-aligned except,
/// optionally, the first (a label).
#[derive(Debug, Clone)]
pub struct Markdown {
    out: String,
}

impl Markdown {
    /// A table with these column headers; `label_left` aligns the first column left.
    pub fn new(header: &[String], label_left: bool) -> Self {
        let mut out = format!("| {} |\n|", header.join(" | "));
        if label_left {
            out += "---|";
        }
        out += &"---:|".repeat(header.len() - usize::from(label_left));
        out.push('\n');
        Self { out }
    }

    /// Append a row.
    pub fn row(&mut self, cells: &[String]) {
        let _ = writeln!(self.out, "| {} |", cells.join(" | "));
    }

    /// The table's text, ending with a newline.
    pub fn finish(self) -> String {
        self.out
    }
}

/// `x` with `digits` decimals, or "–" when missing.
pub fn fmt_opt(x: Option<f64>, digits: usize) -> String {
    match x {
        Some(v) => format!("{v:.digits$}"),
        None => "–".to_owned(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn markdown_aligns_and_joins() {
        let mut t = Markdown::new(&["a".into(), "b".into()], true);
        t.row(&["x".into(), String::new()]);
        assert_eq!(t.finish(), "| a | b |\n|---|---:|\n| x |  |\n");
        let t = Markdown::new(&["a".into(), "b".into()], false);
        assert_eq!(t.finish(), "| a | b |\n|---:|---:|\n");
    }

    #[test]
    fn an_empty_group_keeps_its_sigma_columns() {
        let t = Tally::default().stats("x", true);
        assert_eq!(t.within_1sigma, Some(0.0));
        assert!(t.mae_deg == 0.0 && t.mae_deg.is_sign_negative());
        assert_eq!(Tally::default().stats("x", false).within_2sigma, None);
    }
}
