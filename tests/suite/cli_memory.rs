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

/// `--image-memory` below the scene's images: `train` says they are decoded on demand, and the
/// run (coarse-to-fine, growth, evaluations: every default) writes the same model and checkpoint
/// bytes as the run with its images in memory.
#[test]
fn images_decoded_on_demand_train_the_same_model() {
    let root = temp("on-demand");
    // 40 views of 48² (6.9 kB each): 276 kB of images against a 64 kB budget.
    let data = export_demo(&root, 48, 400);
    let train = |out: &std::path::Path, extra: &[&str]| {
        let mut args = vec![
            "train",
            data.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
            "--iterations",
            "40",
        ];
        args.extend(extra);
        run_ok(&args)
    };
    let (memory, lazy) = (root.join("memory"), root.join("lazy"));
    let said_memory = train(&memory, &[]);
    let said_lazy = train(&lazy, &["--image-memory", "64K"]);
    assert!(!said_memory.contains("decoded from its file"), "{said_memory}");
    assert!(
        said_lazy.contains("do not fit in --image-memory 65.5 kB: each is decoded from its file when used"),
        "{said_lazy}"
    );
    for file in [
        "checkpoint.bin",
        "model/point_cloud.ply",
        "model/texture_alpha.npz",
        "model/texture_color.npz",
    ] {
        assert!(
            std::fs::read(memory.join(file)).unwrap() == std::fs::read(lazy.join(file)).unwrap(),
            "{file} differs"
        );
    }
    std::fs::remove_dir_all(&root).ok();
}
