//! A sweep on a real single-node Slurm cluster (`tools/slurm_single_node.sh`, started here;
//! `.ci/run` installs it): `examples/sweep --slurm` writes an array job and a collect job, both
//! run under Slurm; one task is requeued while it trains and resumes from its checkpoint; every
//! setting's model is bit for bit the model of the same setting run locally, and the collect job
//! writes the sweep's table.
//!
//! Needs root (the daemons) and `sbatch`: skipped with "SKIPPED" otherwise, failing instead when
//! `BBSPLAT_REQUIRE_TOOLS` is set.

use crate::cli::{export_demo, temp};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

/// How long the jobs may take in all (measured: about 20 s, with the requeue).
const DEADLINE: Duration = Duration::from_secs(300);

/// The cluster's `SLURM_CONF`, after starting it; `None` (said as SKIPPED) without root.
fn cluster(test: &str) -> Option<String> {
    let root = Command::new("id").arg("-u").output().is_ok_and(|o| o.stdout == b"0\n");
    if !root {
        assert!(
            std::env::var_os("BBSPLAT_REQUIRE_TOOLS").is_none(),
            "{test}: the single-node cluster needs root (BBSPLAT_REQUIRE_TOOLS is set)"
        );
        let _ = writeln!(std::io::stderr(), "SKIPPED {test}: the single-node cluster needs root");
        return None;
    }
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tools/slurm_single_node.sh");
    let out = Command::new(&script).output().expect("the cluster script runs");
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    if !out.status.success() {
        assert!(
            std::env::var_os("BBSPLAT_REQUIRE_TOOLS").is_none(),
            "{test}: the cluster did not start: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        let _ = writeln!(
            std::io::stderr(),
            "SKIPPED {test}: no Slurm: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        return None;
    }
    let conf = text
        .trim()
        .strip_prefix("export SLURM_CONF=")
        .expect("the script prints SLURM_CONF");
    Some(conf.to_string())
}

/// `program args` with `SLURM_CONF`, which must succeed; its standard output.
fn slurm(conf: &str, program: &str, args: &[&str]) -> String {
    let out = Command::new(program)
        .args(args)
        .env("SLURM_CONF", conf)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{program} {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// Waits (bounded by [`DEADLINE`] from `start`) until `done` holds.
fn wait_until(start: Instant, what: &str, mut done: impl FnMut() -> bool) {
    while !done() {
        assert!(start.elapsed() < DEADLINE, "{what} after {:?}", start.elapsed());
        std::thread::sleep(Duration::from_millis(200));
    }
}

/// Submits the jobs of `submit` (a `submit.sh` printing the ids of the jobs it submits, in
/// order: an array job and its collect job, or a chain of them), requeues task 1 of the array job
/// whose id is printed `array_at`-th once `ready` holds, lets it start again at once, and waits
/// until the last job has ended; returns when the jobs were submitted.
fn submit_requeuing_task_1(
    conf: &str,
    submit: &Path,
    array_at: usize,
    not_ready: &str,
    ready: impl FnMut() -> bool,
) -> Instant {
    let start = Instant::now();
    let submitted = slurm(conf, "sh", &[submit.to_str().unwrap()]);
    let ids: Vec<&str> = submitted
        .trim()
        .split([' ', ',', '\n'])
        .filter(|w| w.chars().all(|c| c.is_ascii_digit()) && !w.is_empty())
        .collect();
    assert!(ids.len() > array_at + 1, "job ids in {submitted:?}");
    let (array, collect) = (ids[array_at], ids[ids.len() - 1]);
    wait_until(start, not_ready, ready);
    let task = format!("{array}_1");
    slurm(conf, "scontrol", &["requeue", &task]);
    // A requeued job is held back before it may start again (its begin time is set about two
    // minutes ahead): once it is pending, let it start now.
    wait_until(start, "task 1 was not pending again", || {
        slurm(conf, "squeue", &["-h", "-j", &task, "-o", "%T"]).trim() == "PENDING"
    });
    slurm(conf, "scontrol", &["update", &format!("JobId={task}"), "StartTime=now"]);
    wait_until(start, "the last job did not end", || {
        slurm(conf, "squeue", &["-h", "-j", collect]).trim().is_empty()
    });
    start
}

/// The model files of a run folder's model ([`crate::cli_blocks::model_files`]).
fn model_bytes(run: &Path) -> Vec<(String, Vec<u8>)> {
    crate::cli_blocks::model_files(&run.join("model"))
}

#[test]
#[ignore = "slow tier (CI runs it): cargo test --test suite -- --ignored --skip ::measure"]
fn a_sweep_runs_as_slurm_jobs_and_a_requeued_task_resumes_to_the_local_result() {
    let test = "a_sweep_runs_as_slurm_jobs";
    let Some(conf) = cluster(test) else { return };
    let root = temp("slurm-sweep");
    let data = export_demo(&root, 24, 100);
    let bbsplat = PathBuf::from(env!("CARGO_BIN_EXE_bbsplat"));
    let sweep = bbsplat.parent().unwrap().join("examples").join("sweep");
    assert!(
        sweep.is_file(),
        "cargo test builds the sweep example: {}",
        sweep.display()
    );
    let train_args = ["--texture-size", "4", "--eval-every", "0", "--save-every", "20"];
    let sweep_args = |out: &Path, extra: &[&str]| {
        let mut a: Vec<String> = [
            data.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--exe",
            bbsplat.to_str().unwrap(),
        ]
        .iter()
        .map(|s| s.to_string())
        .collect();
        a.extend(["--billboards", "60,120", "--iterations", "300"].map(String::from));
        a.extend(extra.iter().map(|s| s.to_string()));
        a.push("--".into());
        a.extend(train_args.map(String::from));
        a
    };
    // The local sweep.
    let local = root.join("local");
    let ok = Command::new(&sweep).args(sweep_args(&local, &[])).output().unwrap();
    assert!(ok.status.success(), "{}", String::from_utf8_lossy(&ok.stderr));
    // The same sweep as Slurm jobs.
    let remote = root.join("slurm");
    let ok = Command::new(&sweep)
        .args(sweep_args(&remote, &["--slurm", "--cpus-per-task", "1"]))
        .output()
        .unwrap();
    assert!(ok.status.success(), "{}", String::from_utf8_lossy(&ok.stderr));
    // Requeue task 1 once it has saved a checkpoint (it trains 300 steps, saving every 20).
    let run1 = remote.join("runs/it300_bb120");
    let start = submit_requeuing_task_1(
        &conf,
        &remote.join("slurm/submit.sh"),
        0,
        "no checkpoint of task 1",
        || run1.join("checkpoint.bin").is_file(),
    );
    let log = std::fs::read_to_string(run1.join("train.log")).unwrap();
    println!("{log}");
    assert!(
        log.contains("interrupted at step") && log.contains("resuming at step"),
        "task 1 was not interrupted and resumed: {log}"
    );
    for slug in ["it300_bb60", "it300_bb120"] {
        let (a, b) = (
            model_bytes(&local.join("runs").join(slug)),
            model_bytes(&remote.join("runs").join(slug)),
        );
        assert!(
            a.len() >= 2 && a == b,
            "{slug}: the Slurm model differs from the local one"
        );
    }
    let table = std::fs::read_to_string(remote.join("sweep.md")).expect("the collect job wrote the table");
    assert!(table.contains("it300_bb60") && table.contains("it300_bb120"), "{table}");
    println!("jobs done in {:?}", start.elapsed());
    std::fs::remove_dir_all(&root).ok();
}

/// Every argument of a task survives the shell: `shell_quote`d words read back by `sh` are the
/// words (spaces, quotes, `$`, backslashes, empty, non-ASCII).
#[test]
fn shell_quoted_words_read_back_unchanged() {
    use bbsplat::sweep::shell_quote;
    let words = [
        "plain",
        "with space",
        "it's",
        "$HOME",
        "a\\b",
        "",
        "naïve",
        "--x=1,2",
        "*",
    ];
    let script = format!(
        "for w in {}; do printf '%s\\n' \"$w\"; done",
        words.iter().map(|w| shell_quote(w)).collect::<Vec<_>>().join(" ")
    );
    let out = Command::new("sh").args(["-c", &script]).output().unwrap();
    let back: Vec<&str> = std::str::from_utf8(&out.stdout).unwrap().lines().collect();
    assert_eq!(back, words);
}

/// `bbsplat benchmark --slurm`: the scenes' runs as an array job, the table as its collect job;
/// task 1 is requeued while it trains (Slurm's SIGTERM makes it save a checkpoint) and resumes;
/// both models are bit for bit those of the same benchmark run locally.
#[test]
#[ignore = "slow tier (CI runs it): cargo test --test suite -- --ignored --skip ::measure"]
fn a_benchmark_runs_as_slurm_jobs_and_a_requeued_scene_resumes_to_the_local_result() {
    let test = "a_benchmark_runs_as_slurm_jobs";
    let Some(conf) = cluster(test) else { return };
    let root = temp("slurm-benchmark");
    let bbsplat = env!("CARGO_BIN_EXE_bbsplat");
    let scenes: Vec<PathBuf> = [("small", "16"), ("large", "48")]
        .iter()
        .map(|(name, resolution)| {
            let dir = root.join(name);
            crate::cli::run_ok(&["demo", "--export", dir.to_str().unwrap(), "--resolution", resolution]);
            dir
        })
        .collect();
    let benchmark = |out: &Path, extra: &[&str]| {
        let mut args: Vec<&str> = vec!["benchmark"];
        args.extend(scenes.iter().map(|s| s.to_str().unwrap()));
        args.extend(["-o", out.to_str().unwrap(), "--iterations", "400"]);
        args.extend_from_slice(extra);
        let out = Command::new(bbsplat).args(&args).output().unwrap();
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        String::from_utf8_lossy(&out.stdout).into_owned()
    };
    let local = root.join("local");
    benchmark(&local, &[]);
    let remote = root.join("slurm");
    let printed = benchmark(&remote, &["--slurm", "--cpus-per-task", "1"]);
    assert!(printed.contains("2 scenes; submit with"), "{printed}");
    assert!(
        !remote.join("benchmark.md").exists(),
        "--slurm trained instead of writing jobs"
    );
    // Requeue task 1 once it trains (the line printed as training starts, after the signals
    // are armed); Slurm's SIGTERM stops it with a checkpoint, and the requeued task resumes.
    let log1 = remote.join("large").join("train.log");
    let start = submit_requeuing_task_1(
        &conf,
        &remote.join("slurm/submit.sh"),
        0,
        "task 1 did not start training",
        || std::fs::read_to_string(&log1).is_ok_and(|l| l.contains("test views at")),
    );
    let log = std::fs::read_to_string(&log1).unwrap();
    assert!(
        log.contains("interrupted at step") && log.contains("resuming at step"),
        "task 1 was not interrupted and resumed: {log}"
    );
    for name in ["small", "large"] {
        let (a, b) = (model_bytes(&local.join(name)), model_bytes(&remote.join(name)));
        assert!(
            a.len() >= 2 && a == b,
            "{name}: the Slurm model differs from the local one"
        );
    }
    let table = std::fs::read_to_string(remote.join("benchmark.md")).expect("the collect job wrote the table");
    assert!(
        table.contains("| small |") && table.contains("| large |") && table.contains("--iterations 400"),
        "{table}"
    );
    assert!(!table.contains("failed"), "{table}");
    println!("jobs done in {:?}", start.elapsed());
    std::fs::remove_dir_all(&root).ok();
}

/// `bbsplat blocks run --slurm`: the block-wise chain as six jobs chained by `afterok` (coarse
/// run, split, the blocks' array, merge, polish, report); every model is bit for bit that of the
/// same chain run locally. (A requeued task resuming is the same array script's as the sweep's
/// and the benchmark's, tested above; requeueing a task of this chain's dependent array once
/// left it never started again under the test's load, not understood yet: docs/cluster.md.)
#[test]
#[ignore = "slow tier (CI runs it): cargo test --test suite -- --ignored --skip ::measure"]
fn a_block_chain_runs_as_chained_slurm_jobs_to_the_local_result() {
    let test = "a_block_chain_runs_as_chained_slurm_jobs";
    let Some(conf) = cluster(test) else { return };
    let root = temp("slurm-blocks");
    let data = root.join("street");
    crate::cli::run_ok(&[
        "demo",
        "--export",
        data.to_str().unwrap(),
        "--street",
        "6",
        "--resolution",
        "32",
    ]);
    let chain = |out: &Path, extra: &[&str]| {
        let mut args = vec!["blocks", "run", data.to_str().unwrap(), "-o", out.to_str().unwrap()];
        args.extend([
            "--coarse-iterations",
            "200",
            "--block-iterations",
            "300",
            "--polish-iterations",
            "100",
        ]);
        args.extend_from_slice(extra);
        crate::cli::run_ok(&args)
    };
    let local = root.join("local");
    chain(&local, &[]);
    let remote = root.join("slurm");
    chain(&remote, &["--slurm", "--cpus-per-task", "1"]);
    let start = Instant::now();
    let submitted = slurm(&conf, "sh", &[remote.join("slurm/submit.sh").to_str().unwrap()]);
    let last = submitted
        .split([' ', ',', '\n'])
        .rfind(|w| !w.is_empty() && w.chars().all(|c| c.is_ascii_digit()))
        .unwrap_or_else(|| panic!("job ids in {submitted:?}"))
        .to_string();
    assert_eq!(submitted.lines().count(), 3, "{submitted}");
    wait_until(start, "the report job did not end", || {
        slurm(&conf, "squeue", &["-h", "-j", &last]).trim().is_empty()
    });
    for run in ["coarse", "blocks/block_0/run", "blocks/block_1/run", "polish"] {
        let (a, b) = (model_bytes(&local.join(run)), model_bytes(&remote.join(run)));
        assert!(
            a.len() >= 2 && a == b,
            "{run}: the Slurm model differs from the local one"
        );
    }
    assert!(
        remote.join("report.json").is_file(),
        "the report job did not write the report"
    );
    println!("jobs done in {:?}", start.elapsed());
    std::fs::remove_dir_all(&root).ok();
}
