//! `bbsplat train`'s pre-flight memory estimate (`train::footprint`) against the peak the run
//! really reaches (`VmHWM`, recorded side by side in `summary.json`).

use super::cli::{export_demo, run_ok, temp};

/// The estimate over the measured peak must lie in this range. Measured on release builds
/// (docs/training.md, "Memory"): 1.00-1.20 from 200 to 1600 px, 10 000 to 300 000 billboards of
/// TS 16 and 58 to 808 views; this run (the test build): 1.15 (with the constants before
/// 2026-12-03, 40 B a billboard float, it was 1.34: the range catches them).
const RATIO_RANGE: (f64, f64) = (0.8, 1.25);

#[test]
fn the_memory_estimate_is_within_a_quarter_of_the_peak() {
    let root = temp("memory");
    let data = export_demo(&root, 96, 20_000);
    let out = root.join("run");
    run_ok(&[
        "train",
        data.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--billboards",
        "20000",
        "--texture-size",
        "8",
        "--growth-cap",
        "0",
        "--iterations",
        "2",
        "--eval-every",
        "0",
        "--quiet",
    ]);
    let summary: serde_json::Value = serde_json::from_slice(&std::fs::read(out.join("summary.json")).unwrap()).unwrap();
    let estimate = summary["estimated_peak_bytes"]
        .as_f64()
        .expect("an estimate in the summary");
    let peak = summary["peak_rss_bytes"].as_f64().unwrap();
    let ratio = estimate / peak;
    eprintln!(
        "memory estimate {:.0} MB, peak {:.0} MB: {ratio:.2}",
        estimate / 1e6,
        peak / 1e6
    );
    assert!(
        (RATIO_RANGE.0..=RATIO_RANGE.1).contains(&ratio),
        "estimate {estimate} bytes against a peak of {peak}: {ratio:.2}"
    );
    std::fs::remove_dir_all(&root).ok();
}
