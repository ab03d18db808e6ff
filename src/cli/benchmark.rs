//! `bbsplat benchmark SCENE... -o OUT --minutes M` (or `--iterations N`): trains each scene with
//! the defaults into `OUT/<name>` and writes the table of their figures ([`bbsplat::benchmark`])
//! as `OUT/benchmark.md` and `OUT/benchmark.json`. With `--slurm` it writes the same runs as a
//! Slurm array job (one task per scene) and a collect job that writes the table, instead of
//! running them ([`bbsplat::sweep::array_scripts`], docs/cluster.md).
//!
//! Each scene runs as its own `bbsplat train SCENE -o OUT/<name> --minutes M` process (this very
//! binary), not in this process: the peak memory a summary records is the process's high-water
//! mark (`VmHWM`), which only a fresh process gives per scene, and a failed or interrupted scene
//! leaves the others and the table untouched. A scene whose `OUT/<name>/summary.json` exists is
//! not trained again; one with only a checkpoint (interrupted) is resumed from it. A scene that
//! fails is marked failed in the table with its error and the others still run; the command
//! then ends with an error naming the failed scenes.

use anyhow::{Context, Result};
use bbsplat::benchmark::{BenchmarkBudget, BenchmarkRow, PAPER_SOURCE, markdown_table};
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
    #[arg(long, required_unless_present = "iterations", conflicts_with = "iterations")]
    pub minutes: Option<f64>,
    /// A step count for each scene instead of a time budget (`bbsplat train --iterations`): the
    /// same models on any machine and thread count.
    #[arg(long)]
    pub iterations: Option<usize>,
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
    /// Write the runs as Slurm jobs into `OUT/slurm/` instead of running them:
    /// `benchmark.sbatch` (an array job, one task per scene, each resumed from its checkpoint when
    /// requeued), `collect.sbatch` (this command without `--slurm`, after every task succeeded:
    /// it writes the table) and `submit.sh`.
    #[arg(long)]
    pub slurm: bool,
    #[command(flatten)]
    pub slurm_flags: super::common::SlurmFlags,
}

impl BenchmarkArgs {
    /// The budget of each scene's run.
    /// The flags each run gets besides its budget, as the table states them.
    fn extra_flags(&self) -> Vec<String> {
        let mut flags: Vec<String> = self.lpips.map(|net| lpips_flag(net).to_string()).into_iter().collect();
        if let Some(t) = self.threads {
            flags.extend(["--threads".to_string(), t.to_string()]);
        }
        flags
    }

    fn budget(&self) -> BenchmarkBudget {
        match (self.minutes, self.iterations) {
            (_, Some(n)) => BenchmarkBudget::Steps(n),
            (Some(m), None) => BenchmarkBudget::Minutes(m),
            (None, None) => unreachable!("clap requires --minutes or --iterations"),
        }
    }
}

/// The name of a scene's row and run folder: the last component of its path.
fn scene_name(scene: &Path) -> Result<String> {
    scene
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .with_context(|| format!("{}: a scene path must end in a folder or file name", scene.display()))
}

/// `--lpips=vgg` or `--lpips=alex`.
fn lpips_flag(net: super::common::LpipsNetwork) -> &'static str {
    match net {
        super::common::LpipsNetwork::Vgg => "--lpips=vgg",
        super::common::LpipsNetwork::Alex => "--lpips=alex",
    }
}

/// The `bbsplat train` arguments of one scene's run (`resume`: its checkpoint to continue).
fn train_arguments(args: &BenchmarkArgs, scene: &Path, out: &Path, resume: Option<&Path>) -> Vec<std::ffi::OsString> {
    let mut a: Vec<std::ffi::OsString> = vec!["train".into(), scene.into(), "-o".into(), out.into()];
    a.extend(args.budget().train_flag().map(Into::into));
    if let Some(net) = args.lpips {
        a.push(lpips_flag(net).into());
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
            "{name}: training {shown} for {}{}",
            args.budget().describe(),
            resume.map_or(String::new(), |c| format!(" (resuming {})", c.display()))
        );
        if let Err(e) = train_scene(args, scene, &out, resume) {
            eprintln!("{name}: failed: {e:#}");
            return BenchmarkRow::failed(name, &shown, format!("{e:#}"));
        }
    }
    match BenchmarkRow::from_summary(name, &shown, &summary) {
        Ok(row) => check_budget(row, &summary, args.budget()),
        Err(e) => BenchmarkRow::failed(name, &shown, e.to_string()),
    }
}

/// A finished run of another budget is not a row of this table: failed, saying so.
fn check_budget(row: BenchmarkRow, summary: &Path, budget: BenchmarkBudget) -> BenchmarkRow {
    if budget.holds(&row) {
        return row;
    }
    let [flag, value] = budget.train_flag();
    BenchmarkRow::failed(
        &row.name,
        &row.scene,
        format!(
            "{} holds {}, not {flag} {value}: remove that folder or choose another -o",
            summary.display(),
            BenchmarkBudget::of_row(&row)
        ),
    )
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
pub fn run(mut args: BenchmarkArgs) -> Result<()> {
    if let Some(minutes) = args.minutes {
        anyhow::ensure!(
            minutes.is_finite() && minutes > 0.0,
            "--minutes {minutes}: must be a finite number > 0"
        );
    }
    anyhow::ensure!(args.iterations != Some(0), "--iterations 0: must be at least 1");
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
    if args.slurm {
        return write_slurm(&mut args, &names);
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
    print!("{}", markdown_table(&rows, args.budget(), &args.extra_flags()));
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
        "# bbsplat benchmark, {} per scene\n\n{}",
        args.budget().describe(),
        markdown_table(rows, args.budget(), &args.extra_flags())
    );
    super::common::write_text_atomic(&md, &text).with_context(|| format!("writing {}", md.display()))?;
    let json = serde_json::json!({
        "minutes": args.minutes,
        "iterations": args.iterations,
        "paper_source": PAPER_SOURCE,
        "units": "psnr dB, train_seconds s, peak_rss_bytes bytes, curve (minutes, psnr dB)",
        "rows": rows,
    });
    let path = args.output.join("benchmark.json");
    let text = serde_json::to_string_pretty(&json).context("encoding the benchmark table")?;
    super::common::write_text_atomic(&path, &text).with_context(|| format!("writing {}", path.display()))
}

/// `--slurm`: the array job of the scenes' runs, the collect job (this command without its Slurm
/// flags) and the submit script, in `OUT/slurm/`. Paths are made absolute: the jobs may start in
/// another folder, on another node.
fn write_slurm(args: &mut BenchmarkArgs, names: &[String]) -> Result<()> {
    args.output = std::path::absolute(&args.output).context("resolving -o")?;
    for scene in &mut args.scenes {
        // A missing scene would fail its task, and with it the collect job (afterok): refused now.
        anyhow::ensure!(
            scene.exists(),
            "{}: no such scene (nothing was written)",
            scene.display()
        );
        *scene = std::path::absolute(&*scene).with_context(|| format!("resolving {}", scene.display()))?;
    }
    let text = |p: &std::ffi::OsStr| -> Result<String> {
        p.to_str()
            .map(str::to_string)
            .with_context(|| format!("{}: a path of a Slurm job must be UTF-8", p.to_string_lossy()))
    };
    let local = BenchmarkArgs {
        threads: None,
        ..args.clone()
    };
    let mut tasks = Vec::new();
    for (scene, name) in args.scenes.iter().zip(names) {
        let run_dir = args.output.join(name);
        let train = train_arguments(&local, scene, &run_dir, None);
        let args = train.iter().map(|a| text(a)).collect::<Result<Vec<_>>>()?;
        tasks.push(bbsplat::sweep::ArrayTask { run_dir, args });
    }
    let exe = std::env::current_exe().context("finding the bbsplat binary the jobs run")?;
    let mut collect = vec![text(exe.as_os_str())?, "benchmark".to_string()];
    for scene in &args.scenes {
        collect.push(text(scene.as_os_str())?);
    }
    collect.extend(["-o".to_string(), text(args.output.as_os_str())?]);
    collect.extend(args.budget().train_flag());
    if let Some(net) = args.lpips {
        collect.push(lpips_flag(net).into());
    }
    if args.curve {
        collect.push("--curve".into());
    }
    let options = args.slurm_flags.options();
    let dir = args.output.join("slurm");
    let scripts = bbsplat::sweep::array_scripts("benchmark", &exe, &tasks, &collect, &dir, &options);
    let paths =
        bbsplat::sweep::write_slurm_scripts(&dir, &scripts).with_context(|| format!("writing {}", dir.display()))?;
    for p in &paths {
        println!("wrote {}", p.display());
    }
    println!("{} scenes; submit with: sh {}", tasks.len(), paths[2].display());
    Ok(())
}
