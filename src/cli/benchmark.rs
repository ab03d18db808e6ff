//! `bbsplat benchmark SCENE... -o OUT --minutes M`: trains each scene with the defaults into
//! `OUT/<name>` and writes the table of their figures ([`bbsplat::benchmark`]) as
//! `OUT/benchmark.md` and `OUT/benchmark.json`.
//!
//! Each scene runs as its own `bbsplat train SCENE -o OUT/<name> --minutes M` process (this very
//! binary), not in this process: the peak memory a summary records is the process's high-water
//! mark (`VmHWM`), which only a fresh process gives per scene, and a failed or interrupted scene
//! leaves the others and the table untouched. A scene whose `OUT/<name>/summary.json` exists is
//! not trained again; one with only a checkpoint (interrupted) is resumed from it. A scene that
//! fails is marked failed in the table with its error and the others still run; the command
//! then ends with an error naming the failed scenes.

use anyhow::{Context, Result};
use bbsplat::benchmark::{BenchmarkRow, PAPER_SOURCE, markdown_table};
use bbsplat::train::run::{CHECKPOINT_FILE, SUMMARY_FILE};
use clap::Args;
use std::path::{Path, PathBuf};
use std::process::Command;

/// Flags of `bbsplat benchmark`.
#[derive(Args, Clone, Debug)]
pub struct BenchmarkArgs {
    /// The scene folders (any format `bbsplat train` reads); each trains into `OUT/<its last
    /// path component>`, so the names must differ.
    #[arg(required = true)]
    pub scenes: Vec<PathBuf>,
    /// Output folder: one run folder per scene, benchmark.md, benchmark.json (and curve.svg).
    #[arg(short, long)]
    pub output: PathBuf,
    /// The time budget of each scene's training (`bbsplat train --minutes`).
    #[arg(long)]
    pub minutes: f64,
    /// Also compute LPIPS of the final test views (`bbsplat train --lpips`; `--lpips=alex`).
    #[arg(long, value_enum, num_args = 0..=1, require_equals = true, default_missing_value = "vgg", value_name = "NETWORK")]
    pub lpips: Option<super::common::LpipsNetwork>,
    /// Also write `OUT/curve.svg`: test PSNR against minutes of training, from each run's
    /// evaluation curve.
    #[arg(long)]
    pub curve: bool,
    /// Rayon worker threads of each run (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
}

/// The name of a scene's row and run folder: the last component of its path.
fn scene_name(scene: &Path) -> Result<String> {
    scene
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .with_context(|| format!("{}: a scene path must end in a folder or file name", scene.display()))
}

/// The `bbsplat train` arguments of one scene's run (`resume`: its checkpoint to continue).
fn train_arguments(args: &BenchmarkArgs, scene: &Path, out: &Path, resume: Option<&Path>) -> Vec<std::ffi::OsString> {
    let mut a: Vec<std::ffi::OsString> = vec!["train".into(), scene.into(), "-o".into(), out.into()];
    a.push("--minutes".into());
    a.push(args.minutes.to_string().into());
    if let Some(net) = args.lpips {
        a.push(
            match net {
                super::common::LpipsNetwork::Vgg => "--lpips=vgg",
                super::common::LpipsNetwork::Alex => "--lpips=alex",
            }
            .into(),
        );
    }
    if let Some(t) = args.threads {
        a.push("--threads".into());
        a.push(t.to_string().into());
    }
    if let Some(checkpoint) = resume {
        a.push("--resume".into());
        a.push(checkpoint.into());
    }
    a
}

/// Runs one scene unless it is finished; returns its row (failed with the error when it fails).
fn bench_scene(args: &BenchmarkArgs, scene: &Path, name: &str) -> BenchmarkRow {
    let shown = scene.display().to_string();
    let out = args.output.join(name);
    let summary = out.join(SUMMARY_FILE);
    if summary.exists() {
        println!("{name}: finished earlier ({}), not trained again", summary.display());
    } else {
        let checkpoint = out.join(CHECKPOINT_FILE);
        let resume = checkpoint.exists().then_some(checkpoint.as_path());
        println!(
            "{name}: training {shown} for {} min{}",
            args.minutes,
            resume.map_or(String::new(), |c| format!(" (resuming {})", c.display()))
        );
        if let Err(e) = train_scene(args, scene, &out, resume) {
            eprintln!("{name}: failed: {e:#}");
            return BenchmarkRow::failed(name, &shown, format!("{e:#}"));
        }
    }
    match BenchmarkRow::from_summary(name, &shown, &summary) {
        Ok(row) => check_budget(row, &summary, args.minutes),
        Err(e) => BenchmarkRow::failed(name, &shown, e.to_string()),
    }
}

/// A finished run of another budget is not a row of this table: failed, saying so.
fn check_budget(row: BenchmarkRow, summary: &Path, minutes: f64) -> BenchmarkRow {
    match row.budget_minutes {
        Some(b) if (b - minutes).abs() <= 1e-9 * minutes.max(1.0) => row,
        other => {
            let what = other.map_or("a run without --minutes".to_string(), |b| {
                format!("a --minutes {b} run")
            });
            BenchmarkRow::failed(
                &row.name,
                &row.scene,
                format!(
                    "{} holds {what}, not --minutes {minutes}: remove that folder or choose another -o",
                    summary.display()
                ),
            )
        }
    }
}

/// Spawns `bbsplat train` for one scene: its standard output is shown as it comes, its standard
/// error (warnings, the error) after it ends, its closing error block kept for the message.
fn train_scene(args: &BenchmarkArgs, scene: &Path, out: &Path, resume: Option<&Path>) -> Result<()> {
    let exe = std::env::current_exe().context("finding the bbsplat binary to run the training")?;
    let output = Command::new(&exe)
        .args(train_arguments(args, scene, out, resume))
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::inherit())
        .stderr(std::process::Stdio::piped())
        .output()
        .with_context(|| format!("running {}", exe.display()))?;
    let stderr = String::from_utf8_lossy(&output.stderr);
    eprint!("{stderr}");
    if output.status.success() && out.join(SUMMARY_FILE).exists() {
        return Ok(());
    }
    // The error block `bbsplat train` ends with ("Error: ..." and its causes), on one line.
    let error = stderr
        .rfind("Error: ")
        .map_or("no message", |at| &stderr[at + "Error: ".len()..]);
    let error = error.split_whitespace().collect::<Vec<_>>().join(" ");
    anyhow::bail!("bbsplat train {} ({}): {error}", scene.display(), output.status)
}

/// Runs `bbsplat benchmark`.
pub fn run(args: BenchmarkArgs) -> Result<()> {
    anyhow::ensure!(
        args.minutes.is_finite() && args.minutes > 0.0,
        "--minutes {}: must be a finite number > 0",
        args.minutes
    );
    let mut names = Vec::new();
    for scene in &args.scenes {
        let name = scene_name(scene)?;
        anyhow::ensure!(
            !names.contains(&name),
            "{}: two scenes are named {name}; their runs would share {}",
            scene.display(),
            args.output.join(&name).display()
        );
        names.push(name);
    }
    std::fs::create_dir_all(&args.output)
        .with_context(|| format!("{}: cannot create the output folder", args.output.display()))?;
    let mut rows = Vec::new();
    for (scene, name) in args.scenes.iter().zip(&names) {
        rows.push(bench_scene(&args, scene, name));
        // The table as it stands after each scene, so an interrupted benchmark leaves one.
        write_tables(&args, &rows)?;
    }
    if args.curve {
        let lines: Vec<(String, Vec<(f64, f64)>)> = rows.iter().map(|r| (r.name.clone(), r.curve.clone())).collect();
        let svg =
            bbsplat::sweep::plot_lines_svg(&lines, "Test PSNR during training", "training time (min)", "curve.svg")?;
        let path = args.output.join("curve.svg");
        super::common::write_text_atomic(&path, &svg).with_context(|| format!("writing {}", path.display()))?;
    }
    print!("{}", markdown_table(&rows, args.minutes));
    let failed: Vec<&str> = rows
        .iter()
        .filter(|r| r.error.is_some())
        .map(|r| r.name.as_str())
        .collect();
    anyhow::ensure!(
        failed.is_empty(),
        "{} of {} scenes failed: {} (their errors are in {})",
        failed.len(),
        rows.len(),
        failed.join(", "),
        args.output.join("benchmark.md").display()
    );
    Ok(())
}

/// Writes `OUT/benchmark.md` and `OUT/benchmark.json` for `rows`.
fn write_tables(args: &BenchmarkArgs, rows: &[BenchmarkRow]) -> Result<()> {
    let md = args.output.join("benchmark.md");
    let text = format!(
        "# bbsplat benchmark, {} minutes per scene\n\n{}",
        args.minutes,
        markdown_table(rows, args.minutes)
    );
    super::common::write_text_atomic(&md, &text).with_context(|| format!("writing {}", md.display()))?;
    let json = serde_json::json!({
        "minutes": args.minutes,
        "paper_source": PAPER_SOURCE,
        "units": "psnr dB, train_seconds s, peak_rss_bytes bytes, curve (minutes, psnr dB)",
        "rows": rows,
    });
    let path = args.output.join("benchmark.json");
    let text = serde_json::to_string_pretty(&json).context("encoding the benchmark table")?;
    super::common::write_text_atomic(&path, &text).with_context(|| format!("writing {}", path.display()))
}
