//! The command line refuses bad arguments with a clear message and a non-zero exit status.

use std::process::Command;

fn run(args: &[&str]) -> (bool, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_bbsplat"))
        .args(args)
        .output()
        .expect("the binary runs");
    (out.status.success(), String::from_utf8_lossy(&out.stderr).into_owned())
}

#[test]
fn demo_rejects_a_texture_smaller_than_two() {
    let (ok, err) = run(&["demo", "--texture-size", "1", "--iterations", "1"]);
    assert!(!ok);
    assert!(err.contains("--texture-size must be at least 2"), "{err}");
}

#[test]
fn demo_rejects_a_tiny_resolution() {
    let (ok, err) = run(&["demo", "--resolution", "4", "--iterations", "1"]);
    assert!(!ok);
    assert!(err.contains("--resolution must be at least 8"), "{err}");
}

#[test]
fn unknown_subcommand_is_refused() {
    let (ok, err) = run(&["bogus"]);
    assert!(!ok);
    assert!(err.contains("unrecognized subcommand"), "{err}");
}

#[test]
fn tiny_demo_runs_and_writes_renders() {
    let dir = std::env::temp_dir().join(format!("bbsplat-cli-{}", std::process::id()));
    let args = [
        "demo",
        "--iterations",
        "5",
        "--billboards",
        "50",
        "--resolution",
        "16",
        "-o",
        dir.to_str().unwrap(),
    ];
    let (ok, err) = run(&args);
    assert!(ok, "{err}");
    let pngs = std::fs::read_dir(&dir)
        .unwrap()
        .filter(|e| e.as_ref().unwrap().path().extension().is_some_and(|x| x == "png"))
        .count();
    assert_eq!(pngs, 16, "8 test views, render and truth each");
    assert!(
        std::fs::read_dir(&dir)
            .unwrap()
            .all(|e| !e.unwrap().path().to_string_lossy().ends_with(".tmp"))
    );
    std::fs::remove_dir_all(&dir).ok();
}

fn temp(tag: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("bbsplat-cli-{tag}-{}", std::process::id()));
    std::fs::remove_dir_all(&dir).ok();
    dir
}

fn run_ok(args: &[&str]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_bbsplat"))
        .args(args)
        .output()
        .expect("the binary runs");
    assert!(
        out.status.success(),
        "{args:?} failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// The whole command-line workflow on a tiny exported demo scene: export, train, render, eval.
#[test]
fn train_render_and_eval_run_on_a_tiny_scene() {
    let root = temp("workflow");
    let data = root.join("data");
    let out = root.join("out");
    run_ok(&[
        "demo",
        "--export",
        data.to_str().unwrap(),
        "--resolution",
        "24",
        "--billboards",
        "100",
    ]);
    assert!(data.join("sparse/0/cameras.bin").exists());
    let printed = run_ok(&[
        "train",
        data.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--iterations",
        "20",
        "--billboards",
        "150",
        "--texture-size",
        "4",
        "--eval-every",
        "10",
        "--quiet",
    ]);
    assert!(printed.contains("test PSNR"), "{printed}");
    let summary: bbsplat::report::TrainSummary =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!((summary.iterations, summary.texture_size), (20, 4));
    assert_eq!(summary.curve.len(), 2, "one intermediate and one final evaluation");
    assert!(summary.test_psnr.is_finite() && summary.model_bytes > 0);
    let model = out.join("model");
    assert!(model.join("point_cloud.ply").exists());

    let renders = root.join("renders");
    let printed = run_ok(&[
        "render",
        model.to_str().unwrap(),
        data.to_str().unwrap(),
        "-o",
        renders.to_str().unwrap(),
    ]);
    assert!(printed.contains("wrote 5 renders"), "{printed}");
    assert_eq!(std::fs::read_dir(&renders).unwrap().count(), 5);

    let table = run_ok(&["eval", model.to_str().unwrap(), data.to_str().unwrap()]);
    assert_eq!(table.lines().count(), 7, "header, 5 views, mean:\n{table}");
    let json = run_ok(&["eval", model.to_str().unwrap(), data.to_str().unwrap(), "--json"]);
    let report: bbsplat::eval::EvalReport = serde_json::from_str(&json).unwrap();
    assert_eq!(report.views.len(), 5);
    // The evaluation of the saved (8-bit) model is what train reported at the end.
    assert!(
        (report.mean_psnr - summary.test_psnr).abs() < 1e-9,
        "{} {}",
        report.mean_psnr,
        summary.test_psnr
    );
    std::fs::remove_dir_all(&root).ok();
}

#[test]
fn train_names_a_missing_scene_folder() {
    let (ok, err) = run(&["train", "/no/such/scene", "-o", "/tmp/never-written"]);
    assert!(!ok);
    assert!(err.contains("/no/such/scene"), "{err}");
    assert!(!std::path::Path::new("/tmp/never-written").exists());
}

#[test]
fn eval_names_an_unreadable_model() {
    let root = temp("badmodel");
    let data = root.join("data");
    run_ok(&[
        "demo",
        "--export",
        data.to_str().unwrap(),
        "--resolution",
        "16",
        "--billboards",
        "20",
    ]);
    let model = root.join("model");
    std::fs::create_dir_all(&model).unwrap();
    std::fs::write(model.join("point_cloud.ply"), b"ply\nformat garbage\n").unwrap();
    let (ok, err) = run(&["eval", model.to_str().unwrap(), data.to_str().unwrap()]);
    assert!(!ok);
    assert!(err.contains("point_cloud.ply") || err.contains("bbsplat.json"), "{err}");
    std::fs::remove_dir_all(&root).ok();
}
