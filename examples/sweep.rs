//! Budget sweep: trains once per setting of a grid with `bbsplat train` (one child process per
//! run), then writes a CSV, JSON, markdown table and SVG plots of speed against error.
//!
//! ```text
//! cargo build --release && cargo run --release --example sweep -- scenes/lego --out sweeps/lego \
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
use bbsplat::sweep::{SubprocessRunner, SweepGrid, run_grid, write_outputs};
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

fn main() -> Result<()> {
    let args = Args::parse();
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
    let exe = match args.exe {
        Some(exe) => exe,
        None => default_exe()?,
    };
    let mut runner = SubprocessRunner::new(exe, args.scene.clone(), args.out.join("runs"));
    runner.extra_args = args.train_args.clone();
    runner.verbose = true;
    let settings = grid.settings()?;
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
