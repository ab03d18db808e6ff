//! `bbsplat train <scene> -o <out>`: the main job.

use super::common::{SceneArgs, start_threads, train_views, write_text_atomic};
use anyhow::{Context, Result};
use bbsplat::eval::{EvalView, evaluate_views};
use bbsplat::init::budget::{BudgetInputs, budget_for};
use bbsplat::init::hull::HullConfig;
use bbsplat::init::scene_init::{PointlessInit, init_model_with};
use bbsplat::model::{Model, logit};
use bbsplat::model_file::{ModelMeta, load_model, save_model};
use bbsplat::raster::{BillboardSet, RenderSettings};
use bbsplat::report::{CurvePoint, SUMMARY_VERSION, TrainSummary, peak_rss_bytes};
use bbsplat::train::resolution::{ResolutionSchedule, downscale_view};
use bbsplat::train::{AdamMode, LearningRateScales, TextureMode, TrainConfig, TrainView, Trainer};
use clap::{Args, ValueEnum};
use glam::Vec3;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
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
    /// schedule; all milestones scale with this number).
    #[arg(long, default_value_t = 7000)]
    pub iterations: usize,
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
    #[arg(long, value_enum, default_value_t = TextureModeArg::Full)]
    pub texture_mode: TextureModeArg,
    /// `dense`: every billboard takes an Adam step each iteration (the reference); `sparse`:
    /// only billboards the view touched.
    #[arg(long, value_enum, default_value_t = AdamModeArg::Dense)]
    pub adam: AdamModeArg,
    /// Do not recycle dead billboards (mean alpha ≤ 0.005).
    #[arg(long)]
    pub no_relocate: bool,
    /// Stop after this many steps (of `--iterations`) with a checkpoint, as Ctrl-C does: lets a
    /// long run be done in slices with `--resume`.
    #[arg(long)]
    pub stop_after: Option<usize>,
    /// Continue from a checkpoint written by an earlier run (Ctrl-C or `--save-every`); the
    /// scene and flags should be those of that run. Continuing is bit-identical to not stopping.
    #[arg(long)]
    pub resume: Option<PathBuf>,
    /// Initialisation of scenes without SfM points: `random` points in the scene box (the
    /// reference), or `hull`: points on the visual hull carved from the images' alpha masks
    /// (RGBA images such as NeRF-synthetic; see docs/training.md).
    #[arg(long, value_enum, default_value_t = InitArg::Random)]
    pub init: InitArg,
    /// Voxels per side of the `--init hull` grid.
    #[arg(long, default_value_t = 128)]
    pub hull_resolution: usize,
    /// Coarse-to-fine: train the first `--coarse-until` of the run on images downscaled by this
    /// factor (1: off, the reference). A coarse step costs about 1/factor² of a full one.
    #[arg(long, default_value_t = 1)]
    pub coarse_factor: u32,
    /// Fraction of the run (0-1) trained on the coarse images when `--coarse-factor` > 1.
    #[arg(long, default_value_t = 0.5)]
    pub coarse_until: f64,
    /// Multiply every learning rate by this factor (1: the reference's rates; the schedules are
    /// unchanged). Runs much shorter than the reference's 32 000 steps gain from more: see
    /// docs/quality.md.
    #[arg(long, default_value_t = 1.0, value_parser = non_negative)]
    pub lr_scale: f32,
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
}

/// A finite number ≥ 0 (the learning-rate factors).
fn non_negative(text: &str) -> Result<f32, String> {
    match text.parse::<f32>() {
        Ok(x) if x.is_finite() && x >= 0.0 => Ok(x),
        Ok(x) => Err(format!("{x} is not a finite number ≥ 0")),
        Err(e) => Err(format!("{text:?} is not a number: {e}")),
    }
}

impl TrainArgs {
    /// The learning-rate multipliers of the flags.
    pub fn lr_scales(&self) -> LearningRateScales {
        LearningRateScales {
            position: self.lr_position.unwrap_or(self.lr_scale),
            sh: self.lr_sh.unwrap_or(self.lr_scale),
            shape: self.lr_shape.unwrap_or(self.lr_scale),
            texture: self.lr_texture.unwrap_or(self.lr_scale),
        }
    }
}

/// `--init`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum InitArg {
    /// Uniform random points in the scene box.
    Random,
    /// Points on the surface of the visual hull of the alpha masks.
    Hull,
}

/// `--texture-mode`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum TextureModeArg {
    /// Learned textures.
    Full,
    /// Gaussian billboards, SH colour only.
    Gaussian,
}

/// `--adam`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum AdamModeArg {
    /// All rows every step.
    Dense,
    /// Touched rows only.
    Sparse,
}

fn evenly_spaced<T>(items: &[T], at_most: usize) -> Vec<&T> {
    if items.len() <= at_most || at_most == 0 {
        return items.iter().collect();
    }
    (0..at_most).map(|k| &items[k * items.len() / at_most]).collect()
}

fn evaluate(
    set: &BillboardSet<'_>,
    views: &[(String, TrainView)],
    settings: &RenderSettings,
) -> Result<(f64, f64, f64)> {
    let report = evaluate_views(
        set,
        views.iter().map(|(name, v)| EvalView {
            name,
            camera: &v.camera,
            rgb: &v.rgb,
        }),
        settings,
        |_, _| {},
    )?;
    Ok((report.mean_psnr, report.mean_ssim, report.mean_render_ms))
}

/// Runs `bbsplat train`.
pub fn run(args: TrainArgs) -> Result<()> {
    anyhow::ensure!(args.texture_size >= 2, "--texture-size must be at least 2");
    anyhow::ensure!(args.sh_degree <= 3, "--sh-degree must be 0, 1, 2 or 3");
    anyhow::ensure!(args.iterations >= 1, "--iterations must be at least 1");
    anyhow::ensure!(args.coarse_factor >= 1, "--coarse-factor must be at least 1");
    anyhow::ensure!(
        (0.0..=1.0).contains(&args.coarse_until),
        "--coarse-until must be a fraction between 0 and 1"
    );
    let resolution = ResolutionSchedule {
        factor: args.coarse_factor,
        until: args.coarse_until,
    };
    let threads = start_threads(args.threads)?;
    let start = Instant::now();
    let scene = args.scene_args.load(&args.scene, args.quiet)?;
    let train = train_views(&scene.train);
    anyhow::ensure!(
        !train.is_empty(),
        "{}: the scene has no training view",
        args.scene.display()
    );
    let coarse: Vec<TrainView> = if args.coarse_factor > 1 {
        train.iter().map(|v| downscale_view(v, args.coarse_factor)).collect()
    } else {
        Vec::new()
    };
    let test: Vec<(String, TrainView)> = scene
        .test
        .iter()
        .map(|v| v.name.clone())
        .zip(train_views(&scene.test))
        .collect();
    let background = Vec3::from_array(scene.background.rgb());
    let config = TrainConfig {
        iterations: args.iterations,
        sh_degree: args.sh_degree,
        background,
        seed: args.seed,
        extent: scene.extent,
        impact_threshold: args.texture_threshold,
        adam: match args.adam {
            AdamModeArg::Dense => AdamMode::Dense,
            AdamModeArg::Sparse => AdamMode::Sparse,
        },
        texture_mode: match args.texture_mode {
            TextureModeArg::Full => TextureMode::Full,
            TextureModeArg::Gaussian => TextureMode::Gaussian,
        },
        relocate: !args.no_relocate,
        lr_scales: args.lr_scales(),
        ..TrainConfig::default()
    };
    let checkpoint = args.output.join("checkpoint.bin");
    let mut trainer = match &args.resume {
        Some(path) => {
            let t = Trainer::load_checkpoint(path).with_context(|| format!("resuming from {}", path.display()))?;
            anyhow::ensure!(
                t.config().iterations == args.iterations,
                "{}: the checkpoint is of a {}-step run, not --iterations {}",
                path.display(),
                t.config().iterations,
                args.iterations
            );
            println!("resuming at step {} from {}", t.step_index(), path.display());
            t
        }
        None => {
            let budget = match args.billboards {
                Some(n) => {
                    anyhow::ensure!(n >= 1, "--billboards must be at least 1");
                    n
                }
                None => {
                    let b = budget_for(&BudgetInputs::from_scene(&scene, args.texture_size));
                    if !args.quiet {
                        println!("budget: {}", b.reason);
                    }
                    b.billboards
                }
            };
            let pointless = match args.init {
                InitArg::Random => PointlessInit::Random,
                InitArg::Hull => PointlessInit::Hull(HullConfig {
                    resolution: args.hull_resolution,
                    ..HullConfig::default()
                }),
            };
            let (model, init) = init_model_with(&scene, budget, args.texture_size, args.seed, &pointless)
                .with_context(|| format!("initialising {} billboards", budget))?;
            if args.init == InitArg::Hull && init.hull == 0 {
                eprintln!(
                    "note: --init hull applies to scenes without SfM points; this one has them and they were used"
                );
            }
            if !args.quiet {
                let hull = if init.hull > 0 {
                    format!(
                        ", {} on the visual hull (of {} surface voxels)",
                        init.hull, init.hull_candidates
                    )
                } else {
                    String::new()
                };
                let random_box = if init.random > 0 {
                    format!(" ({})", init.box_rule)
                } else {
                    String::new()
                };
                println!(
                    "initial billboards: {} from SfM points, {} on the sky sphere (radius {:.2}){hull}, {} random{random_box}",
                    init.sfm, init.sky, init.sky_radius, init.random,
                );
            }
            Trainer::new(model, config)
        }
    };
    let cam0 = train[0].camera;
    // From here on Ctrl-C saves a checkpoint instead of killing the process.
    let interrupted = Arc::new(AtomicBool::new(false));
    {
        let flag = interrupted.clone();
        ctrlc::set_handler(move || flag.store(true, Ordering::SeqCst)).context("installing the Ctrl-C handler")?;
    }
    println!(
        "{}: {} train / {} test views at {}x{}, {} billboards (TS {}), loaded in {:.1} s, {threads} threads",
        args.scene.display(),
        train.len(),
        test.len(),
        cam0.width,
        cam0.height,
        trainer.model.len(),
        trainer.model.texture_size,
        start.elapsed().as_secs_f64()
    );
    std::fs::create_dir_all(&args.output).with_context(|| format!("creating {}", args.output.display()))?;

    let eval_settings = RenderSettings {
        background,
        sh_degree: args.sh_degree,
        ..RenderSettings::default()
    };
    let eval_subset: Vec<(String, TrainView)> = evenly_spaced(&test, args.eval_views).into_iter().cloned().collect();
    let bar = if args.quiet {
        ProgressBar::hidden()
    } else {
        let bar = ProgressBar::with_draw_target(Some(args.iterations as u64), ProgressDrawTarget::stderr_with_hz(4));
        bar.set_style(
            ProgressStyle::with_template("{bar:28} {pos}/{len} [{elapsed_precise}<{eta_precise}, {per_sec}] {msg}")
                .expect("a valid template"),
        );
        bar
    };
    let mut curve = Vec::new();
    let mut train_seconds = 0.0;
    let mut running_psnr = f64::NAN;
    let mut relocated = 0usize;
    while trainer.step_index() < args.iterations {
        let stop_requested = args.stop_after.is_some_and(|n| trainer.step_index() >= n);
        if stop_requested || interrupted.load(Ordering::SeqCst) {
            bar.abandon();
            trainer
                .save_checkpoint(&checkpoint)
                .with_context(|| format!("saving {}", checkpoint.display()))?;
            eprintln!(
                "{} at step {}: saved {}; continue with the same command and --resume {}",
                if stop_requested { "stopped" } else { "interrupted" },
                trainer.step_index(),
                checkpoint.display(),
                checkpoint.display()
            );
            if stop_requested {
                return Ok(());
            }
            std::process::exit(130);
        }
        let t0 = Instant::now();
        let views = if resolution.is_coarse(trainer.step_index(), args.iterations) {
            &coarse
        } else {
            &train
        };
        let log = trainer.step(views)?;
        train_seconds += t0.elapsed().as_secs_f64();
        running_psnr = if running_psnr.is_nan() {
            log.psnr
        } else {
            0.95 * running_psnr + 0.05 * log.psnr
        };
        let step = trainer.step_index();
        bar.set_position(step as u64);
        relocated += log.relocated;
        bar.set_message(format!(
            "loss {:.4} | train PSNR {running_psnr:.2} dB | relocated {relocated}",
            log.loss
        ));
        if args.save_every > 0 && step % args.save_every == 0 {
            trainer
                .save_checkpoint(&checkpoint)
                .with_context(|| format!("saving {}", checkpoint.display()))?;
        }
        if args.eval_every > 0 && step % args.eval_every == 0 && step < args.iterations && !eval_subset.is_empty() {
            let (psnr, ssim, _) = evaluate(&trainer.activated.as_set(), &eval_subset, &eval_settings)?;
            curve.push(CurvePoint {
                step,
                seconds: train_seconds,
                psnr,
                ssim,
            });
            if !args.quiet {
                bar.suspend(|| {
                    println!(
                        "step {step:>6}: test PSNR {psnr:.2} dB, SSIM {ssim:.4} ({} views), {train_seconds:.0} s",
                        eval_subset.len()
                    )
                });
            }
        }
    }
    bar.finish_and_clear();
    // The model is saved as the reference saves it (8-bit textures) and evaluated as re-loaded,
    // as the reference's render.py does.
    let model_dir = args.output.join("model");
    let meta = ModelMeta::for_model(&trainer.model, args.sh_degree, background.to_array());
    let model_bytes = save_model(&model_dir, &effective_model(&trainer), &meta)
        .with_context(|| format!("saving the model to {}", model_dir.display()))?;
    trainer
        .save_checkpoint(&checkpoint)
        .with_context(|| format!("saving {}", checkpoint.display()))?;
    let (saved, _) = load_model(&model_dir).with_context(|| format!("re-loading {}", model_dir.display()))?;
    let saved = saved.activate();
    let (test_psnr, test_ssim, render_ms) = if test.is_empty() {
        (f64::NAN, f64::NAN, f64::NAN)
    } else {
        evaluate(&saved.as_set(), &test, &eval_settings)?
    };
    curve.push(CurvePoint {
        step: args.iterations,
        seconds: train_seconds,
        psnr: test_psnr,
        ssim: test_ssim,
    });
    let summary = TrainSummary {
        version: SUMMARY_VERSION,
        scene: args.scene.display().to_string(),
        iterations: args.iterations,
        billboards: trainer.model.len(),
        alive: trainer.alive_count(),
        texture_size: args.texture_size,
        sh_degree: args.sh_degree,
        resolution: [cam0.width, cam0.height],
        train_seconds,
        render_ms_per_frame: render_ms,
        test_psnr,
        test_ssim,
        test_views: test.len(),
        model_bytes,
        peak_rss_bytes: peak_rss_bytes(),
        seed: args.seed,
        threads,
        curve,
        command: std::env::args().collect(),
    };
    write_summary(&args.output, &summary)?;
    println!(
        "trained {} steps in {:.1} s ({:.2} it/s): test PSNR {:.2} dB, SSIM {:.4} over {} views; {} billboards ({} alive); model {:.2} MB; peak memory {:.0} MB",
        args.iterations,
        train_seconds,
        args.iterations as f64 / train_seconds,
        test_psnr,
        test_ssim,
        test.len(),
        summary.billboards,
        summary.alive,
        model_bytes as f64 / 1e6,
        summary.peak_rss_bytes as f64 / 1e6
    );
    Ok(())
}

/// The model to save: the trainer's raw parameters, with the alpha logits taken from the textures
/// the renderer actually used (in Gaussian mode those are opacity × the fixed shape, not the
/// stored logits).
fn effective_model(trainer: &Trainer) -> Model {
    let mut model = trainer.model.clone();
    if trainer.config().texture_mode == TextureMode::Gaussian {
        let t = model.texture_size * model.texture_size;
        for (i, texel) in trainer.activated.textures.iter().enumerate() {
            model.alpha_logits[i] = if model.alpha_mask[i % t] {
                logit(texel[3].clamp(1e-6, 1.0 - 1e-6))
            } else {
                0.0
            };
        }
    }
    model
}

fn write_summary(dir: &Path, summary: &TrainSummary) -> Result<()> {
    let text = serde_json::to_string_pretty(summary).context("encoding the summary")?;
    write_text_atomic(&dir.join("summary.json"), &text)
}
