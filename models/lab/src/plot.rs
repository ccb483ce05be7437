//! SVG plots of evaluation reports (the paper's Fig. 7: MAE against speed with a band).
//!
//! Only the SVG backend is built (no bitmap backend, no font files): SVG text is left to
//! the viewer's fonts, so plotting works on a headless machine with nothing installed.

use std::path::Path;

use plotters::coord::ranged1d::ValueFormatter;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;

use crate::eval::Report;

/// Errors of plotting.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    /// The report has no speed bin to plot.
    #[error("report has no speed bins to plot")]
    Empty,
    /// The drawing backend failed (typically: the file could not be written).
    #[error("plotting {path}: {message}")]
    Backend {
        /// Output file.
        path: String,
        /// Backend error, as text (plotters' error type is generic over the backend).
        message: String,
    },
}

/// A qualitative palette (Tableau 10) that stays distinguishable for many estimators.
const PALETTE: [RGBColor; 8] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(127, 127, 127),
];

/// Vertical axis scale of [`plot_mae_vs_speed_with`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum YScale {
    /// Linear, as in the paper's Fig. 7.
    #[default]
    Linear,
    /// Logarithmic: S1 errors span 0.1° to 90°, which a linear axis flattens to one
    /// visible point at standstill.
    Log,
}

/// Plots MAE against speed for every estimator of `report`, with a ±1 std band of the
/// absolute error (clamped at 0), as an SVG file on a linear axis (paper's Fig. 7).
///
/// Each bin is placed at the mean true speed of its samples rather than at its nominal
/// centre: S1 speeds sit exactly on bin edges, and the last bin ("≥ max") has no centre.
pub fn plot_mae_vs_speed(report: &Report, path: impl AsRef<Path>) -> Result<(), PlotError> {
    plot_mae_vs_speed_with(report, path, YScale::Linear)
}

/// [`plot_mae_vs_speed`] with a choice of vertical scale.
pub fn plot_mae_vs_speed_with(
    report: &Report,
    path: impl AsRef<Path>,
    scale: YScale,
) -> Result<(), PlotError> {
    let path = path.as_ref();
    if report.bins.is_empty() {
        return Err(PlotError::Empty);
    }
    let backend_err = |e: &dyn std::fmt::Display| PlotError::Backend {
        path: path.display().to_string(),
        message: e.to_string(),
    };
    let xs: Vec<f64> = report.bins.iter().map(|b| b.mean_speed).collect();
    let x_max = xs
        .iter()
        .copied()
        .fold(0.0, f64::max)
        .max(report.config.bin_width)
        * 1.05;
    let y_max = report
        .bins
        .iter()
        .flat_map(|b| b.stats.iter().map(|s| s.mae_deg + s.abs_err_std_deg))
        .fold(0.0, f64::max)
        .max(1e-3)
        * 1.05;
    // The log axis starts at half the smallest positive MAE; band edges below it are
    // clamped there (a band reaching 0 has no log).
    let y_min = report
        .bins
        .iter()
        .flat_map(|b| b.stats.iter().map(|s| s.mae_deg))
        .filter(|m| *m > 0.0)
        .fold(f64::INFINITY, f64::min)
        .min(y_max / 10.0)
        * 0.5;

    let root = SVGBackend::new(path, (960, 600)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| backend_err(&e))?;
    let mut builder = ChartBuilder::on(&root);
    builder
        .caption(
            "Heading MAE vs speed (band: ±1 std of |error|)",
            ("sans-serif", 22),
        )
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(60);
    match scale {
        YScale::Linear => {
            let chart = builder
                .build_cartesian_2d(0.0..x_max, 0.0..y_max)
                .map_err(|e| backend_err(&e))?;
            draw(chart, report, &xs, 0.0).map_err(|e| backend_err(&e))?;
        }
        YScale::Log => {
            let chart = builder
                .build_cartesian_2d(0.0..x_max, (y_min..y_max).log_scale())
                .map_err(|e| backend_err(&e))?;
            draw(chart, report, &xs, y_min).map_err(|e| backend_err(&e))?;
        }
    }
    root.present().map_err(|e| backend_err(&e))?;
    Ok(())
}

/// Draws mesh, bands, lines and legend on a chart of either y scale; `floor` is the
/// lowest value a band edge may take.
fn draw<'a, Y>(
    mut chart: ChartContext<'a, SVGBackend<'a>, Cartesian2d<RangedCoordf64, Y>>,
    report: &Report,
    xs: &[f64],
    floor: f64,
) -> Result<(), DrawingAreaErrorKind<<SVGBackend<'a> as DrawingBackend>::ErrorType>>
where
    Y: Ranged<ValueType = f64> + ValueFormatter<f64>,
{
    chart
        .configure_mesh()
        .x_desc("true speed [m/s]")
        .y_desc("MAE of wrapped heading error [deg]")
        .draw()?;
    for (k, name) in report.estimators.iter().enumerate() {
        let color = PALETTE[k % PALETTE.len()];
        let stats: Vec<(f64, f64, f64)> = report
            .bins
            .iter()
            .zip(xs)
            .map(|(b, &x)| (x, b.stats[k].mae_deg, b.stats[k].abs_err_std_deg))
            .collect();
        // Band polygon: upper edge left to right, then lower edge back.
        let band: Vec<(f64, f64)> = stats
            .iter()
            .map(|&(x, m, s)| (x, (m + s).max(floor)))
            .chain(stats.iter().rev().map(|&(x, m, s)| (x, (m - s).max(floor))))
            .collect();
        chart.draw_series(std::iter::once(Polygon::new(band, color.mix(0.15))))?;
        chart
            .draw_series(LineSeries::new(
                stats.iter().map(|&(x, m, _)| (x, m.max(floor))),
                color.stroke_width(2),
            ))?
            .label(name.as_str())
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2))
            });
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .position(SeriesLabelPosition::UpperRight)
        .draw()?;
    Ok(())
}

/// One series of [`plot_heading_timeline`]: name, heading per epoch (degrees), and an
/// optional 1σ per epoch drawn as a band.
pub struct Series<'a> {
    /// Legend.
    pub name: &'a str,
    /// Heading, degrees.
    pub heading_deg: &'a [f32],
    /// 1σ, degrees.
    pub std_deg: Option<&'a [f32]>,
}

/// Heading against time (truth and estimators) as an SVG: points, not lines, so the
/// wrap at 0°/360° draws no false strokes; a σ band is a vertical bar per epoch, split
/// at the wrap.
pub fn plot_heading_timeline(
    path: impl AsRef<Path>,
    title: &str,
    t_s: &[f64],
    series: &[Series<'_>],
) -> Result<(), PlotError> {
    let path = path.as_ref();
    let backend_err = |e: &dyn std::fmt::Display| PlotError::Backend {
        path: path.display().to_string(),
        message: e.to_string(),
    };
    let (Some(&t0), Some(&t1)) = (t_s.first(), t_s.last()) else {
        return Err(PlotError::Empty);
    };
    let root = SVGBackend::new(path, (1400, 560)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| backend_err(&e))?;
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 20))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(55)
        .build_cartesian_2d(0.0..(t1 - t0).max(1.0), 0.0..360.0)
        .map_err(|e| backend_err(&e))?;
    chart
        .configure_mesh()
        .x_desc("time [s]")
        .y_desc("heading [deg, clockwise from north]")
        .y_labels(9)
        .draw()
        .map_err(|e| backend_err(&e))?;
    for (k, s) in series.iter().enumerate() {
        let color = if k == 0 {
            BLACK
        } else {
            PALETTE[(k - 1) % PALETTE.len()]
        };
        if let Some(sd) = s.std_deg {
            let band = color.mix(0.12);
            for (i, (&h, &d)) in s.heading_deg.iter().zip(sd).enumerate() {
                let x = t_s[i] - t0;
                let (lo, hi) = ((h - d) as f64, (h + d) as f64);
                for (a, b) in [(lo, hi), (lo + 360.0, hi + 360.0), (lo - 360.0, hi - 360.0)] {
                    let (a, b) = (a.max(0.0), b.min(360.0));
                    if a < b {
                        chart
                            .draw_series(std::iter::once(PathElement::new(
                                vec![(x, a), (x, b)],
                                band.stroke_width(2),
                            )))
                            .map_err(|e| backend_err(&e))?;
                    }
                }
            }
        }
        let size = if k == 0 { 3 } else { 2 };
        chart
            .draw_series(
                s.heading_deg
                    .iter()
                    .enumerate()
                    .map(|(i, &h)| Circle::new((t_s[i] - t0, h as f64), size, color.filled())),
            )
            .map_err(|e| backend_err(&e))?
            .label(s.name)
            .legend(move |(x, y)| Circle::new((x + 8, y), 4, color.filled()));
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .position(SeriesLabelPosition::UpperRight)
        .draw()
        .map_err(|e| backend_err(&e))?;
    root.present().map_err(|e| backend_err(&e))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::eval::{evaluate, Estimate, EvalConfig, Truth};

    #[test]
    fn writes_an_svg_with_every_estimator() {
        let truth = Truth {
            heading_deg: vec![10.0, 20.0, 30.0, 40.0],
            speed: vec![0.05, 0.3, 1.2, 7.0],
        };
        let est = |name: &str, h: &[f32]| Estimate {
            name: name.into(),
            heading_deg: h.to_vec(),
            std_deg: None,
        };
        let r = evaluate(
            &truth,
            &[
                est("atan2", &[30.0, 25.0, 31.0, 40.5]),
                est("ghnet", &[12.0, 21.0, 30.5, 40.0]),
            ],
            &EvalConfig::default(),
        )
        .unwrap();
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("mae.svg");
        plot_mae_vs_speed(&r, &path).unwrap();
        let linear = std::fs::read_to_string(&path).unwrap();
        plot_mae_vs_speed_with(&r, &path, YScale::Log).unwrap();
        let log = std::fs::read_to_string(&path).unwrap();
        for svg in [&linear, &log] {
            assert!(svg.starts_with("<svg"));
            for needle in [
                "atan2",
                "ghnet",
                "true speed [m/s]",
                "<polygon",
                "<polyline",
            ] {
                assert!(svg.contains(needle), "missing {needle}");
            }
        }
        assert_ne!(linear, log);
    }

    #[test]
    fn empty_report_is_an_error() {
        let r = evaluate(&Truth::default(), &[], &EvalConfig::default()).unwrap();
        assert!(matches!(
            plot_mae_vs_speed(&r, "/nonexistent/x.svg"),
            Err(PlotError::Empty)
        ));
    }
}
