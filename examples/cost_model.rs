//! A training step's time against image size and billboard count, on trained-like object scenes
//! generated at each size (`TrainedLikeConfig::object`: the billboards' screen sizes scale with
//! the image width and `1/√n`, so the work per pixel stays that of a trained lego state). Prints
//! a markdown table and a fit `t = a·pixels + b·billboards + c` (least relative squares), and writes the
//! plot as SVG. docs/perf.md, "Cost model", has the figures.
//!
//! ```text
//! cargo run --release --features examples --example cost_model -- OUT.svg [SIZES] [BILLBOARDS] [STEPS]
//! ```
//!
//! `SIZES` and `BILLBOARDS` are comma-separated (default `200,400,800,1600` and
//! `10000,30000,100000,300000`); each configuration takes the untimed steps up to 3/32 of a
//! 64-step run (as `benches/train_step.rs`), then `STEPS` timed steps (default 3), the median
//! kept. A step draws one view, so the number of views does not enter its time (only memory:
//! docs/training.md, "Memory").

use bbsplat::train::trained_like_case::trained_like_case;
use bbsplat::train::{TrainConfig, Trainer};
use plotters::prelude::*;
use std::time::Instant;

/// Median seconds of a step at `size²` pixels with `billboards` billboards.
fn step_seconds(size: u32, billboards: usize, steps: usize) -> f64 {
    let (model, views, config) = trained_like_case(size, billboards);
    let mut trainer = Trainer::new(
        model,
        TrainConfig {
            iterations: 64,
            ..config
        },
    );
    for _ in 0..6 {
        trainer.step(&views).expect("a step");
    }
    let mut times: Vec<f64> = (0..steps)
        .map(|_| {
            let t = Instant::now();
            trainer.step(&views).expect("a step");
            t.elapsed().as_secs_f64()
        })
        .collect();
    times.sort_by(f64::total_cmp);
    times[times.len() / 2]
}

/// Least squares of `t = a·x + b·y + c` in relative error (each row weighted by `1/t²`, so
/// that the 30 ms steps count as much as the 1.5 s ones; normal equations, Cramer's rule).
fn fit(rows: &[(f64, f64, f64)]) -> [f64; 3] {
    let mut m = [[0.0f64; 3]; 3];
    let mut v = [0.0f64; 3];
    for &(x, y, t) in rows {
        let f = [x, y, 1.0];
        let w = 1.0 / (t * t);
        for i in 0..3 {
            for j in 0..3 {
                m[i][j] += w * f[i] * f[j];
            }
            v[i] += w * f[i] * t;
        }
    }
    let det = |m: &[[f64; 3]; 3]| {
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    };
    let d = det(&m);
    [0, 1, 2].map(|k| {
        let mut mk = m;
        for i in 0..3 {
            mk[i][k] = v[i];
        }
        det(&mk) / d
    })
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let out = args
        .get(1)
        .ok_or("usage: cost_model OUT.svg [SIZES] [BILLBOARDS] [STEPS]")?;
    let list = |i: usize, default: &str| -> Result<Vec<u64>, std::num::ParseIntError> {
        args.get(i)
            .map_or(default, String::as_str)
            .split(',')
            .map(str::parse)
            .collect()
    };
    let sizes = list(2, "200,400,800,1600")?;
    let counts = list(3, "10000,30000,100000,300000")?;
    let steps: usize = args.get(4).map(|s| s.parse()).transpose()?.unwrap_or(3).max(1);
    println!("| pixels | billboards | step s | ns / pixel | ns / billboard |");
    println!("|---|--:|--:|--:|--:|");
    let mut rows = Vec::new();
    for &n in &counts {
        for &size in &sizes {
            let t = step_seconds(size as u32, n as usize, steps);
            let pixels = (size * size) as f64;
            println!(
                "| {size}² | {n} | {t:.3} | {:.0} | {:.0} |",
                t * 1e9 / pixels,
                t * 1e9 / n as f64
            );
            rows.push((pixels, n as f64, t));
        }
    }
    let [a, b, c] = fit(&rows);
    let worst = rows
        .iter()
        .map(|&(x, y, t)| ((a * x + b * y + c) / t - 1.0).abs())
        .fold(0.0, f64::max);
    println!(
        "\nfit: t = {:.1} ns · pixels + {:.0} ns · billboards + {:.1} ms; largest relative error {:.0} %",
        a * 1e9,
        b * 1e9,
        c * 1e3,
        100.0 * worst
    );
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (800, 560)).into_drawing_area();
        root.fill(&WHITE)?;
        let (xs, ts): (Vec<f64>, Vec<f64>) = rows.iter().map(|r| (r.0 / 1e6, r.2)).unzip();
        let (x_lo, x_hi) = (
            xs.iter().copied().fold(f64::MAX, f64::min),
            xs.iter().copied().fold(0.0, f64::max),
        );
        let (t_lo, t_hi) = (
            ts.iter().copied().fold(f64::MAX, f64::min),
            ts.iter().copied().fold(0.0, f64::max),
        );
        let mut chart = ChartBuilder::on(&root)
            .caption(
                "training step time (2 cores, trained-like object scenes)",
                ("sans-serif", 20),
            )
            .margin(12)
            .x_label_area_size(45)
            .y_label_area_size(60)
            .build_cartesian_2d(
                (x_lo * 0.8..x_hi * 1.25).log_scale(),
                (t_lo * 0.8..t_hi * 1.25).log_scale(),
            )?;
        chart
            .configure_mesh()
            .light_line_style(WHITE)
            .x_label_formatter(&|v| format!("{v:.2}"))
            .y_label_formatter(&|v| format!("{v:.2}"))
            .x_desc("image size (megapixels)")
            .y_desc("seconds per step")
            .draw()?;
        for (k, &n) in counts.iter().enumerate() {
            let colour = Palette99::pick(k).to_rgba();
            let line: Vec<(f64, f64)> = rows
                .iter()
                .filter(|r| r.1 == n as f64)
                .map(|r| (r.0 / 1e6, r.2))
                .collect();
            chart
                .draw_series(LineSeries::new(line.iter().copied(), colour.stroke_width(2)))?
                .label(format!("{n} billboards"))
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], colour.stroke_width(2)));
            chart.draw_series(line.iter().map(|&p| Circle::new(p, 4, colour.filled())))?;
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperLeft)
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()?;
        root.present()?;
    }
    std::fs::write(out, svg)?;
    println!("wrote {out}");
    Ok(())
}
