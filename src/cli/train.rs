//! `bbsplat train <scene> -o <out>`: the main job.

use super::common::{MaskModeArg, start_threads};
use super::signals::Signals;
use super::train_args::{InitArg, TrainArgs};
use super::{preflight, resume, validate};
use anyhow::{Context, Result};
use bbsplat::memory::human_bytes;
use bbsplat::plan::{RunLength, TrainPlan};
use bbsplat::report::RunReport;
use bbsplat::train::RunError;
use bbsplat::train::footprint::{output_bytes, scene_training_bytes, training_bytes};
use bbsplat::train::run_time;
use bbsplat::train::{RunConfig, RunOutcome, StopReason, TrainEvent, TrainView, Trainer};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::time::Instant;

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

/// `--views FILE`: keeps the scene's views named in the file; a name that is no view of the
/// scene, or a list that keeps no training view, is refused naming the file.
fn keep_listed_views(scene: &mut bbsplat::scene::Scene, list: &std::path::Path) -> Result<()> {
    let text = bbsplat::file_io::read_text_bounded(list, bbsplat::file_io::SCENE_FILE)
        .with_context(|| format!("reading --views {}", list.display()))?;
    let names: std::collections::BTreeSet<String> = text
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty() && !l.starts_with('#'))
        .map(str::to_string)
        .collect();
    let unknown = scene.keep_views(&names);
    if let Some(first) = unknown.first() {
        anyhow::bail!(
            "{}: {} of its {} names are no view of the scene, e.g. {first:?}",
            list.display(),
            unknown.len(),
            names.len()
        );
    }
    anyhow::ensure!(
        !scene.train.is_empty(),
        "{}: none of its {} views is a training view of the scene",
        list.display(),
        names.len()
    );
    Ok(())
}

/// `--init-model DIR`: the billboards to start from, of texture size `texture_size`.
fn start_model(dir: &std::path::Path, texture_size: usize) -> Result<bbsplat::RawBillboards> {
    let (model, _) = bbsplat::load_model(dir).with_context(|| format!("reading --init-model {}", dir.display()))?;
    anyhow::ensure!(
        model.texture_size == texture_size,
        "--init-model {}: its textures are {}×{}, not --texture-size {texture_size}; give --texture-size {}",
        dir.display(),
        model.texture_size,
        model.texture_size,
        model.texture_size
    );
    anyhow::ensure!(
        !model.is_empty(),
        "--init-model {}: the model has no billboard",
        dir.display()
    );
    Ok(model)
}

/// Runs `bbsplat train`: loads the scene, builds or resumes the trainer, and turns the events of
/// [`bbsplat::train::run`] into the progress bar and printed lines; Ctrl-C raises its stop
/// signal.
pub fn run(args: TrainArgs) -> Result<()> {
    let signals = Signals::install()?;
    let start = Instant::now();
    validate::train_args(&args)?;
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
    if let Some(path) = &args.resume {
        // The checkpoint's kind and size before the scene loads (a link to a device, a FIFO, a
        // file too large are refused now, not after minutes of loading); read after it.
        bbsplat::file_io::check_readable(path, bbsplat::file_io::CHECKPOINT)
            .with_context(|| format!("resuming from {}", path.display()))?;
    }
    let threads = start_threads(args.threads)?;
    let (mut scene, background) = args.scene_args.load_for_training(&args.scene)?;
    if let Some(list) = &args.views {
        keep_listed_views(&mut scene, list)?;
    }
    anyhow::ensure!(
        !scene.train.is_empty(),
        "{}: the scene has no training view",
        args.scene.display()
    );
    let weight_by_masks = args.scene_args.mask_mode == MaskModeArg::Weight;
    anyhow::ensure!(
        !weight_by_masks || scene.train.iter().any(|v| v.mask.is_some()),
        "{}: --mask-mode weight, but no training view has a mask (a NeuS mask/ folder, or --masks DIR)",
        args.scene.display()
    );
    if let Some(cache) = scene.image_cache()
        && !args.quiet
    {
        let pixels: u64 = scene
            .train
            .iter()
            .chain(&scene.test)
            .map(|v| v.camera.pixel_count() as u64)
            .sum();
        println!(
            "images: {} of 8-bit images do not fit in --image-memory {}: each is decoded from its file when used, through a cache of that size",
            human_bytes(3 * pixels),
            human_bytes(cache.budget())
        );
    }
    let request = args.request();
    let record = resume::record_of(&args, &scene);
    let mut automatic = Vec::new();
    // The time of the run a checkpoint continues, or why it is not known.
    let mut earlier_time = None;
    // The pre-flight estimate of the peak memory, printed and recorded beside the measured one.
    let estimated_peak;
    let mut resume_warnings = Vec::new();
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
                None => match request.length {
                    RunLength::Minutes(_) => anyhow::bail!(
                        "{}: the checkpoint is of a {}-step run, not of a --minutes run",
                        path.display(),
                        t.config().iterations
                    ),
                    RunLength::Steps(iterations) => anyhow::ensure!(
                        t.config().iterations == iterations,
                        "{}: the checkpoint is of a {}-step run, not --iterations {}",
                        path.display(),
                        t.config().iterations,
                        iterations
                    ),
                },
            }
            if let Some(note) = resume::check(path, t.run_record(), &record)? {
                eprintln!("{note}");
            }
            let (n, ts) = (t.model().len(), t.model().texture_size);
            estimated_peak = scene_training_bytes(n, t.config().growth_cap, ts, &scene);
            validate::memory(
                &format!(
                    "resuming {n} billboards at texture size {ts} on {} views",
                    scene.train.len() + scene.test.len()
                ),
                estimated_peak,
            )?;
            preflight::free_space(&args.output, output_bytes(n, ts))?;
            println!("resuming at step {} from {}", t.step_index(), path.display());
            match run_time::read_beside(path, t.step_index()) {
                Ok(time) => earlier_time = Some(time),
                Err(why) => {
                    eprintln!("warning: {why}");
                    resume_warnings.push(why);
                }
            }
            t
        }
        None => {
            let start_model = match &args.init_model {
                Some(dir) => Some(start_model(dir, args.texture_size)?),
                None => None,
            };
            let mut request = request;
            if let Some(model) = &start_model {
                request.billboards = Some(model.len());
            }
            let mut plan = TrainPlan::new(
                &scene,
                args.scene_args.background.is_none().then_some(&background),
                &request,
            )
            .map_err(|e| anyhow::anyhow!("--{e}"))?;
            if start_model.is_some() {
                // The scene's initialisation is not used.
                plan.choices.retain(|c| c.setting != "init");
            }
            if !args.quiet {
                for c in &plan.choices {
                    println!("{}: {} ({})", c.setting, c.value, c.reason);
                }
            }
            automatic = plan.choices.clone();
            let budget = plan.billboards;
            estimated_peak = plan.training_bytes(&scene);
            validate::memory(
                &format!(
                    "training {budget} billboards at --texture-size {} on {} views",
                    args.texture_size,
                    scene.train.len() + scene.test.len()
                ),
                estimated_peak,
            )?;
            preflight::free_space(&args.output, output_bytes(budget, args.texture_size))?;
            let model = match start_model {
                Some(model) => {
                    if !args.quiet {
                        let from = args.init_model.as_ref().map(|d| d.display().to_string());
                        println!("initial billboards: {budget} from {}", from.unwrap_or_default());
                    }
                    model
                }
                None => {
                    if !args.quiet {
                        println!("initialising {budget} billboards...");
                    }
                    let (model, init) = plan
                        .init_model(&scene)
                        .with_context(|| format!("initialising {} billboards", budget))?;
                    if args.init == InitArg::Hull && init.hull == 0 {
                        eprintln!(
                            "note: --init hull applies to scenes without SfM points; this one has them and they were used"
                        );
                    }
                    if !args.quiet {
                        println!("initial billboards: {init}");
                    }
                    model
                }
            };
            let mut trainer = plan.trainer(model);
            trainer.set_run_record(record);
            trainer
        }
    };
    // The views' 8-bit images move into the training views (converted to floats per step).
    let mut scene_warnings = scene.warnings;
    scene_warnings.extend(resume_warnings);
    let train_names: Vec<String> = scene.train.iter().map(|v| v.name.clone()).collect();
    // With --mask-mode weight each training view's mask weights its loss.
    let train: Vec<TrainView> = scene
        .train
        .into_iter()
        .map(|mut v| {
            let loss_mask = if weight_by_masks { v.mask.take() } else { None };
            TrainView::from_owned_view(v).with_loss_mask(loss_mask)
        })
        .collect();
    // The test views' masks (NeuS mask/, --masks), for the masked figures of the summary.
    let test_masks: Vec<Option<Vec<u8>>> = scene.test.iter().map(|v| v.mask.clone()).collect();
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
    // The final evaluation's LPIPS network when asked for; missing or damaged weights are warned
    // about and noted in the summary, and do not stop the run.
    let (lpips, lpips_note) = match args.lpips {
        None => (None, Some("not asked for (bbsplat train --lpips)".to_string())),
        Some(network) => match bbsplat::lpips::Lpips::load_cached(network.into()) {
            Ok(net) => (Some(std::sync::Arc::new(net)), None),
            Err(e) => {
                if !args.quiet {
                    eprintln!("warning: {e}; the run goes on without LPIPS");
                }
                (None, Some(e.to_string()))
            }
        },
    };
    // Raised by the live view's `/refresh`, taken by the run after each step.
    let refresh = bbsplat::train::SnapshotRequest::new();
    let run_config = RunConfig {
        eval_every: args.eval_every,
        eval_views: args.eval_views,
        save_every: args.save_every,
        output: Some(args.output.clone()),
        stop_after: args.stop_after,
        resolution: request.resolution,
        scene: args.scene.display().to_string(),
        // Arguments as the OS gave them (a path need not be UTF-8).
        command: std::env::args_os().map(|a| a.to_string_lossy().into_owned()).collect(),
        warnings: scene_warnings,
        automatic,
        earlier_time,
        lpips,
        lpips_note,
        step_clock: bbsplat::train::StepClock::Wall,
        snapshot_every: if args.view { args.view_every as usize } else { 0 },
        snapshot_request: args.view.then(|| refresh.clone()),
        estimated_peak_bytes: Some(estimated_peak),
    };
    let live = if args.view {
        let cameras = train_names
            .into_iter()
            .zip(&train)
            .map(|(name, v)| (name, v.camera))
            .collect();
        let config = trainer.config();
        let (live, address) = super::live::LiveView::start(
            args.view_port,
            trainer.activated(),
            trainer.step_index(),
            cameras,
            config.sh_degree,
            config.background,
            refresh,
        )?;
        println!("live view at http://{address}/");
        std::io::Write::flush(&mut std::io::stdout())?;
        Some(live)
    } else {
        None
    };
    let last_record = std::cell::RefCell::new(None::<RunReport>);
    let print_event = |event: &TrainEvent| match event {
        TrainEvent::Started {
            train_views,
            test_views,
            width,
            height,
            billboards,
            texture_size,
            ..
        } => println!(
            "{}: {train_views} train / {test_views} test views at {width}x{height}, {billboards} billboards (TS {texture_size}), loaded in {:.1} s, {threads} threads; estimated peak memory {:.0} MB",
            args.scene.display(),
            start.elapsed().as_secs_f64(),
            estimated_peak as f64 / 1e6
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
    let on_event = |event: &TrainEvent| {
        if let Some(live) = &live {
            match event {
                TrainEvent::Step {
                    log,
                    iterations,
                    running_psnr,
                    ..
                } => live.step(log.step, *iterations, log.loss, *running_psnr, log.view),
                TrainEvent::Evaluation { psnr, .. } => live.evaluation(*psnr),
                TrainEvent::Snapshot { step, billboards } => live.snapshot(*step, billboards),
                TrainEvent::Finished(_) | TrainEvent::Stopped { .. } => live.done(),
                _ => {}
            }
        }
        print_event(event)
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
        let lpips = match (&summary.lpips_network, summary.test_lpips) {
            (Some(net), Some(d)) => format!(", LPIPS-{net} {d:.4}"),
            _ => String::new(),
        };
        format!(
            "test PSNR {:.2} dB, SSIM {:.4}{lpips} over {} views",
            summary.test_psnr, summary.test_ssim, summary.test_views
        )
    };
    let scores = match masked_summary(&args.output, &test, &test_masks)? {
        Some((psnr, ssim, n)) => {
            format!("{scores}; masked (over the mask pixels) PSNR {psnr:.2} dB, SSIM {ssim:.4} over {n} views")
        }
        None => scores,
    };
    println!(
        "trained {} steps in {:.1} s ({:.2} it/s): {scores}; {} billboards ({} alive); model {:.2} MB; peak memory {:.0} MB (estimated {:.0} MB)",
        summary.iterations,
        summary.train_seconds,
        summary.iterations as f64 / summary.train_seconds,
        summary.billboards,
        summary.alive,
        summary.model_bytes as f64 / 1e6,
        summary.peak_rss_bytes as f64 / 1e6,
        estimated_peak as f64 / 1e6
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

/// When test views have masks: PSNR and SSIM of the saved model over their mask pixels
/// ([`bbsplat::eval::masked_image_metrics`]), added to `<out>/summary.json` as `masked_test`
/// (beside the whole-image `test_psnr` / `test_ssim`, which are unchanged); returns the means and
/// the number of views measured.
fn masked_summary(
    out: &std::path::Path,
    test: &[TrainView],
    masks: &[Option<Vec<u8>>],
) -> Result<Option<(f64, f64, usize)>> {
    if masks.iter().all(Option::is_none) {
        return Ok(None);
    }
    let model_dir = out.join(bbsplat::train::run::MODEL_DIR);
    let (raw, meta) = super::common::read_model(&model_dir)?;
    let activated = raw.activate();
    let settings = bbsplat::raster::RenderSettings {
        background: glam::Vec3::from_array(meta.background),
        sh_degree: meta.sh_degree,
        ..Default::default()
    };
    let views = test.iter().zip(masks).map(|(v, m)| {
        Ok::<_, bbsplat::scene::SceneError>(bbsplat::eval::EvalView {
            name: "",
            camera: &v.camera,
            rgb: v.rgb.to_f32()?,
            mask: m.as_deref(),
        })
    });
    let mut unread = None;
    let read = bbsplat::eval::until_error(views, &mut unread);
    let report = bbsplat::eval::evaluate_views(&activated.borrowed(), read, &settings, |_, _| {})
        .context("the masked evaluation of the test views")?;
    if let Some(e) = unread {
        return Err(anyhow::Error::new(e).context("the masked evaluation of the test views"));
    }
    let (Some(psnr), Some(ssim)) = (report.mean_masked_psnr, report.mean_masked_ssim) else {
        return Ok(None);
    };
    let n = report.views.iter().filter(|v| v.masked_psnr.is_some()).count();
    let path = out.join(bbsplat::train::run::SUMMARY_FILE);
    let text = bbsplat::file_io::read_text_bounded(&path, bbsplat::file_io::JSON_FILE)?;
    let mut summary: serde_json::Value =
        serde_json::from_str(&text).with_context(|| format!("reading back {}", path.display()))?;
    if let Some(fields) = summary.as_object_mut() {
        fields.insert(
            "masked_test".into(),
            serde_json::json!({
                "psnr": psnr,
                "ssim": ssim,
                "views": n,
                "what": "mean PSNR (dB) and SSIM of the saved model over the pixels of each test view's mask (value at least 128); test_psnr and test_ssim are over whole images",
            }),
        );
    }
    let json = serde_json::to_string_pretty(&summary).context("encoding the summary")?;
    super::common::write_text_atomic(&path, &json).with_context(|| format!("writing {}", path.display()))?;
    Ok(Some((psnr, ssim, n)))
}
