//! Issue 60 item 9: `summary.json` after `--resume` reports the time of the whole run (the
//! resumed parts included), resuming a finished run keeps its time, and a checkpoint whose
//! run-time file is missing says so in the summary instead of reporting part of the run as all
//! of it.

use super::cli::{export_demo, run_ok, temp, tiny_train_args};
use bbsplat::train::run_time::{RUN_TIME_FILE, RunTime};
use std::path::Path;
use std::process::Command;

fn summary(out: &Path) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(out.join("summary.json")).unwrap()).unwrap()
}

fn run_time(out: &Path) -> RunTime {
    serde_json::from_slice(&std::fs::read(out.join(RUN_TIME_FILE)).unwrap()).unwrap()
}

#[test]
fn a_resumed_run_reports_the_time_of_the_whole_run() {
    let root = temp("resume-time");
    let data = export_demo(&root, 24, 100);
    let out = root.join("out");
    let (d, o) = (data.to_str().unwrap(), out.to_str().unwrap());
    run_ok(&tiny_train_args(d, o, &["--stop-after", "20"]));
    let first = run_time(&out);
    assert_eq!(first.step, 20);
    assert!(first.train_seconds > 0.0 && first.other_seconds > 0.0, "{first:?}");
    let c = out.join("checkpoint.bin");
    let c = c.to_str().unwrap();
    run_ok(&tiny_train_args(d, o, &["--resume", c]));
    let whole = run_time(&out);
    assert_eq!(whole.step, 40);
    let s = summary(&out);
    let train_seconds = s["train_seconds"].as_f64().unwrap();
    // The summary's time is the whole run's: the first part's and the second's.
    assert!(
        train_seconds > first.train_seconds,
        "summary {train_seconds} s, first part alone {} s",
        first.train_seconds
    );
    assert_eq!(train_seconds, whole.train_seconds);
    assert!(s["other_seconds"].as_f64().unwrap() > first.other_seconds);
    assert!(s["warnings"].as_array().unwrap().is_empty(), "{}", s["warnings"]);
    // Resuming the finished run does no step and keeps the time (it was rewritten to 0).
    run_ok(&tiny_train_args(d, o, &["--resume", c]));
    let again = summary(&out)["train_seconds"].as_f64().unwrap();
    assert_eq!(again, train_seconds);
    std::fs::remove_dir_all(&root).ok();
}

#[test]
fn a_checkpoint_without_its_run_time_is_resumed_with_a_warning_in_the_summary() {
    let root = temp("resume-time-lost");
    let data = export_demo(&root, 24, 100);
    let (a, b) = (root.join("a"), root.join("b"));
    let d = data.to_str().unwrap();
    run_ok(&tiny_train_args(d, a.to_str().unwrap(), &["--stop-after", "20"]));
    // The checkpoint copied alone: its time is not known.
    std::fs::create_dir_all(&b).unwrap();
    std::fs::copy(a.join("checkpoint.bin"), root.join("copied.bin")).unwrap();
    let copied = root.join("copied.bin");
    let output = Command::new(env!("CARGO_BIN_EXE_bbsplat"))
        .args(tiny_train_args(
            d,
            b.to_str().unwrap(),
            &["--resume", copied.to_str().unwrap()],
        ))
        .output()
        .unwrap();
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    let err = String::from_utf8_lossy(&output.stderr);
    assert!(err.contains("the time before step 20 is not counted"), "{err}");
    let warnings = summary(&b)["warnings"].to_string();
    assert!(
        warnings.contains("the time before step 20 is not counted"),
        "{warnings}"
    );
    // A run-time file of another checkpoint (same folder, older step) is not taken either.
    std::fs::copy(a.join("checkpoint.bin"), root.join("copied.bin")).unwrap();
    let mut stale = run_time(&a);
    stale.step = 10;
    std::fs::write(root.join(RUN_TIME_FILE), serde_json::to_string(&stale).unwrap()).unwrap();
    let c = root.join("c");
    let output = Command::new(env!("CARGO_BIN_EXE_bbsplat"))
        .args(tiny_train_args(
            d,
            c.to_str().unwrap(),
            &["--resume", copied.to_str().unwrap()],
        ))
        .output()
        .unwrap();
    assert!(output.status.success());
    let err = String::from_utf8_lossy(&output.stderr);
    assert!(err.contains("belongs to another checkpoint (of step 10)"), "{err}");
    std::fs::remove_dir_all(&root).ok();
}
