//! `bbsplat benchmark`: two tiny demo scenes and a missing one, the tables read back against the
//! runs' summaries, a rerun that trains nothing.

use super::cli::{export_demo, temp};
use std::process::Command;

fn summary(path: &std::path::Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

#[test]
fn benchmark_tables_hold_each_run_and_a_rerun_trains_nothing() {
    let root = temp("benchmark");
    let small = export_demo(&root.join("small"), 24, 100);
    let large = export_demo(&root.join("large"), 32, 120);
    // Distinct row names: the last path component.
    let (scene_a, scene_b) = (root.join("scene_a"), root.join("dtu_scan65"));
    std::fs::rename(&small, &scene_a).unwrap();
    std::fs::rename(&large, &scene_b).unwrap();
    let missing = root.join("no_such_scene");
    let out = root.join("bench");
    let args = |extra: &[&str]| {
        let mut a = vec![
            "benchmark".to_string(),
            scene_a.display().to_string(),
            missing.display().to_string(),
            scene_b.display().to_string(),
            "-o".into(),
            out.display().to_string(),
            "--minutes".into(),
            "0.02".into(),
            "--curve".into(),
        ];
        a.extend(extra.iter().map(|s| s.to_string()));
        a
    };
    let first = Command::new(env!("CARGO_BIN_EXE_bbsplat"))
        .args(args(&[]))
        .output()
        .unwrap();
    let (stdout, stderr) = (
        String::from_utf8_lossy(&first.stdout).into_owned(),
        String::from_utf8_lossy(&first.stderr).into_owned(),
    );
    // The missing scene fails the command, named, after the others ran.
    assert!(!first.status.success(), "{stdout}\n{stderr}");
    assert!(stderr.contains("1 of 3 scenes failed: no_such_scene"), "{stderr}");
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("benchmark.json")).unwrap()).unwrap();
    let md = std::fs::read_to_string(out.join("benchmark.md")).unwrap();
    let rows = json["rows"].as_array().unwrap();
    assert_eq!(rows.len(), 3);
    assert_eq!(json["minutes"], 0.02);
    let failed = &rows[1];
    assert_eq!(failed["name"], "no_such_scene");
    let error = failed["error"].as_str().unwrap();
    assert!(error.contains(&missing.display().to_string()), "{error}");
    assert!(md.contains("| no_such_scene | failed |"), "{md}");
    assert!(
        md.contains(&format!("no_such_scene ({}) failed:", missing.display())),
        "{md}"
    );
    for (row, name) in [(&rows[0], "scene_a"), (&rows[2], "dtu_scan65")] {
        assert_eq!(row["name"], name);
        assert!(row["error"].is_null(), "{row}");
        let s = summary(&out.join(name).join("summary.json"));
        for (ours, theirs) in [
            ("psnr", "test_psnr"),
            ("ssim", "test_ssim"),
            ("train_seconds", "train_seconds"),
            ("iterations", "iterations"),
            ("billboards", "billboards"),
            ("peak_rss_bytes", "peak_rss_bytes"),
            ("test_views", "test_views"),
        ] {
            assert_eq!(row[ours], s[theirs], "{name} {ours}");
        }
        assert!(s["iterations"].as_u64().unwrap() > 0 && s["peak_rss_bytes"].as_u64().unwrap() > 0);
        assert_eq!(s["plan"]["budget_minutes"], 0.02, "trained with the benchmark's budget");
        assert_eq!(row["budget_minutes"], 0.02);
        assert_eq!(
            row["curve"].as_array().unwrap().len(),
            s["curve"].as_array().unwrap().len()
        );
        // The markdown row holds the same figures, rounded as printed.
        let line = md
            .lines()
            .find(|l| l.starts_with(&format!("| {name} |")))
            .unwrap_or_else(|| panic!("{md}"));
        let psnr = format!("| {:.2} |", s["test_psnr"].as_f64().unwrap());
        let steps = format!("| {} |", s["iterations"]);
        let billboards = format!("| {} |", s["billboards"]);
        assert!(
            line.contains(&psnr) && line.contains(&steps) && line.contains(&billboards),
            "{line}"
        );
    }
    // The paper's row beside the scene it has, "not in Table 9" beside the other.
    assert_eq!(rows[2]["paper"]["psnr"], 29.67);
    assert!(rows[0]["paper"].is_null());
    assert!(
        md.lines()
            .any(|l| l.starts_with("| scene_a |") && l.ends_with("not in Table 9 |")),
        "{md}"
    );
    assert!(md.contains("29.67 / 0.8754 / 0.2803 (DTU Scan65)"), "{md}");
    let svg = std::fs::read_to_string(out.join("curve.svg")).unwrap();
    assert!(svg.starts_with("<svg") && svg.contains("scene_a") && svg.contains("dtu_scan65"));

    // A rerun (the missing scene left out) trains nothing and gives the same rows.
    let summary_before = std::fs::read(out.join("scene_a/summary.json")).unwrap();
    let again = Command::new(env!("CARGO_BIN_EXE_bbsplat"))
        .args(args(&[]).into_iter().filter(|a| *a != missing.display().to_string()))
        .output()
        .unwrap();
    let printed = String::from_utf8_lossy(&again.stdout);
    assert!(again.status.success(), "{}", String::from_utf8_lossy(&again.stderr));
    assert!(printed.contains("scene_a: finished earlier") && printed.contains("dtu_scan65: finished earlier"));
    assert!(!printed.contains("training "), "{printed}");
    assert_eq!(std::fs::read(out.join("scene_a/summary.json")).unwrap(), summary_before);
    let json_again: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("benchmark.json")).unwrap()).unwrap();
    assert_eq!(json_again["rows"][0], rows[0]);
    assert_eq!(json_again["rows"][1], rows[2]);

    // Another budget over the same folder is not mixed into the table.
    let other = Command::new(env!("CARGO_BIN_EXE_bbsplat"))
        .args([
            "benchmark",
            scene_a.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
            "--minutes",
            "0.05",
        ])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&other.stderr);
    assert!(!other.status.success());
    let md = std::fs::read_to_string(out.join("benchmark.md")).unwrap();
    assert!(
        md.contains("holds a --minutes 0.02 run, not --minutes 0.05"),
        "{md}\n{stderr}"
    );
    std::fs::remove_dir_all(&root).ok();
}

/// Two scenes with the same folder name would share a run folder: refused before any training.
#[test]
fn benchmark_refuses_two_scenes_of_one_name() {
    let root = temp("benchmark_names");
    let out = Command::new(env!("CARGO_BIN_EXE_bbsplat"))
        .args(["benchmark", "a/lego", "b/lego", "-o"])
        .arg(root.join("bench"))
        .args(["--minutes", "1"])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && stderr.contains("two scenes are named lego"),
        "{stderr}"
    );
    assert!(!root.join("bench").exists(), "nothing written");
}

#[test]
fn benchmark_slurm_refuses_a_missing_scene_before_writing_jobs() {
    let root = temp("benchmark_slurm_missing");
    let out = Command::new(env!("CARGO_BIN_EXE_bbsplat"))
        .arg("benchmark")
        .arg(root.join("nowhere"))
        .arg("-o")
        .arg(root.join("bench"))
        .args(["--iterations", "10", "--slurm"])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && stderr.contains("nowhere: no such scene"),
        "{stderr}"
    );
    assert!(!root.join("bench").exists(), "nothing written");
    // And --minutes with --iterations is refused by the parser, naming both.
    let out = Command::new(env!("CARGO_BIN_EXE_bbsplat"))
        .args(["benchmark", "a", "-o", "b", "--minutes", "1", "--iterations", "5"])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && stderr.contains("--minutes") && stderr.contains("--iterations"),
        "{stderr}"
    );
}
