//! `bbsplat blocks run SCENE -o DIR`: the whole block-wise chain ([`bbsplat::blocks`],
//! docs/cluster.md "Tier 2") run stage after stage on this machine, or written as Slurm jobs
//! chained by dependencies (`--slurm`).
//!
//! The stages and their folders in `DIR`:
//! 1. `coarse/`: `bbsplat train SCENE -o DIR/coarse --iterations C`;
//! 2. `blocks/`: `bbsplat blocks split SCENE --coarse DIR/coarse/model -o DIR/blocks`;
//! 3. `blocks/block_K/run/`: per block, `bbsplat train SCENE -o … --init-model
//!    DIR/blocks/block_K/init --views DIR/blocks/block_K/views.txt --iterations B`;
//! 4. `merged/`: `bbsplat blocks merge DIR/blocks -o DIR/merged`;
//! 5. `polish/`: `bbsplat train SCENE -o DIR/polish --init-model DIR/merged --iterations P` (its
//!    summary holds the final test figures, every test view of the scene);
//! 6. `DIR/report.json`: `bbsplat blocks report DIR`.
//!
//! Each stage is a process of this binary. A stage that is done is not run again (a training
//! with its `summary.json`, the split with its `blocks.json`, the merge with its model, the
//! report with its file); a training with only a checkpoint resumes from it. With `--slurm` the
//! same stages are written into `DIR/slurm/`: three array jobs (the coarse run, the blocks, the
//! polish; [`bbsplat::sweep::array_scripts`]: requeued tasks resume, done tasks exit at once),
//! each followed by its collect job (split, merge, report), and `submit.sh`, which submits the
//! six with `afterok` dependencies. `--iterations` runs are deterministic on any thread count, so
//! the chain under Slurm gives the same models as here.

use super::blocks_files::{PLAN_FILE, block_dir};
use anyhow::{Context, Result};
use bbsplat::sweep::{ArrayTask, array_scripts, write_slurm_scripts};
use bbsplat::train::run::{CHECKPOINT_FILE, MODEL_DIR, SUMMARY_FILE};
use clap::Args;
use std::path::{Path, PathBuf};
use std::process::Command;

/// Flags of `bbsplat blocks run`.
#[derive(Args, Clone, Debug)]
pub struct ChainArgs {
    /// The dataset (any format `bbsplat train` reads).
    pub scene: PathBuf,
    /// How the scene is read: passed to every stage that loads it (the trainings and the split).
    #[command(flatten)]
    pub scene_args: super::common::SceneArgs,
    /// The chain's folder (coarse/, blocks/, merged/, polish/, report.json; slurm/ with --slurm).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Cells along the cameras' main spread × across it (`blocks split --grid`).
    #[arg(long, default_value = "2x1")]
    pub grid: String,
    /// `blocks split --margin`.
    #[arg(long, default_value_t = 0.2)]
    pub margin: f32,
    /// `blocks split --min-share`.
    #[arg(long, default_value_t = 0.1)]
    pub min_share: f64,
    /// `blocks split --turn` (degrees).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pub turn: f32,
    /// Steps of the coarse run of the whole scene.
    #[arg(long, default_value_t = 1000)]
    pub coarse_iterations: usize,
    /// Steps of each block's run.
    #[arg(long, default_value_t = 3000)]
    pub block_iterations: usize,
    /// Steps of the polish of the merged model on every view.
    #[arg(long, default_value_t = 500)]
    pub polish_iterations: usize,
    /// Rayon worker threads of each stage run here (default: all cores; with --slurm each task
    /// gets its CPUs).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Write the stages as Slurm jobs into `DIR/slurm/` instead of running them.
    #[arg(long)]
    pub slurm: bool,
    #[command(flatten)]
    pub slurm_flags: super::common::SlurmFlags,
}

/// The chain's stages as `bbsplat` argument lists (trainings without `--threads` and
/// `--resume`, which the runner or the Slurm task adds).
struct Stages {
    coarse: ArrayTask,
    split: Vec<String>,
    blocks: Vec<ArrayTask>,
    merge: Vec<String>,
    polish: ArrayTask,
    report: Vec<String>,
}

fn text(p: &Path) -> String {
    p.display().to_string()
}

fn training(chain: &ChainArgs, out: PathBuf, iterations: usize, extra: &[String]) -> ArrayTask {
    let mut args = vec!["train".to_string(), text(&chain.scene), "-o".into(), text(&out)];
    args.extend(chain.scene_args.to_flags());
    args.extend(["--iterations".to_string(), iterations.to_string(), "--quiet".into()]);
    args.extend(extra.iter().cloned());
    ArrayTask { run_dir: out, args }
}

fn stages(args: &ChainArgs, cells: usize) -> Stages {
    let dir = &args.output;
    let blocks_dir = dir.join("blocks");
    let coarse = training(args, dir.join("coarse"), args.coarse_iterations, &[]);
    let mut split = vec![
        "blocks".to_string(),
        "split".into(),
        text(&args.scene),
        "--coarse".into(),
        text(&dir.join("coarse").join(MODEL_DIR)),
        "-o".into(),
        text(&blocks_dir),
        "--grid".into(),
        args.grid.clone(),
        "--margin".into(),
        args.margin.to_string(),
        "--min-share".into(),
        args.min_share.to_string(),
        "--turn".into(),
        args.turn.to_string(),
    ];
    split.extend(args.scene_args.to_flags());
    let blocks = (0..cells)
        .map(|k| {
            let block = block_dir(&blocks_dir, k);
            let extra = [
                "--init-model".to_string(),
                text(&block.join("init")),
                "--views".into(),
                text(&block.join("views.txt")),
            ];
            training(args, block.join("run"), args.block_iterations, &extra)
        })
        .collect();
    let merge = vec![
        "blocks".to_string(),
        "merge".into(),
        text(&blocks_dir),
        "-o".into(),
        text(&dir.join("merged")),
    ];
    let polish = training(
        args,
        dir.join("polish"),
        args.polish_iterations,
        &["--init-model".to_string(), text(&dir.join("merged"))],
    );
    let report = vec!["blocks".to_string(), "report".into(), text(dir)];
    Stages {
        coarse,
        split,
        blocks,
        merge,
        polish,
        report,
    }
}

/// Runs `bbsplat blocks run`.
pub fn run(args: &ChainArgs) -> Result<()> {
    let (columns, rows) = super::blocks_files::grid(&args.grid).map_err(|e| anyhow::anyhow!("--grid {e}"))?;
    for (flag, n) in [
        ("--coarse-iterations", args.coarse_iterations),
        ("--block-iterations", args.block_iterations),
        ("--polish-iterations", args.polish_iterations),
    ] {
        anyhow::ensure!(n >= 1, "{flag} must be at least 1");
    }
    anyhow::ensure!(
        args.scene.exists(),
        "{}: no such scene (the chain's jobs would fail)",
        args.scene.display()
    );
    let stages = stages(args, columns * rows);
    let exe = std::env::current_exe().context("finding the bbsplat binary to run the stages")?;
    if args.slurm {
        return write_chain_scripts(args, &stages, &exe);
    }
    let dir = &args.output;
    train_stage(&exe, "coarse run", &stages.coarse, args.threads)?;
    if dir.join("blocks").join(PLAN_FILE).exists() {
        println!("split: done earlier");
    } else {
        run_stage(&exe, "split", &stages.split)?;
    }
    for (k, block) in stages.blocks.iter().enumerate() {
        train_stage(&exe, &format!("block {k}"), block, args.threads)?;
    }
    if dir.join("merged").join("bbsplat.json").exists() {
        println!("merge: done earlier");
    } else {
        run_stage(&exe, "merge", &stages.merge)?;
    }
    train_stage(&exe, "polish", &stages.polish, args.threads)?;
    run_stage(&exe, "report", &stages.report)
}

/// Runs one training unless its summary exists, resuming from its checkpoint when it has one.
fn train_stage(exe: &Path, what: &str, task: &ArrayTask, threads: Option<usize>) -> Result<()> {
    if task.run_dir.join(SUMMARY_FILE).exists() {
        println!("{what}: done earlier ({})", task.run_dir.display());
        return Ok(());
    }
    let mut stage = task.args.clone();
    if let Some(t) = threads {
        stage.extend(["--threads".to_string(), t.to_string()]);
    }
    let checkpoint = task.run_dir.join(CHECKPOINT_FILE);
    if checkpoint.exists() {
        stage.extend(["--resume".to_string(), text(&checkpoint)]);
    }
    run_stage(exe, what, &stage)
}

/// Runs `exe` with `stage`'s arguments, its output shown as it comes.
fn run_stage(exe: &Path, what: &str, stage: &[String]) -> Result<()> {
    println!("{what}: bbsplat {}", stage.join(" "));
    let status = Command::new(exe)
        .args(stage)
        .stdin(std::process::Stdio::null())
        .status()
        .with_context(|| format!("running {}", exe.display()))?;
    anyhow::ensure!(
        status.success(),
        "{what} failed ({status}): bbsplat {}",
        stage.join(" ")
    );
    Ok(())
}

/// `--slurm`: the three array jobs with their collect jobs, and the submit script chaining
/// them.
fn write_chain_scripts(args: &ChainArgs, stages: &Stages, exe: &Path) -> Result<()> {
    let options = args.slurm_flags.options();
    let slurm = args.output.join("slurm");
    let parts = [
        ("coarse", std::slice::from_ref(&stages.coarse), &stages.split),
        ("blocks", stages.blocks.as_slice(), &stages.merge),
        ("polish", std::slice::from_ref(&stages.polish), &stages.report),
    ];
    let mut submit = String::from(
        "#!/bin/sh\n# Submits the block-wise chain: coarse run, split, blocks, merge, polish, report;\n\
         # each job after the one before it succeeded.\nset -eu\nafter=\n",
    );
    for (job, tasks, collect) in parts {
        let dir = slurm.join(job);
        let command: Vec<String> = std::iter::once(text(exe)).chain(collect.iter().cloned()).collect();
        let scripts = array_scripts(job, exe, tasks, &command, &dir, &options);
        write_slurm_scripts(&dir, &scripts).with_context(|| format!("writing {}", dir.display()))?;
        let quote = |name: &str| bbsplat::sweep::shell_quote(&text(&dir.join(name)));
        submit += &format!(
            "a=$(sbatch --parsable ${{after:+--dependency=afterok:$after}} {})\na=${{a%%;*}}\n\
             c=$(sbatch --parsable --dependency=afterok:\"$a\" {})\nafter=${{c%%;*}}\n\
             echo \"{job}: array job $a, then job $after\"\n",
            quote(&format!("{job}.sbatch")),
            quote("collect.sbatch"),
        );
    }
    let path = slurm.join("submit.sh");
    bbsplat::file_io::write_atomic(&path, submit.as_bytes())?;
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o755))?;
    }
    println!(
        "wrote the chain's Slurm jobs to {}: submit them with {}",
        slurm.display(),
        path.display()
    );
    Ok(())
}
