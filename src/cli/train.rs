//! `bbsplat train <scene> -o <out>`: the main job.

use super::auto_settings;
use super::common::{SceneArgs, start_threads};
use super::signals::Signals;
use super::{preflight, resume, validate};
use anyhow::{Context, Result};
use bbsplat::init::scene_init::init_model_with;
use bbsplat::report::RunReport;
use bbsplat::train::RunError;
use bbsplat::train::footprint::{output_bytes, training_bytes};
use bbsplat::train::geometry::GeometryRegularisers;
use bbsplat::train::resolution::ResolutionSchedule;
use bbsplat::train::time_budget::TimePlan;
use bbsplat::train::{
    AdamMode, ClampGradient, LearningRateScales, RunConfig, RunOutcome, StopReason, TextureMode, TrainConfig,
    TrainEvent, TrainView, Trainer,
};
use clap::builder::{PossibleValuesParser, TypedValueParser};
use clap::{Args, ValueEnum};
use glam::Vec3;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::path::PathBuf;
use std::time::Instant;

/// Flags of `bbsplat train`.
#[derive(Args, Clone, Debug)]
pub struct TrainArgs {
    /// The dataset: a COLMAP folder, a NeRF-synthetic folder or a transforms.json (auto-detected).
    pub scene: PathBuf,
    /// Output folder (model, checkpoints, summary.json).
    #[arg(short, long)]
    pub output: PathBuf,
    #[command(flatten)]
    pub scene_args: SceneArgs,
    /// Optimisation steps, one image each (the reference's 32 000 is the 100 % point of every
    /// schedule; all milestones scale with this number). Default 7000, unless `--minutes` is
    /// given. Exact and reproducible, unlike `--minutes`.
    #[arg(long, conflicts_with = "minutes")]
    pub iterations: Option<usize>,
    /// A time budget: train for this many minutes of step time (evaluations and saving not
    /// counted), the number of steps and every schedule planned from the step time measured
    /// while training (see docs/training.md). The plan is in the checkpoint: `--resume`
    /// continues it.
    #[arg(long, value_parser = positive_minutes)]
    pub minutes: Option<f64>,
    /// Billboard count (default: derived from the scene, see docs/training.md).
    #[arg(long)]
    pub billboards: Option<usize>,
    /// Texture side TS (TS×TS alpha and colour texels per billboard).
    #[arg(long, default_value_t = 16)]
    pub texture_size: usize,
    /// Highest SH degree (0-3).
    #[arg(long, default_value_t = 3)]
    pub sh_degree: u32,
    /// Seed of the initialisation and of the view order.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Rayon worker threads (default: all cores). Results do not depend on it.
    #[arg(long)]
    pub threads: Option<usize>,
    /// Evaluate on the test views every n steps (0: only at the end).
    #[arg(long, default_value_t = 1000)]
    pub eval_every: usize,
    /// At most this many test views (evenly spaced) in the intermediate evaluations; the final
    /// evaluation uses all of them.
    #[arg(long, default_value_t = 25)]
    pub eval_views: usize,
    /// Write a checkpoint every n steps (0: only on Ctrl-C).
    #[arg(long, default_value_t = 0)]
    pub save_every: usize,
    /// No progress bar or per-evaluation lines; the final summary is still printed.
    #[arg(long)]
    pub quiet: bool,
    /// Threshold σ of the texture regulariser (paper Eq. 9) on a billboard's per-view impact
    /// (Σ α·T over its pixels): billboards with less impact have their textures pulled to the
    /// initial state. The paper uses 500; the current reference code 100.
    #[arg(long, default_value_t = 500.0)]
    pub texture_threshold: f32,
    /// `full`: learned alpha and colour textures (BBSplat); `gaussian`: plain Gaussian billboards
    /// with one opacity each and SH colour only (the "textures off" ablation).
    #[arg(long, default_value_t = TextureMode::Full, value_parser = texture_mode())]
    pub texture_mode: TextureMode,
    /// `dense`: every billboard takes an Adam step each iteration (the reference); `sparse`:
    /// only billboards the view touched.
    #[arg(long, value_enum, default_value_t = AdamModeArg::Dense)]
    pub adam: AdamModeArg,
    /// Do not recycle dead billboards (mean alpha ≤ 0.005).
    #[arg(long)]
    pub no_relocate: bool,
    /// Grow the set by 5 % every 100 steps (spec §6) up to this many billboards (0: no growth).
    /// Default: from the scene (see docs/training.md).
    #[arg(long)]
    pub growth_cap: Option<usize>,
    /// Share (0-1) of each growth step's new billboards placed where the view just trained on
    /// is rendered worst (camera-facing, at the depth where the neighbouring views agree, in
    /// the target colour) instead of copied from existing billboards ∝ alpha (0: the
    /// reference's growth). Default: from the scene, 1 without SfM points and 0 with them
    /// (docs/quality.md).
    #[arg(long, value_parser = fraction)]
    pub error_growth: Option<f32>,
    /// Stop after this many steps (of `--iterations`) with a checkpoint, as Ctrl-C does: lets a
    /// long run be done in slices with `--resume`.
    #[arg(long)]
    pub stop_after: Option<usize>,
    /// Continue from a checkpoint written by an earlier run (Ctrl-C, a signal, `--stop-after` or
    /// `--save-every`) with the same scene and flags: a different dataset or a flag that changes
    /// the model or the optimisation is refused. Continuing is bit-identical to not stopping.
    #[arg(long)]
    pub resume: Option<PathBuf>,
    /// Replace the run the output folder already holds (without it, such a folder is refused
    /// unless the run is continued with `--resume`). Its files are replaced one by one, each
    /// atomically, as this run writes its own.
    #[arg(long)]
    pub overwrite: bool,
    /// Initialisation of scenes without SfM points, in the box the cameras look at: `auto`
    /// (the hull when the images have alpha masks, else random points plus a background shell),
    /// `random` points (the reference), or `hull`: points on the visual hull carved from the
    /// images' alpha masks (RGBA images such as NeRF-synthetic; see docs/training.md).
    #[arg(long, value_enum, default_value_t = InitArg::Auto)]
    pub init: InitArg,
    /// Voxels per side of the `--init hull` grid.
    #[arg(long, default_value_t = 128)]
    pub hull_resolution: usize,
    /// Coarse-to-fine: train the first `--coarse-until` of the run on images downscaled by this
    /// factor (1: off, the reference). A coarse step costs about 1/factor² of a full one.
    /// Default 2 (measured on lego, docs/quality.md).
    #[arg(long, default_value_t = 2)]
    pub coarse_factor: u32,
    /// Fraction of the run (0-1) trained on the coarse images when `--coarse-factor` > 1.
    #[arg(long, default_value_t = 0.5)]
    pub coarse_until: f64,
    /// Multiply every learning rate by this factor (1: the reference's rates; the schedules are
    /// unchanged). Default: a factor of the run length (4 up to 7000 steps, 1 at the reference's
    /// 32 000, log-linear between; measured on lego, see docs/quality.md), used when no
    /// learning-rate flag is given.
    #[arg(long, value_parser = non_negative)]
    pub lr_scale: Option<f32>,
    /// Learning-rate factor of the positions (default: `--lr-scale`).
    #[arg(long, value_parser = non_negative)]
    pub lr_position: Option<f32>,
    /// Learning-rate factor of the SH coefficients (default: `--lr-scale`).
    #[arg(long, value_parser = non_negative)]
    pub lr_sh: Option<f32>,
    /// Learning-rate factor of the log-scales and quaternions (default: `--lr-scale`).
    #[arg(long, value_parser = non_negative)]
    pub lr_shape: Option<f32>,
    /// Learning-rate factor of the alpha and colour textures (default: `--lr-scale`).
    #[arg(long, value_parser = non_negative)]
    pub lr_texture: Option<f32>,
    /// Gradient through the compositing clamp `α = min(0.99, a)`: `exact` (the derivative of the
    /// forward: none above the clamp) or `straight-through` (as if unclamped, as the reference
    /// rasterizer does). See docs/training.md.
    #[arg(long, value_enum, default_value_t = ClampGradientArg::Exact)]
    pub clamp_gradient: ClampGradientArg,
    /// Weight of the 2DGS normal-consistency regulariser (0: off, the reference's default; its
    /// DTU scripts use 0.05): the rendered normals are pulled toward the normals of the rendered
    /// depth. See docs/training.md.
    #[arg(long, default_value_t = 0.0, value_parser = non_negative)]
    pub lambda_normal: f32,
    /// Weight of the 2DGS depth-distortion regulariser (0: off, the reference's default; its DTU
    /// scripts use 100 to 1000): concentrates each pixel's blending weights in depth.
    #[arg(long, default_value_t = 0.0, value_parser = non_negative)]
    pub lambda_dist: f32,
    /// Fraction of the run (0-1) after which `--lambda-normal` applies (default 7000/32000, the
    /// reference's iteration 7000; with `--minutes`, of the planned steps).
    #[arg(long, default_value_t = bbsplat::train::geometry::NORMAL_FROM, value_parser = fraction)]
    pub normal_from: f32,
    /// Fraction of the run (0-1) after which `--lambda-dist` applies (default 3000/32000, the
    /// reference's iteration 3000; with `--minutes`, of the planned steps).
    #[arg(long, default_value_t = bbsplat::train::geometry::DISTORTION_FROM, value_parser = fraction)]
    pub dist_from: f32,
}

/// A number in `[0, 1]` (the regularisers' start fractions).
fn fraction(text: &str) -> Result<f32, String> {
    match text.parse::<f32>() {
        Ok(x) if (0.0..=1.0).contains(&x) => Ok(x),
        Ok(x) => Err(format!("{x} is not a fraction in [0, 1]")),
        Err(e) => Err(format!("{text:?} is not a number: {e}")),
    }
}

/// `--minutes`: a finite number > 0.
fn positive_minutes(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(x) if x.is_finite() && x > 0.0 => Ok(x),
        Ok(x) => Err(format!("{x} is not a finite number > 0")),
        Err(e) => Err(format!("{text:?} is not a number: {e}")),
    }
}

/// Steps of a run without `--iterations` or `--minutes`.
pub const DEFAULT_ITERATIONS: usize = 7000;

/// A finite number ≥ 0 (the learning-rate factors).
fn non_negative(text: &str) -> Result<f32, String> {
    match text.parse::<f32>() {
        Ok(x) if x.is_finite() && x >= 0.0 => Ok(x),
        Ok(x) => Err(format!("{x} is not a finite number ≥ 0")),
        Err(e) => Err(format!("{text:?} is not a number: {e}")),
    }
}

/// `--texture-mode`: the library's names ([`TextureMode::as_str`]), listed in `--help` and in
/// the error for any other value.
fn texture_mode() -> impl TypedValueParser<Value = TextureMode> {
    PossibleValuesParser::new(TextureMode::ALL.map(TextureMode::as_str))
        .map(|name| name.parse::<TextureMode>().expect("one of the listed names"))
}

impl TrainArgs {
    /// The learning-rate multipliers of the flags (1 where none is given).
    pub fn lr_scales(&self) -> LearningRateScales {
        let all = self.lr_scale.unwrap_or(1.0);
        LearningRateScales {
            position: self.lr_position.unwrap_or(all),
            sh: self.lr_sh.unwrap_or(all),
            shape: self.lr_shape.unwrap_or(all),
            texture: self.lr_texture.unwrap_or(all),
        }
    }

    /// The geometry regularisers of the flags.
    pub fn geometry(&self) -> GeometryRegularisers {
        GeometryRegularisers {
            lambda_normal: self.lambda_normal,
            lambda_distortion: self.lambda_dist,
            normal_from: self.normal_from,
            distortion_from: self.dist_from,
        }
    }

    /// True when no learning-rate flag is given: the rates then follow the run length
    /// ([`bbsplat::train::run_length_lr_factor`]).
    pub fn lr_by_run_length(&self) -> bool {
        [
            self.lr_scale,
            self.lr_position,
            self.lr_sh,
            self.lr_shape,
            self.lr_texture,
        ]
        .iter()
        .all(Option::is_none)
    }
}

/// `--init`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum InitArg {
    /// The hull when the images have alpha masks, else random points plus a background shell.
    Auto,
    /// Uniform random points in the scene box.
    Random,
    /// Points on the surface of the visual hull of the alpha masks.
    Hull,
}

/// `--clamp-gradient`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum ClampGradientArg {
    /// Zero gradient where the clamp is active.
    Exact,
    /// The gradient passes through the clamp.
    StraightThrough,
}

impl From<ClampGradientArg> for ClampGradient {
    fn from(c: ClampGradientArg) -> Self {
        match c {
            ClampGradientArg::Exact => ClampGradient::Exact,
            ClampGradientArg::StraightThrough => ClampGradient::PassThrough,
        }
    }
}

/// `--adam`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum AdamModeArg {
    /// All rows every step.
    Dense,
    /// Touched rows only.
    Sparse,
}

/// After a failed run, makes sure the trained state is on disk: errors that already name a
/// checkpoint need nothing; otherwise the trainer (when its parameters are finite) is written to
/// `<out>/checkpoint.bin`, or to the temporary folder when that fails. Returns a note for the
/// message saying where, or what could not be saved.
fn rescue(trainer: &Trainer, error: &RunError, out: &std::path::Path) -> String {
    let named = match error {
        RunError::ModelSave { checkpoint, .. } => Some(checkpoint.clone()),
        RunError::Step { checkpoint, .. } => checkpoint.clone(),
        _ => None,
    };
    if let Some(path) = named {
        return format!(
            " (once fixed, continue from the saved state with --resume {})",
            path.display()
        );
    }
    if trainer.step_index() == 0 {
        return String::new();
    }
    if trainer.non_finite_parameter().is_some() {
        return " (the trainer's state is not finite and was not saved)".into();
    }
    let candidates = [
        out.join(bbsplat::train::run::CHECKPOINT_FILE),
        std::env::temp_dir().join(format!("bbsplat-rescued-{}.bin", std::process::id())),
    ];
    for path in candidates {
        if trainer.save_checkpoint(&path).is_ok() {
            return format!(
                " (the trained state at step {} is saved in {}: continue with --resume {})",
                trainer.step_index(),
                path.display(),
                path.display()
            );
        }
    }
    " (the trained state could not be saved anywhere)".into()
}

/// Runs `bbsplat train`: loads the scene, builds or resumes the trainer, and turns the events of
/// [`bbsplat::train::run`] into the progress bar and printed lines; Ctrl-C raises its stop
/// signal.
pub fn run(args: TrainArgs) -> Result<()> {
    let signals = Signals::install()?;
    let start = Instant::now();
    validate::train_args(&args)?;
    let iterations = args.iterations.unwrap_or(DEFAULT_ITERATIONS);
    if let Some(n) = args.billboards {
        validate::memory(
            &format!("--billboards {n} at --texture-size {}", args.texture_size),
            training_bytes(n, args.texture_size, 0, 0),
        )?;
    }
    if matches!(args.init, InitArg::Hull | InitArg::Auto) {
        let r = args.hull_resolution as u64;
        validate::memory(&format!("--hull-resolution {r}"), r.saturating_pow(3).saturating_mul(2))?;
    }
    preflight::output_folder(&args.output, args.resume.as_deref(), args.overwrite)?;
    let threads = start_threads(args.threads)?;
    let (scene, background) = args.scene_args.load_for_training(&args.scene, args.quiet)?;
    anyhow::ensure!(
        !scene.train.is_empty(),
        "{}: the scene has no training view",
        args.scene.display()
    );
    let views = scene.train.iter().chain(&scene.test);
    let view_pixels: u64 = views.clone().map(|v| v.camera.pixel_count() as u64).sum();
    let largest_view = views.map(|v| v.camera.pixel_count() as u64).max().unwrap_or(0);
    let record = resume::record_of(&args, &scene);
    let mut automatic = Vec::new();
    let mut trainer = match &args.resume {
        Some(path) => {
            let t = Trainer::load_checkpoint(path).with_context(|| format!("resuming from {}", path.display()))?;
            match t.time_plan() {
                Some(plan) => anyhow::ensure!(
                    args.iterations.is_none() && args.minutes.is_none_or(|m| m * 60.0 == plan.budget_seconds),
                    "{}: the checkpoint is of a --minutes {} run; resume it with that budget (or no --minutes) \
                     and without --iterations",
                    path.display(),
                    plan.budget_seconds / 60.0
                ),
                None => {
                    anyhow::ensure!(
                        args.minutes.is_none(),
                        "{}: the checkpoint is of a {}-step run, not of a --minutes run",
                        path.display(),
                        t.config().iterations
                    );
                    anyhow::ensure!(
                        t.config().iterations == iterations,
                        "{}: the checkpoint is of a {}-step run, not --iterations {}",
                        path.display(),
                        t.config().iterations,
                        iterations
                    );
                }
            }
            if let Some(note) = resume::check(path, t.run_record(), &record)? {
                eprintln!("{note}");
            }
            preflight::free_space(&args.output, output_bytes(t.model().len(), t.model().texture_size))?;
            println!("resuming at step {} from {}", t.step_index(), path.display());
            t
        }
        None => {
            let auto = auto_settings::resolve(&args, &scene, &background)?;
            if !args.quiet {
                for c in &auto.choices {
                    println!("{}: {} ({})", c.setting, c.value, c.reason);
                }
            }
            automatic = auto.choices.clone();
            let budget = auto.billboards;
            validate::memory(
                &format!(
                    "training {budget} billboards at --texture-size {} on {} views",
                    args.texture_size,
                    scene.train.len() + scene.test.len()
                ),
                training_bytes(budget, args.texture_size, view_pixels, largest_view),
            )?;
            preflight::free_space(&args.output, output_bytes(budget, args.texture_size))?;
            let (model, init) = init_model_with(&scene, budget, args.texture_size, args.seed, &auto.pointless)
                .with_context(|| format!("initialising {} billboards", budget))?;
            if args.init == InitArg::Hull && init.hull == 0 {
                eprintln!(
                    "note: --init hull applies to scenes without SfM points; this one has them and they were used"
                );
            }
            if !args.quiet {
                println!("initial billboards: {init}");
            }
            let config = TrainConfig {
                iterations,
                sh_degree: args.sh_degree,
                background: Vec3::from_array(scene.background.rgb()),
                seed: args.seed,
                extent: scene.extent,
                impact_threshold: args.texture_threshold,
                adam: match args.adam {
                    AdamModeArg::Dense => AdamMode::Dense,
                    AdamModeArg::Sparse => AdamMode::Sparse,
                },
                texture_mode: args.texture_mode,
                relocate: !args.no_relocate,
                growth_cap: auto.growth_cap,
                error_growth: auto.error_growth,
                lr_scales: args.lr_scales(),
                lr_by_run_length: args.lr_by_run_length(),
                clamp_gradient: args.clamp_gradient.into(),
                geometry: args.geometry(),
                ..TrainConfig::default()
            };
            let mut trainer = Trainer::new(model, config);
            trainer.set_time_plan(args.minutes.map(TimePlan::new));
            trainer.set_run_record(record);
            trainer
        }
    };
    // The views' 8-bit images move into the training views (converted to floats per step).
    let scene_warnings = scene.warnings;
    let train: Vec<TrainView> = scene.train.into_iter().map(TrainView::from_owned_view).collect();
    let test: Vec<TrainView> = scene.test.into_iter().map(TrainView::from_owned_view).collect();
    // From here on a signal stops the run with a checkpoint instead of ending the process.
    let stop = signals.arm();
    let bar = if args.quiet {
        ProgressBar::hidden()
    } else {
        let bar = ProgressBar::with_draw_target(
            Some(trainer.config().iterations as u64),
            ProgressDrawTarget::stderr_with_hz(4),
        );
        bar.set_style(
            ProgressStyle::with_template("{bar:28} {pos}/{len} [{elapsed_precise}<{eta_precise}, {per_sec}] {msg}")
                .expect("a valid template"),
        );
        bar
    };
    let run_config = RunConfig {
        eval_every: args.eval_every,
        eval_views: args.eval_views,
        save_every: args.save_every,
        output: Some(args.output.clone()),
        stop_after: args.stop_after,
        resolution: ResolutionSchedule {
            factor: args.coarse_factor,
            until: args.coarse_until,
        },
        scene: args.scene.display().to_string(),
        // Arguments as the OS gave them (a path need not be UTF-8).
        command: std::env::args_os().map(|a| a.to_string_lossy().into_owned()).collect(),
        warnings: scene_warnings,
        automatic,
    };
    let last_record = std::cell::RefCell::new(None::<RunReport>);
    let on_event = |event: &TrainEvent| match event {
        TrainEvent::Started {
            train_views,
            test_views,
            width,
            height,
            billboards,
            texture_size,
            ..
        } => println!(
            "{}: {train_views} train / {test_views} test views at {width}x{height}, {billboards} billboards (TS {texture_size}), loaded in {:.1} s, {threads} threads",
            args.scene.display(),
            start.elapsed().as_secs_f64()
        ),
        TrainEvent::Warning(warning) if !args.quiet => bar.suspend(|| eprintln!("warning: {warning}")),
        TrainEvent::Step {
            log,
            iterations,
            running_psnr,
            relocated_total,
            ..
        } => {
            bar.set_length(*iterations as u64);
            bar.set_position(log.step as u64);
            bar.set_message(format!(
                "loss {:.4} | train PSNR {running_psnr:.2} dB | relocated {relocated_total}",
                log.loss
            ));
        }
        TrainEvent::Evaluation {
            step,
            psnr,
            ssim,
            seconds,
            views,
        } if !args.quiet => bar.suspend(|| {
            println!("step {step:>6}: test PSNR {psnr:.2} dB, SSIM {ssim:.4} ({views} views), {seconds:.0} s")
        }),
        TrainEvent::Record(record) => *last_record.borrow_mut() = Some((**record).clone()),
        _ => {}
    };
    let outcome = bbsplat::train::run(&mut trainer, &train, &test, &run_config, &stop, on_event);
    let summary = match outcome {
        Ok(RunOutcome::Finished(summary)) => {
            bar.finish_and_clear();
            summary
        }
        Ok(RunOutcome::Stopped {
            step,
            reason,
            checkpoint,
        }) => {
            bar.abandon();
            let checkpoint = checkpoint.unwrap_or_else(|| args.output.join(bbsplat::train::run::CHECKPOINT_FILE));
            eprintln!(
                "{} at step {step}: saved {}; continue with the same command and --resume {}",
                if reason == StopReason::Requested {
                    "interrupted"
                } else {
                    "stopped"
                },
                checkpoint.display(),
                checkpoint.display()
            );
            if reason == StopReason::Requested {
                std::process::exit(130);
            }
            return Ok(());
        }
        Ok(other) => anyhow::bail!("training ended unexpectedly: {other:?}"),
        Err(e) => {
            bar.abandon();
            let note = rescue(&trainer, &e, &args.output);
            return Err(e).with_context(|| format!("training on {}{note}", args.scene.display()));
        }
    };
    let scores = if summary.test_views == 0 {
        "no test views to score (--test-every 0 or an empty test list)".to_string()
    } else {
        format!(
            "test PSNR {:.2} dB, SSIM {:.4} over {} views",
            summary.test_psnr, summary.test_ssim, summary.test_views
        )
    };
    println!(
        "trained {} steps in {:.1} s ({:.2} it/s): {scores}; {} billboards ({} alive); model {:.2} MB; peak memory {:.0} MB",
        summary.iterations,
        summary.train_seconds,
        summary.iterations as f64 / summary.train_seconds,
        summary.billboards,
        summary.alive,
        summary.model_bytes as f64 / 1e6,
        summary.peak_rss_bytes as f64 / 1e6
    );
    if let Some(record) = last_record.into_inner() {
        print!("{}", describe_record(&record));
    }
    Ok(())
}

/// The end-of-run lines about the automatic choices, the plan and the billboard count.
fn describe_record(record: &RunReport) -> String {
    let mut out = String::new();
    for c in &record.automatic {
        out.push_str(&format!("chosen {}: {} ({})\n", c.setting, c.value, c.reason));
    }
    if let Some(p) = &record.plan {
        out.push_str(&format!(
            "time budget {:.2} min: {:.2} min of steps ({:+.1} %), {} steps planned; step {:.3} s coarse, {:.3} s full{}\n",
            p.budget_minutes,
            p.spent_minutes,
            100.0 * (p.spent_minutes / p.budget_minutes - 1.0),
            p.planned_steps,
            p.coarse_step_seconds,
            p.fine_step_seconds,
            p.fine_from.map_or(String::new(), |s| format!(", full resolution from step {s}"))
        ));
    }
    if let Some(g) = &record.growth {
        out.push_str(&format!(
            "billboards: {} at the start, {} at the end ({} alive), growth cap {}\n",
            g.initial, g.final_count, g.alive, g.cap
        ));
    }
    out.push_str(&format!(
        "outside the steps (evaluation, saving): {:.1} s\n",
        record.other_seconds
    ));
    out
}
