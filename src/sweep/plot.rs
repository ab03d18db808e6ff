//! SVG plots of a sweep (plotters' SVG backend; text is left to the SVG viewer's fonts, so no
//! system font is needed to draw).

use super::{SweepError, SweepRecord, pareto_front};
use plotters::prelude::*;
use std::path::PathBuf;

/// Plot size in SVG pixels.
const SIZE: (u32, u32) = (800, 560);

fn plot_error(name: &str, e: Box<dyn std::error::Error>) -> SweepError {
    SweepError::Plot {
        path: PathBuf::from(name),
        message: e.to_string(),
    }
}

/// `lo..hi` covering the finite values with 5 % padding; `0..1` when there are none, `±1` around
/// a single value.
pub(crate) fn padded_range(values: impl Iterator<Item = f64>) -> std::ops::Range<f64> {
    let (lo, hi) = values
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| (lo.min(v), hi.max(v)));
    if lo > hi {
        0.0..1.0
    } else if hi - lo < 1e-9 * hi.abs().max(1.0) {
        lo - 1.0..hi + 1.0
    } else {
        let pad = 0.05 * (hi - lo);
        lo - pad..hi + pad
    }
}

/// A scatter of `(x, y)` per record with the Pareto front (low x, high y) as filled red markers
/// joined by a line and labelled. Non-finite points are left out.
fn scatter_with_front(
    points: &[(f64, f64)],
    labels: &[String],
    title: &str,
    x_desc: &str,
) -> Result<String, Box<dyn std::error::Error>> {
    let finite: Vec<(f64, f64)> = points
        .iter()
        .copied()
        .filter(|p| p.0.is_finite() && p.1.is_finite())
        .collect();
    let front_idx: Vec<usize> = pareto_front(points)
        .into_iter()
        .filter(|&i| points[i].0.is_finite() && points[i].1.is_finite())
        .collect();
    let front: Vec<(f64, f64)> = front_idx.iter().map(|&i| points[i]).collect();
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, SIZE).into_drawing_area();
        root.fill(&WHITE)?;
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 20))
            .margin(12)
            .x_label_area_size(45)
            .y_label_area_size(60)
            .build_cartesian_2d(
                padded_range(finite.iter().map(|p| p.0)),
                padded_range(finite.iter().map(|p| p.1)),
            )?;
        chart.configure_mesh().x_desc(x_desc).y_desc("test PSNR (dB)").draw()?;
        chart
            .draw_series(finite.iter().map(|&p| Circle::new(p, 4, BLUE.stroke_width(1))))?
            .label("run")
            .legend(|(x, y)| Circle::new((x + 10, y), 4, BLUE.stroke_width(1)));
        chart
            .draw_series(LineSeries::new(front.iter().copied(), RED.stroke_width(2)))?
            .label("Pareto front")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], RED.stroke_width(2)));
        chart.draw_series(front.iter().map(|&p| Circle::new(p, 5, RED.filled())))?;
        // Labels to the lower right of the front markers.
        chart.draw_series(front_idx.iter().map(|&i| {
            EmptyElement::at(points[i]) + Text::new(labels[i].clone(), (6, 4), ("sans-serif", 11).into_font())
        }))?;
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::LowerRight)
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .draw()?;
        root.present()?;
    }
    Ok(svg)
}

/// SVG of test PSNR (dB) against training time (s), one marker per run, the Pareto front in red
/// with the slugs of its runs.
pub fn plot_psnr_vs_time_svg(records: &[SweepRecord]) -> Result<String, SweepError> {
    let points: Vec<(f64, f64)> = records
        .iter()
        .map(|r| (r.summary.train_seconds, r.summary.test_psnr))
        .collect();
    let labels: Vec<String> = records.iter().map(|r| r.setting.slug()).collect();
    scatter_with_front(&points, &labels, "PSNR against training time", "training time (s)")
        .map_err(|e| plot_error("psnr_vs_time.svg", e))
}

/// SVG of test PSNR (dB) against model size on disk (MB = 10⁶ bytes), the Pareto front in red
/// with the slugs of its runs. Runs with `model_bytes == 0` (no model saved) are left out.
pub fn plot_psnr_vs_size_svg(records: &[SweepRecord]) -> Result<String, SweepError> {
    let points: Vec<(f64, f64)> = records
        .iter()
        .map(|r| {
            (
                super::output::size_cost(r.summary.model_bytes) / 1e6,
                r.summary.test_psnr,
            )
        })
        .collect();
    let labels: Vec<String> = records.iter().map(|r| r.setting.slug()).collect();
    scatter_with_front(&points, &labels, "PSNR against model size", "model size (MB)")
        .map_err(|e| plot_error("psnr_vs_size.svg", e))
}

/// SVG of test PSNR (dB) against training time (s) during each run (its `curve`), one coloured
/// line per run labelled with its slug. Runs without curve points are left out.
pub fn plot_curves_svg(records: &[SweepRecord]) -> Result<String, SweepError> {
    let lines: Vec<(String, Vec<(f64, f64)>)> = records
        .iter()
        .map(|r| {
            let points = r.summary.curve.iter().map(|c| (c.seconds, c.psnr)).collect();
            (r.setting.slug(), points)
        })
        .collect();
    plot_lines_svg(&lines, "Test PSNR during training", "training time (s)", "curves.svg")
}

/// SVG of test PSNR (dB, the y axis) against `x_desc` (the x axis, which always includes 0): one
/// coloured line with markers per `(label, points)`, labelled in a legend. Non-finite points are
/// left out, and lines left without points are not drawn. `file_name` names the plot in an error.
///
/// ```
/// let lines = vec![("a".to_string(), vec![(0.5, 20.0), (1.0, 24.0)])];
/// let svg = bbsplat::sweep::plot_lines_svg(&lines, "PSNR", "minutes", "p.svg").unwrap();
/// assert!(svg.starts_with("<svg") && svg.contains("minutes"));
/// ```
pub fn plot_lines_svg(
    lines: &[(String, Vec<(f64, f64)>)],
    title: &str,
    x_desc: &str,
    file_name: &str,
) -> Result<String, SweepError> {
    let draw = || -> Result<String, Box<dyn std::error::Error>> {
        let lines: Vec<(&str, Vec<(f64, f64)>)> = lines
            .iter()
            .map(|(label, l)| {
                let finite = l.iter().copied().filter(|p| p.0.is_finite() && p.1.is_finite());
                (label.as_str(), finite.collect::<Vec<_>>())
            })
            .filter(|(_, l)| !l.is_empty())
            .collect();
        let all = || lines.iter().flat_map(|(_, l)| l.iter().copied());
        let mut svg = String::new();
        {
            let root = SVGBackend::with_string(&mut svg, SIZE).into_drawing_area();
            root.fill(&WHITE)?;
            let x = padded_range(all().map(|p| p.0).chain(std::iter::once(0.0)));
            let mut chart = ChartBuilder::on(&root)
                .caption(title, ("sans-serif", 20))
                .margin(12)
                .x_label_area_size(45)
                .y_label_area_size(60)
                .build_cartesian_2d(x, padded_range(all().map(|p| p.1)))?;
            chart.configure_mesh().x_desc(x_desc).y_desc("test PSNR (dB)").draw()?;
            for (i, (label, line)) in lines.iter().enumerate() {
                let colour = Palette99::pick(i).to_rgba();
                chart
                    .draw_series(LineSeries::new(line.iter().copied(), colour.stroke_width(2)))?
                    .label(*label)
                    .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], colour.stroke_width(2)));
                chart.draw_series(line.iter().map(|&p| Circle::new(p, 3, colour.filled())))?;
            }
            if !lines.is_empty() {
                chart
                    .configure_series_labels()
                    .position(SeriesLabelPosition::LowerRight)
                    .background_style(WHITE.mix(0.85))
                    .border_style(BLACK)
                    .draw()?;
            }
            root.present()?;
        }
        Ok(svg)
    };
    draw().map_err(|e| plot_error(file_name, e))
}
