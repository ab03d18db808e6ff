//! The trained-like benchmark scenes match the statistics of trained states within 20 %
//! (`bbsplat::billboards::trained_like`; the measured states and commands are in
//! `docs/benchmarks.md`).

use bbsplat::billboards::{TrainedLikeConfig, random_scene_camera, trained_like_scene};
use bbsplat::raster::{RenderSettings, WorkloadStats, render};

/// Workload of a trained state at 400×400 with about 10 000 billboards, as `WorkloadStats`
/// measures it (`docs/benchmarks.md` gives the commands and the full rows).
struct Target {
    evaluated_per_pixel: f64,
    blended_per_pixel: f64,
    covered_fraction: f64,
    blended_covered_p50_p90: [f64; 2],
    /// Screen sizes, compared for the 10 000-billboard scenes only (a 30 000-billboard scene has
    /// billboards √3 times smaller by design, the same work per pixel).
    screen_px_p10_p50_p90: [f64; 3],
    alpha_bins: [f64; 5],
}

/// lego (NeRF-synthetic) after 2000 steps (`--iterations 2000 --lr-scale 4 --init hull
/// --coarse-factor 2 --coarse-until 0.5 --background white`), 8 test views at 400×400.
const LEGO: Target = Target {
    evaluated_per_pixel: 15.7,
    blended_per_pixel: 11.1,
    covered_fraction: 0.33,
    blended_covered_p50_p90: [30.0, 58.0],
    screen_px_p10_p50_p90: [3.5, 16.0, 35.6],
    alpha_bins: [0.60, 0.30, 0.10, 0.00, 0.00],
};

/// beer_colmap after 1500 steps (`--lr-scale 4`), 4 test views at 220×391 with 3799 of 4414
/// billboards visible: per-pixel figures as measured; screen sizes scaled to 400² and 10 000
/// billboards, × √(400² / (220·391)) · √(3799 / 10 000) = 0.84 (the same screen area per
/// billboard relative to the image).
const BEER: Target = Target {
    evaluated_per_pixel: 27.1,
    blended_per_pixel: 19.8,
    covered_fraction: 1.0,
    blended_covered_p50_p90: [18.0, 31.0],
    screen_px_p10_p50_p90: [1.35, 5.72, 24.5],
    alpha_bins: [0.58, 0.33, 0.08, 0.00, 0.00],
};

/// The statistics of `stats` that are not within 20 % of `target` (alpha bins holding under 5 %
/// of the texels: within 0.02 absolute; screen sizes only when `compare_sizes`).
fn mismatches(stats: &WorkloadStats, target: &Target, compare_sizes: bool) -> Vec<String> {
    let mut out = Vec::new();
    // Within 20 % of `want`, or within 0.02 for alpha bins under 5 % (`absolute`).
    let mut check_with = |name: &str, got: f64, want: f64, absolute: bool| {
        let tolerance = if absolute { 0.02 } else { 0.2 * want.abs() };
        let within = (got - want).abs() <= tolerance; // false for NaN
        if !within {
            out.push(format!("{name}: {got:.3} vs {want:.3}"));
        }
    };
    let mut check = |name: &str, got: f64, want: f64| check_with(name, got, want, false);
    check("evaluated / px", stats.evaluated_per_pixel, target.evaluated_per_pixel);
    check("blended / px", stats.blended_per_pixel, target.blended_per_pixel);
    check("covered", stats.covered_fraction, target.covered_fraction);
    for (i, q) in ["p50", "p90"].iter().enumerate() {
        let got = f64::from(stats.blended_covered_p50_p90[i]);
        check(
            &format!("blended per covered px {q}"),
            got,
            target.blended_covered_p50_p90[i],
        );
    }
    if compare_sizes {
        for (i, q) in ["p10", "p50", "p90"].iter().enumerate() {
            let got = f64::from(stats.screen_px_p10_p50_p90[i]);
            check(&format!("screen px {q}"), got, target.screen_px_p10_p50_p90[i]);
        }
    }
    for (i, (&got, &want)) in stats.alpha_bins.iter().zip(&target.alpha_bins).enumerate() {
        check_with(&format!("alpha bin {i}"), got, want, want < 0.05);
    }
    out
}

fn stats_of(config: &TrainedLikeConfig) -> WorkloadStats {
    let scene = trained_like_scene(config);
    let set = scene.borrowed();
    let camera = random_scene_camera(config.width, config.height);
    WorkloadStats::of(&set, &render(&set, &camera, &RenderSettings::default()))
}

#[test]
fn object_scenes_match_a_trained_lego_state() {
    let ten = stats_of(&TrainedLikeConfig::object(10_000, 400, 400));
    eprintln!("{}", ten.table_row("object 400²/10000"));
    let failures = mismatches(&ten, &LEGO, true);
    assert!(failures.is_empty(), "object 400²/10000: {failures:?}");
    // At 30 000 billboards the depth per covered pixel concentrates: its median is 43 against
    // 30 (measured; docs/benchmarks.md), the one statistic outside 20 %, exempted here by name.
    let thirty = stats_of(&TrainedLikeConfig::object(30_000, 400, 400));
    eprintln!("{}", thirty.table_row("object 400²/30000"));
    let failures = mismatches(&thirty, &LEGO, false);
    assert_eq!(
        failures
            .iter()
            .map(|f| f.split(':').next().unwrap_or(""))
            .collect::<Vec<_>>(),
        ["blended per covered px p50"],
        "object 400²/30000: {failures:?}"
    );
}

#[test]
fn capture_scenes_match_a_trained_beer_colmap_state() {
    for n in [10_000, 30_000] {
        let stats = stats_of(&TrainedLikeConfig::capture(n, 400, 400));
        eprintln!("{}", stats.table_row(&format!("capture 400²/{n}")));
        let failures = mismatches(&stats, &BEER, n == 10_000);
        assert!(failures.is_empty(), "capture 400²/{n}: {failures:?}");
    }
}

#[test]
fn the_random_benchmark_scene_does_not_match() {
    // The check can fail: the random scene of issue 3 (0.7 blended pairs per pixel) is far
    // from a trained state.
    let config = bbsplat::billboards::RandomSceneConfig::benchmark(10_000, 400, 400);
    let scene = bbsplat::billboards::random_scene(&config);
    let set = scene.borrowed();
    let camera = random_scene_camera(400, 400);
    let stats = WorkloadStats::of(&set, &render(&set, &camera, &RenderSettings::default()));
    let failures = mismatches(&stats, &LEGO, true);
    assert!(failures.len() >= 5, "{failures:?}");
}
