//! Budget sweep: trains once per setting of a grid with `bbsplat train` (one child process per
//! run), then writes a CSV, JSON, markdown table and SVG plots of speed against error.
//!
//! ```text
//! cargo build --release && cargo run --release --features examples --example sweep -- scenes/lego --out sweeps/lego \
//!     --billboards 1000,3000 --iterations 500,2000 -- --threads 2 --downscale 2
//! ```
//!
//! Axes given on the command line override those of `--grid <file.json>`. Arguments after `--`
//! are passed to every `bbsplat train` run. Runs live in `<out>/runs/<slug>/` (with `train.log`
//! and `summary.json`); settings whose `summary.json` exists are not run again, so re-running
//! the same command resumes an interrupted sweep. Reports (`sweep.csv`, `sweep.json`, `sweep.md`,
//! `psnr_vs_time.svg`, `psnr_vs_size.svg`, `curves.svg`) are rewritten in `<out>/` after every
//! run.
use anyhow::{Context, Result, bail};
use bbsplat::sweep::{
    SlurmOptions, SubprocessRunner, SweepGrid, run_grid, slurm_scripts, write_outputs, write_slurm_scripts,
};
use clap::Parser;
use std::path::PathBuf;
use std::time::Instant;

#[derive(Parser)]
#[command(
    name = "sweep",
    about = "Train over a grid of budgets and report speed against error"
)]
struct Args {
    /// Scene folder passed to `bbsplat train`.
    scene: PathBuf,
    /// Output folder: runs in `<out>/runs/<slug>/`, reports in `<out>/`.
    #[arg(long)]
    out: PathBuf,
    /// JSON grid, e.g. `{"billboards": [1000, 3000], "iterations": [500, 2000], "seeds": [0]}`.
    #[arg(long)]
    grid: Option<PathBuf>,
    /// Optimisation steps, comma-separated.
    #[arg(long)]
    iterations: Option<String>,
    /// Billboard budgets, comma-separated.
    #[arg(long)]
    billboards: Option<String>,
    /// Texture sides, comma-separated.
    #[arg(long)]
    texture_size: Option<String>,
    /// Texel budgets per channel, comma-separated: each run gets `texels / TS²` billboards for
    /// its texture size (the supplement's Table 7); exclusive with `--billboards`.
    #[arg(long)]
    texels: Option<String>,
    /// Largest training image widths in pixels, comma-separated.
    #[arg(long)]
    max_width: Option<String>,
    /// Texture-threshold σ values (Eq. 9), comma-separated.
    #[arg(long)]
    texture_threshold: Option<String>,
    /// Texture modes (`full`, `gaussian`), comma-separated.
    #[arg(long)]
    texture_mode: Option<String>,
    /// Seeds, comma-separated.
    #[arg(long)]
    seeds: Option<String>,
    /// The `bbsplat` executable (default: `bbsplat` in the target folder this example was built
    /// into).
    #[arg(long)]
    exe: Option<PathBuf>,
    /// Print the commands and exit.
    #[arg(long)]
    dry_run: bool,
    /// Write the sweep as Slurm jobs into `<out>/slurm/` instead of running it: `sweep.sbatch`
    /// (one array task per setting), `collect.sbatch` (this command without the Slurm flags,
    /// after every task succeeded) and `submit.sh`, which submits both (docs/cluster.md).
    #[arg(long)]
    slurm: bool,
    /// With --slurm: CPUs per task (`bbsplat` gets as many threads).
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u32).range(1..=4096))]
    cpus_per_task: u32,
    /// With --slurm: memory per task in MB.
    #[arg(long)]
    mem: Option<u64>,
    /// With --slurm: time limit per task, in Slurm's syntax (e.g. `30:00`).
    #[arg(long)]
    time: Option<String>,
    /// With --slurm: the partition.
    #[arg(long)]
    partition: Option<String>,
    /// Flags passed to every `bbsplat train` run.
    #[arg(last = true)]
    train_args: Vec<String>,
}

/// `bbsplat` next to this example: examples live in `target/<profile>/examples/`.
fn default_exe() -> Result<PathBuf> {
    let me = std::env::current_exe().context("locating this executable")?;
    let name = format!("bbsplat{}", std::env::consts::EXE_SUFFIX);
    let candidates: Vec<PathBuf> = me.ancestors().skip(1).take(2).map(|d| d.join(&name)).collect();
    candidates.iter().find(|p| p.is_file()).cloned().with_context(|| {
        format!(
            "no bbsplat executable at {}; build it (`cargo build --release`) or pass --exe",
            candidates
                .iter()
                .map(|p| p.display().to_string())
                .collect::<Vec<_>>()
                .join(" or ")
        )
    })
}

/// The Slurm flags of this command, with the number of values each takes.
const SLURM_FLAGS: [(&str, usize); 5] = [
    ("--slurm", 0),
    ("--cpus-per-task", 1),
    ("--mem", 1),
    ("--time", 1),
    ("--partition", 1),
];

/// This command line without its Slurm flags, the executable as an absolute path: the collect
/// job's command.
fn collect_command() -> Result<Vec<String>> {
    let exe = std::env::current_exe().context("locating this executable")?;
    let mut out = vec![exe.display().to_string()];
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        if a == "--" {
            out.push(a);
            out.extend(args.by_ref());
            break;
        }
        match SLURM_FLAGS
            .iter()
            .find(|(f, _)| a == *f || a.starts_with(&format!("{f}=")))
        {
            Some((f, n)) if a == *f => {
                for _ in 0..*n {
                    args.next();
                }
            }
            Some(_) => {}
            None => out.push(a),
        }
    }
    Ok(out)
}

fn write_slurm(args: &Args, runner: &SubprocessRunner, settings: &[bbsplat::sweep::Setting]) -> Result<()> {
    let dir = args.out.join("slurm");
    let options = SlurmOptions {
        cpus_per_task: args.cpus_per_task,
        mem_mb: args.mem,
        time: args.time.clone(),
        partition: args.partition.clone(),
    };
    let scripts = slurm_scripts(runner, settings, &collect_command()?, &dir, &options);
    let paths = write_slurm_scripts(&dir, &scripts).with_context(|| format!("writing {}", dir.display()))?;
    for p in &paths {
        println!("wrote {}", p.display());
    }
    println!("{} settings; submit with: sh {}", settings.len(), paths[2].display());
    Ok(())
}

fn main() -> Result<()> {
    let mut args = Args::parse();
    // Absolute paths: the jobs may start in another folder, on another machine.
    args.out = std::path::absolute(&args.out).context("resolving --out")?;
    args.scene = std::path::absolute(&args.scene).context("resolving the scene path")?;
    let mut grid = match &args.grid {
        Some(path) => SweepGrid::from_json_file(path)?,
        None => SweepGrid::default(),
    };
    for (axis, list) in [
        ("iterations", &args.iterations),
        ("billboards", &args.billboards),
        ("texture-size", &args.texture_size),
        ("texels", &args.texels),
        ("max-width", &args.max_width),
        ("texture-threshold", &args.texture_threshold),
        ("texture-mode", &args.texture_mode),
        ("seeds", &args.seeds),
    ] {
        if let Some(list) = list {
            grid.set_axis(axis, list)?;
        }
    }
    let exe = match args.exe.clone() {
        Some(exe) => exe,
        None => default_exe()?,
    };
    let mut runner = SubprocessRunner::new(exe, args.scene.clone(), args.out.join("runs"));
    runner.extra_args = args.train_args.clone();
    runner.verbose = true;
    let settings = grid.settings()?;
    if args.slurm {
        return write_slurm(&args, &runner, &settings);
    }
    if args.dry_run {
        for s in &settings {
            println!("{} {}", runner.exe.display(), runner.args(s).join(" "));
        }
        return Ok(());
    }
    eprintln!("{} settings, runs in {}", settings.len(), runner.out_root.display());
    let start = Instant::now();
    let mut done = Vec::new();
    let mut index = 0;
    let outcome = run_grid(&grid, |s| {
        index += 1;
        eprintln!("[{index}/{}] {}", settings.len(), s.slug());
        let summary = runner.run(s)?;
        eprintln!(
            "    {:.1} s training, {:.2} dB test PSNR, {:.2} MB",
            summary.train_seconds,
            summary.test_psnr,
            summary.model_bytes as f64 / 1e6
        );
        done.push(bbsplat::sweep::SweepRecord {
            setting: *s,
            summary: summary.clone(),
        });
        // Keep the reports current so an interrupted sweep still leaves them; a failure here is
        // not the run's failure.
        if let Err(e) = write_outputs(&args.out, &done) {
            eprintln!("warning: {e}");
        }
        Ok(summary)
    })?;
    let files = write_outputs(&args.out, &outcome.records)?;
    println!("{}", std::fs::read_to_string(&files.markdown)?);
    println!(
        "{} runs in {:.0} s; reports: {}, {}, {}, {}, {}, {}",
        outcome.records.len(),
        start.elapsed().as_secs_f64(),
        files.csv.display(),
        files.json.display(),
        files.markdown.display(),
        files.psnr_vs_time.display(),
        files.psnr_vs_size.display(),
        files.curves.display()
    );
    if !outcome.failures.is_empty() {
        for f in &outcome.failures {
            eprintln!("failed: {}: {}", f.setting.slug(), f.error);
        }
        bail!("{} of {} runs failed", outcome.failures.len(), settings.len());
    }
    Ok(())
}
