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
