//! The library's training loop (`bbsplat::train::run`): events in order, the same state as
//! stepping by hand, stop requests with a resumable checkpoint, non-finite values stopping the run
//! with a typed error and the last good checkpoint on disk, and the clamp-gradient setting.

use bbsplat::demo::{DemoConfig, generate};
use bbsplat::model::{RawBillboards, logit};
use bbsplat::report::TrainSummary;
use bbsplat::scene::split::camera_extent;
use bbsplat::testing_internals::train::edit_model_unsynced;
use bbsplat::train::run::{CHECKPOINT_FILE, MODEL_DIR, SUMMARY_FILE};
use bbsplat::train::{
    AdamMode, ClampGradient, NonFinite, ParamGroup, RunConfig, RunError, RunOutcome, StopReason, StopSignal,
    TrainConfig, TrainError, TrainEvent, TrainView, Trainer, run,
};
use glam::Vec3;
use std::path::PathBuf;

struct Setup {
    trainer: Trainer,
    train: Vec<TrainView>,
    test: Vec<TrainView>,
}

/// A small demo scene (24 px, 6 train / 2 test views, 150 billboards of TS 4) and a trainer for
/// a run of `iterations` steps.
fn setup(iterations: usize, tweak: impl Fn(TrainConfig) -> TrainConfig) -> Setup {
    let scene = generate(&DemoConfig {
        resolution: 24,
        train_views: 6,
        test_views: 2,
        points: 150,
        seed: 4,
    });
    let train: Vec<TrainView> = scene.train.iter().map(TrainView::from_demo).collect();
    let test: Vec<TrainView> = scene.test.iter().map(TrainView::from_demo).collect();
    let model = RawBillboards::from_points(&scene.points, &scene.colours, 4, 4);
    let cameras: Vec<_> = train.iter().map(|v| v.camera).collect();
    let config = TrainConfig {
        iterations,
        seed: 4,
        background: Vec3::from_array(scene.background),
        extent: camera_extent(&cameras),
        ..TrainConfig::default()
    };
    Setup {
        trainer: Trainer::new(model, tweak(config)),
        train,
        test,
    }
}

fn temp_dir(tag: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("bbsplat-run-{tag}-{}", std::process::id()));
    std::fs::remove_dir_all(&dir).ok();
    dir
}

/// A compact trace of the events: kind and step.
fn trace(event: &TrainEvent) -> String {
    match event {
        TrainEvent::Started { step, .. } => format!("start@{step}"),
        TrainEvent::Step { log, .. } => format!("step@{}", log.step),
        TrainEvent::Evaluation { step, views, .. } => format!("eval@{step}/{views}"),
        TrainEvent::Checkpoint { step, .. } => format!("ckpt@{step}"),
        TrainEvent::ModelSaved { .. } => "model".into(),
        TrainEvent::Stopped { step, .. } => format!("stopped@{step}"),
        TrainEvent::Record(_) => "record".into(),
        TrainEvent::Finished(_) => "finished".into(),
        TrainEvent::Warning(w) => format!("warning {w}"),
        other => format!("{other:?}"),
    }
}

#[test]
fn a_run_reports_its_events_in_order_and_equals_stepping_by_hand() {
    let Setup {
        mut trainer,
        train,
        test,
    } = setup(12, |c| c);
    let Setup {
        trainer: mut manual, ..
    } = setup(12, |c| c);
    let dir = temp_dir("events");
    let config = RunConfig {
        eval_every: 5,
        eval_views: 1,
        save_every: 4,
        output: Some(dir.clone()),
        scene: "demo".into(),
        ..RunConfig::default()
    };
    let mut events = Vec::new();
    let outcome = run(&mut trainer, &train, &test, &config, &StopSignal::new(), |e| {
        events.push(trace(e))
    })
    .unwrap();
    let mut expected = vec!["start@0".to_string()];
    for s in 1..=12 {
        expected.push(format!("step@{s}"));
        if s % 4 == 0 {
            expected.push(format!("ckpt@{s}"));
        }
        if s % 5 == 0 {
            expected.push(format!("eval@{s}/1"));
        }
    }
    expected.extend(["ckpt@12".into(), "model".into(), "record".into(), "finished".into()]);
    assert_eq!(events, expected);

    for _ in 0..12 {
        manual.step(&train).unwrap();
    }
    assert!(
        trainer.checkpoint_bytes() == manual.checkpoint_bytes(),
        "run ≠ manual steps"
    );
    let RunOutcome::Finished(summary) = outcome else {
        panic!("not finished: {outcome:?}");
    };
    assert_eq!(summary.curve.iter().map(|p| p.step).collect::<Vec<_>>(), [5, 10, 12]);
    assert_eq!(
        (summary.iterations, summary.test_views, summary.scene.as_str()),
        (12, 2, "demo")
    );
    assert!(summary.test_psnr.is_finite() && summary.model_bytes > 0);
    assert!(std::fs::read(dir.join(CHECKPOINT_FILE)).unwrap() == manual.checkpoint_bytes());
    assert!(dir.join(MODEL_DIR).join("point_cloud.ply").exists());
    let text = std::fs::read_to_string(dir.join(SUMMARY_FILE)).unwrap();
    let file: bbsplat::report::SummaryFile = serde_json::from_str(&text).unwrap();
    // JSON keeps the numbers to within the last bit.
    assert_eq!((file.summary.iterations, file.summary.curve.len()), (12, 3));
    assert!((file.summary.test_psnr - summary.test_psnr).abs() < 1e-12);
    assert_eq!(file.settings.clamp_gradient, "exact");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn without_an_output_folder_nothing_is_written_and_the_float_model_is_evaluated() {
    let Setup {
        mut trainer,
        train,
        test,
    } = setup(6, |c| c);
    let config = RunConfig {
        eval_every: 0,
        save_every: 2,
        ..RunConfig::default()
    };
    let mut events = Vec::new();
    let outcome = run(&mut trainer, &train, &test, &config, &StopSignal::new(), |e| {
        events.push(trace(e))
    })
    .unwrap();
    assert!(
        events.iter().all(|e| !e.starts_with("ckpt") && e != "model"),
        "{events:?}"
    );
    let RunOutcome::Finished(summary) = outcome else {
        panic!("not finished");
    };
    assert_eq!(summary.model_bytes, 0);
    // Trainer::evaluate is the mean 8-bit PSNR of the float model over the same views.
    assert_eq!(summary.test_psnr, trainer.evaluate(&test).unwrap());
}

/// A stop request (here raised from the callback after step 5) saves a checkpoint that, run to
/// the end, gives the files of an uninterrupted run; `stop_after` stops at its step.
#[test]
fn a_stop_request_saves_a_checkpoint_that_resumes_bit_for_bit() {
    let straight_dir = temp_dir("straight");
    let resumed_dir = temp_dir("resumed");
    let config = |dir: &PathBuf| RunConfig {
        eval_every: 0,
        output: Some(dir.clone()),
        ..RunConfig::default()
    };
    let Setup {
        mut trainer,
        train,
        test,
    } = setup(10, |c| c);
    run(
        &mut trainer,
        &train,
        &test,
        &config(&straight_dir),
        &StopSignal::new(),
        |_| {},
    )
    .unwrap();

    let Setup { mut trainer, .. } = setup(10, |c| c);
    let stop = StopSignal::new();
    let outcome = run(&mut trainer, &train, &test, &config(&resumed_dir), &stop, |e| {
        if let TrainEvent::Step { log, .. } = e
            && log.step == 5
        {
            stop.request();
        }
    })
    .unwrap();
    let checkpoint = resumed_dir.join(CHECKPOINT_FILE);
    assert_eq!(
        outcome,
        RunOutcome::Stopped {
            step: 5,
            reason: StopReason::Requested,
            checkpoint: Some(checkpoint.clone()),
        }
    );
    assert!(!resumed_dir.join(SUMMARY_FILE).exists());
    let mut resumed = Trainer::load_checkpoint(&checkpoint).unwrap();
    assert_eq!(resumed.step_index(), 5);
    // A signal still raised stops again at once; a fresh one lets the run finish.
    let again = run(&mut resumed, &train, &test, &config(&resumed_dir), &stop, |_| {}).unwrap();
    assert!(matches!(again, RunOutcome::Stopped { step: 5, .. }), "{again:?}");
    let stop_after = RunConfig {
        stop_after: Some(8),
        ..config(&resumed_dir)
    };
    let at_8 = run(&mut resumed, &train, &test, &stop_after, &StopSignal::new(), |_| {}).unwrap();
    assert!(
        matches!(
            at_8,
            RunOutcome::Stopped {
                step: 8,
                reason: StopReason::StopAfter,
                ..
            }
        ),
        "{at_8:?}"
    );
    let end = run(
        &mut resumed,
        &train,
        &test,
        &config(&resumed_dir),
        &StopSignal::new(),
        |_| {},
    )
    .unwrap();
    assert!(matches!(end, RunOutcome::Finished(_)));
    for file in [CHECKPOINT_FILE, "model/point_cloud.ply", "model/texture_alpha.npz"] {
        let (a, b) = (
            std::fs::read(straight_dir.join(file)).unwrap(),
            std::fs::read(resumed_dir.join(file)).unwrap(),
        );
        assert!(a == b, "{file} differs");
    }
    std::fs::remove_dir_all(&straight_dir).ok();
    std::fs::remove_dir_all(&resumed_dir).ok();
}

/// A NaN pixel in one view: the step that draws it is refused (typed error naming the step, the
/// view and the loss), the trainer keeps the state from before that step, and that state is the
/// checkpoint on disk; it loads, equals a clean run stopped at the same step, and continues.
#[test]
fn a_nan_pixel_stops_the_run_with_the_last_good_state_on_disk() {
    const BAD: usize = 3;
    let Setup {
        mut trainer,
        mut train,
        test,
    } = setup(40, |c| c);
    let clean_views = train.clone();
    let mut poisoned = train[BAD].rgb.to_f32().unwrap().into_owned();
    poisoned[100] = f32::NAN;
    train[BAD].rgb = poisoned.into();
    let dir = temp_dir("nan-pixel");
    let config = RunConfig {
        eval_every: 0,
        save_every: 1000,
        output: Some(dir.clone()),
        ..RunConfig::default()
    };
    let mut events = Vec::new();
    let err = run(&mut trainer, &train, &test, &config, &StopSignal::new(), |e| {
        events.push(trace(e))
    })
    .unwrap_err();
    let checkpoint = dir.join(CHECKPOINT_FILE);
    let RunError::Step {
        source: TrainError::NonFinite { step, view, value },
        checkpoint: Some(saved),
    } = &err
    else {
        panic!("unexpected error {err:?}");
    };
    let (step, view) = (*step, *view);
    assert_eq!((view, *value), (BAD, NonFinite::Loss), "{err}");
    assert_eq!(*saved, checkpoint);
    assert!(
        step >= 1 && step <= train.len(),
        "the bad view is drawn within the first epoch: {step}"
    );
    assert_eq!(trainer.step_index(), step - 1, "the bad step was not applied");
    let message = err.to_string();
    assert!(
        message.contains(&format!("step {step}")) && message.contains("loss") && message.contains("not applied"),
        "{message}"
    );
    assert_eq!(events.last().unwrap(), &format!("ckpt@{}", step - 1));

    // The checkpoint is the state before the bad step: a clean run of step − 1 steps.
    let on_disk = Trainer::load_checkpoint(&checkpoint).unwrap();
    let Setup { trainer: mut clean, .. } = setup(40, |c| c);
    for _ in 0..step - 1 {
        clean.step(&clean_views).unwrap();
    }
    assert!(on_disk.checkpoint_bytes() == clean.checkpoint_bytes());
    assert!(trainer.checkpoint_bytes() == clean.checkpoint_bytes());
    // The refused view went back on the stack: with the pixel mended, the next step is the
    // clean run's next step.
    let mut mended = on_disk;
    let log = mended.step(&clean_views).unwrap();
    let clean_log = clean.step(&clean_views).unwrap();
    assert_eq!(log, clean_log);
    assert!(mended.checkpoint_bytes() == clean.checkpoint_bytes());
    std::fs::remove_dir_all(&dir).ok();
}

/// A parameter made non-finite by the optimiser step (an infinite position learning rate): the
/// error names the step and the group, the trainer is past the step, and the checkpoint on disk
/// is still the last one written before (by an earlier slice of the run).
#[test]
fn a_non_finite_parameter_leaves_the_last_checkpoint_untouched() {
    let dir = temp_dir("nan-param");
    let config = RunConfig {
        eval_every: 0,
        output: Some(dir.clone()),
        stop_after: Some(3),
        ..RunConfig::default()
    };
    let Setup {
        mut trainer,
        train,
        test,
    } = setup(20, |c| c);
    run(&mut trainer, &train, &test, &config, &StopSignal::new(), |_| {}).unwrap();
    let good = std::fs::read(dir.join(CHECKPOINT_FILE)).unwrap();

    let Setup { mut trainer, .. } = setup(20, |c| TrainConfig {
        lr_scales: bbsplat::train::LearningRateScales {
            position: f32::INFINITY,
            ..c.lr_scales
        },
        ..c
    });
    let config = RunConfig {
        save_every: 1,
        stop_after: None,
        ..config
    };
    let err = run(&mut trainer, &train, &test, &config, &StopSignal::new(), |_| {}).unwrap_err();
    assert!(
        matches!(
            &err,
            RunError::Step {
                source: TrainError::NonFinite {
                    step: 1,
                    value: NonFinite::Parameter(ParamGroup::Positions),
                    ..
                },
                checkpoint: None,
            }
        ),
        "{err:?}"
    );
    assert!(
        err.to_string().contains("positions") && err.to_string().contains("was applied"),
        "{err}"
    );
    assert_eq!(trainer.step_index(), 1);
    assert!(
        std::fs::read(dir.join(CHECKPOINT_FILE)).unwrap() == good,
        "checkpoint overwritten"
    );
    assert_eq!(
        Trainer::load_checkpoint(dir.join(CHECKPOINT_FILE))
            .unwrap()
            .step_index(),
        3
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// A NaN written into a parameter: `run` refuses to start and names the group; written into the
/// raw parameters alone (the activated copy the step renders left finite), `Trainer::step`
/// applies its step and then names the group.
#[test]
fn a_nan_parameter_is_named_by_run_and_by_step() {
    let Setup {
        mut trainer,
        train,
        test,
    } = setup(20, |c| c);
    trainer.edit_model(|m| m.quaternions[7][2] = f32::NAN);
    let dir = temp_dir("nan-start");
    let config = RunConfig {
        output: Some(dir.clone()),
        ..RunConfig::default()
    };
    let err = run(&mut trainer, &train, &test, &config, &StopSignal::new(), |_| {}).unwrap_err();
    assert!(
        matches!(
            err,
            RunError::NonFiniteStart {
                step: 0,
                group: ParamGroup::Quaternions
            }
        ),
        "{err:?}"
    );
    assert!(err.to_string().contains("quaternions"), "{err}");
    assert!(!dir.exists(), "nothing written");

    let Setup { mut trainer, .. } = setup(20, |c| c);
    edit_model_unsynced(&mut trainer, |m| m.sh[5 * 48 + 1] = f32::NAN);
    let err = trainer.step(&train).unwrap_err();
    assert!(
        matches!(
            err,
            TrainError::NonFinite {
                step: 1,
                value: NonFinite::Parameter(ParamGroup::Sh),
                ..
            }
        ),
        "{err:?}"
    );
    assert_eq!(trainer.non_finite_parameter(), Some(ParamGroup::Sh));
}

/// A NaN written into an alpha or a colour logit (of the raw parameters alone, as the optimiser
/// step writes it before the check) is named after the step that applied it, in
/// dense mode (where the texture step checks the logits as it writes them and the parameter
/// check relies on it) and in row-sparse mode (where the whole arrays are scanned).
#[test]
fn a_nan_texture_logit_is_named_after_the_step() {
    for adam in [AdamMode::Dense, AdamMode::Sparse] {
        for (alpha, group) in [(true, ParamGroup::AlphaTextures), (false, ParamGroup::ColourTextures)] {
            let Setup { mut trainer, train, .. } = setup(20, |c| TrainConfig { adam, ..c });
            // Billboard 6's texel 5 (its blue channel for colour; planar rows).
            let t = trainer.model().texture_size * trainer.model().texture_size;
            edit_model_unsynced(&mut trainer, |m| {
                if alpha {
                    m.alpha_logits[6 * t + 5] = f32::NAN;
                } else {
                    m.colour_logits[6 * 3 * t + 2 * t + 5] = f32::NAN;
                }
            });
            let err = trainer.step(&train).unwrap_err();
            assert!(
                matches!(
                    err,
                    TrainError::NonFinite {
                        step: 1,
                        value: NonFinite::Parameter(g),
                        ..
                    } if g == group
                ),
                "{adam:?} {group:?}: {err:?}"
            );
        }
    }
}

/// The clamp gradient: with every alpha texel at 0.999 (above the 0.99 clamp) and the
/// regularisers off, the first step's alpha gradient (read from Adam's first moments) differs
/// between the settings and reaches fewer texels with the exact gradient (only texels with a
/// sample below the clamp, where a masked corner texel mixes in); the colour gradient, which does
/// not go through the clamp, is the same bit for bit. With no texel above the clamp the two
/// settings train bit-identically. The setting survives a checkpoint.
#[test]
fn the_clamp_gradient_setting_changes_the_update_only_where_the_clamp_is_active() {
    use bbsplat::train::group;
    let train_with = |clamp: ClampGradient, alpha: Option<f32>, steps: usize| {
        let Setup { mut trainer, train, .. } = setup(64, |c| TrainConfig {
            clamp_gradient: clamp,
            texture_reg_weight: 0.0,
            opacity_reg_weight: 0.0,
            relocate: false,
            ..c
        });
        if let Some(a) = alpha {
            let mask = trainer.model().alpha_mask.clone();
            let mut model = trainer.model().clone();
            for (k, x) in model.alpha_logits.iter_mut().enumerate() {
                if mask[k % mask.len()] {
                    *x = logit(a);
                }
            }
            trainer = Trainer::new(model, *trainer.config());
        }
        for _ in 0..steps {
            trainer.step(&train).unwrap();
        }
        trainer
    };
    let exact = train_with(ClampGradient::Exact, Some(0.999), 1);
    let through = train_with(ClampGradient::PassThrough, Some(0.999), 1);
    let support = |t: &Trainer| -> Vec<bool> { t.adam()[group::ALPHA].m.iter().map(|&m| m != 0.0).collect() };
    let (s_exact, s_through) = (support(&exact), support(&through));
    let count = |s: &[bool]| s.iter().filter(|&&x| x).count();
    eprintln!(
        "alpha texels with a gradient: exact {}, straight-through {} of {}",
        count(&s_exact),
        count(&s_through),
        s_exact.len()
    );
    assert!(
        s_exact.iter().zip(&s_through).all(|(&e, &t)| !e || t),
        "every texel the exact gradient reaches, straight-through reaches"
    );
    // Measured: 527 against 594 of 2400 (most sampled texels also have a sample below the clamp
    // at TS 4), and the first moments differ on 296 texels.
    let differ = (exact.adam()[group::ALPHA].m.iter())
        .zip(&through.adam()[group::ALPHA].m)
        .filter(|(a, b)| a != b)
        .count();
    eprintln!("alpha first moments differ on {differ} texels");
    assert!(
        count(&s_through) > count(&s_exact) * 11 / 10 && differ > count(&s_through) / 4,
        "exact {} against straight-through {}, {differ} differ",
        count(&s_exact),
        count(&s_through)
    );
    assert!(exact.adam()[group::COLOUR].m == through.adam()[group::COLOUR].m);
    let back = Trainer::from_checkpoint_bytes(&through.checkpoint_bytes(), std::path::Path::new("x")).unwrap();
    assert_eq!(back.config().clamp_gradient, ClampGradient::PassThrough);

    // Initial alphas (peak 0.49): the clamp never acts and the settings agree bit for bit.
    let exact = train_with(ClampGradient::Exact, None, 4);
    let through = train_with(ClampGradient::PassThrough, None, 4);
    assert!(exact.model() == through.model());
}

/// The setting reaches `summary.json` through the run.
#[test]
fn the_summary_records_the_clamp_gradient() {
    let Setup {
        mut trainer,
        train,
        test,
    } = setup(2, |c| TrainConfig {
        clamp_gradient: ClampGradient::PassThrough,
        ..c
    });
    let dir = temp_dir("summary-clamp");
    let config = RunConfig {
        output: Some(dir.clone()),
        ..RunConfig::default()
    };
    run(&mut trainer, &train, &test, &config, &StopSignal::new(), |_| {}).unwrap();
    let text = std::fs::read_to_string(dir.join(SUMMARY_FILE)).unwrap();
    assert!(text.contains(r#""clamp_gradient": "straight-through""#), "{text}");
    std::fs::remove_dir_all(&dir).ok();
}

/// A summary that cannot be written (a folder stands where `summary.json` goes) is a typed error
/// naming the file and saying what is there, the folder is left as it is (not replaced by a
/// renamed file), and no temporary file is left behind.
#[test]
fn an_unwritable_summary_is_an_io_error_naming_the_file() {
    let Setup {
        mut trainer,
        train,
        test,
    } = setup(2, |c| c);
    let dir = temp_dir("summary-blocked");
    std::fs::create_dir_all(dir.join(SUMMARY_FILE)).unwrap();
    let config = RunConfig {
        output: Some(dir.clone()),
        ..RunConfig::default()
    };
    let err = run(&mut trainer, &train, &test, &config, &StopSignal::new(), |_| {}).unwrap_err();
    match &err {
        RunError::Checkpoint(bbsplat::train::checkpoint::CheckpointError::File(
            bbsplat::file_io::FileError::NotWritable { path, kind, .. },
        )) => {
            assert_eq!(path, &dir.join(SUMMARY_FILE), "{err}");
            assert_eq!(*kind, bbsplat::file_io::FileKind::Directory, "{err}");
        }
        other => panic!("expected a refused output, got {other:?}"),
    }
    assert!(err.to_string().contains(SUMMARY_FILE), "{err}");
    assert!(dir.join(SUMMARY_FILE).is_dir());
    let leftovers: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().contains(".tmp"))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn no_training_views_is_a_typed_error() {
    let Setup { mut trainer, test, .. } = setup(2, |c| c);
    let err = run(
        &mut trainer,
        &[],
        &test,
        &RunConfig::default(),
        &StopSignal::new(),
        |_| {},
    )
    .unwrap_err();
    assert!(matches!(err, RunError::NoTrainViews), "{err:?}");
}

/// The cost of the non-finite checks against a step, by default at the size of the `train_step`
/// bench's larger case (192 px, 10 000 billboards, TS 16; `BBSPLAT_MEASURE="96 3000"` for the
/// smaller). Not run by default; run with
/// `cargo test --test suite train_run::measure -- --ignored --nocapture`.
#[test]
#[ignore]
fn measure_non_finite_check_cost() {
    use std::time::Instant;
    let spec = std::env::var("BBSPLAT_MEASURE").unwrap_or_else(|_| "192 10000".into());
    let v: Vec<usize> = spec.split_whitespace().map(|x| x.parse().unwrap()).collect();
    let scene = generate(&DemoConfig {
        resolution: v[0] as u32,
        points: 2 * v[1],
        ..DemoConfig::default()
    });
    let keep = bbsplat::init::fps::farthest_point_sampling(&scene.points, v[1]).unwrap();
    let points: Vec<Vec3> = keep.iter().map(|&i| scene.points[i]).collect();
    let colours: Vec<[f32; 3]> = keep.iter().map(|&i| scene.colours[i]).collect();
    let model = RawBillboards::from_points(&points, &colours, 16, 0);
    let train: Vec<TrainView> = scene.train.iter().map(TrainView::from_demo).collect();
    let cameras: Vec<_> = train.iter().map(|v| v.camera).collect();
    let mut trainer = Trainer::new(
        model,
        TrainConfig {
            iterations: 1000,
            background: Vec3::from_array(scene.background),
            extent: camera_extent(&cameras),
            ..TrainConfig::default()
        },
    );
    for _ in 0..3 {
        trainer.step(&train).unwrap();
    }
    let steps = 10;
    let t0 = Instant::now();
    for _ in 0..steps {
        trainer.step(&train).unwrap();
    }
    let step_ms = t0.elapsed().as_secs_f64() * 1e3 / steps as f64;
    let grads = bbsplat::raster::RenderGradients::zeros(trainer.model().len(), 16);
    let reps = 50;
    let t0 = Instant::now();
    for _ in 0..reps {
        assert_eq!(bbsplat::train::finite::non_finite_gradient(&grads), None);
    }
    let grad_ms = t0.elapsed().as_secs_f64() * 1e3 / reps as f64;
    let t0 = Instant::now();
    for _ in 0..reps {
        assert_eq!(trainer.non_finite_parameter(), None);
    }
    let param_ms = t0.elapsed().as_secs_f64() * 1e3 / reps as f64;
    println!(
        "{spec}: {} threads: step {step_ms:.1} ms (checks included); gradient check {grad_ms:.2} ms, parameter check \
         {param_ms:.2} ms: {:.1} % of a step",
        rayon::current_num_threads(),
        100.0 * (grad_ms + param_ms) / step_ms
    );
}

/// A stop request raised while an intermediate evaluation is due abandons the evaluation (no
/// `Evaluation` event, no curve point) and stops at once with a checkpoint of that step.
#[test]
fn a_stop_request_during_an_evaluation_abandons_it_and_saves_the_checkpoint() {
    let Setup {
        mut trainer,
        train,
        test,
    } = setup(12, |c| c);
    let dir = temp_dir("stop-eval");
    let config = RunConfig {
        eval_every: 5,
        output: Some(dir.clone()),
        ..RunConfig::default()
    };
    let stop = StopSignal::new();
    let mut events = Vec::new();
    let outcome = run(&mut trainer, &train, &test, &config, &stop, |e| {
        // Raised after step 5's work, before its evaluation.
        if matches!(e, TrainEvent::Step { log, .. } if log.step == 5) {
            stop.request();
        }
        events.push(trace(e));
    })
    .unwrap();
    assert!(
        matches!(
            outcome,
            RunOutcome::Stopped {
                step: 5,
                reason: StopReason::Requested,
                ..
            }
        ),
        "{outcome:?}"
    );
    assert!(!events.iter().any(|e| e.starts_with("eval")), "{events:?}");
    assert_eq!(
        events[events.len() - 2..],
        ["ckpt@5".to_string(), "stopped@5".to_string()]
    );
    assert_eq!(
        Trainer::load_checkpoint(dir.join(CHECKPOINT_FILE))
            .unwrap()
            .step_index(),
        5
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// A stop request during the final phase (after the last step: save, re-load, final evaluation)
/// ends the run as `Stopped` at the last step with the model and checkpoint saved and no
/// summary; resuming from that checkpoint finishes with the files of an uninterrupted run.
#[test]
fn a_stop_request_in_the_final_phase_keeps_the_model_and_resumes_to_the_same_files() {
    let dir_a = temp_dir("final-a");
    let dir_b = temp_dir("final-b");
    let config = |dir: &PathBuf| RunConfig {
        eval_every: 0,
        output: Some(dir.clone()),
        ..RunConfig::default()
    };
    let Setup {
        mut trainer,
        train,
        test,
    } = setup(8, |c| c);
    let plain = run(&mut trainer, &train, &test, &config(&dir_a), &StopSignal::new(), |_| {}).unwrap();
    assert!(matches!(plain, RunOutcome::Finished(_)));

    let Setup { mut trainer, .. } = setup(8, |c| c);
    let stop = StopSignal::new();
    let outcome = run(&mut trainer, &train, &test, &config(&dir_b), &stop, |e| {
        if matches!(e, TrainEvent::ModelSaved { .. }) {
            stop.request();
        }
    })
    .unwrap();
    assert!(
        matches!(
            outcome,
            RunOutcome::Stopped {
                step: 8,
                reason: StopReason::Requested,
                ..
            }
        ),
        "{outcome:?}"
    );
    assert!(dir_b.join(MODEL_DIR).join("point_cloud.ply").exists());
    assert!(
        !dir_b.join(SUMMARY_FILE).exists(),
        "no summary for an interrupted final evaluation"
    );
    let mut resumed = Trainer::load_checkpoint(dir_b.join(CHECKPOINT_FILE)).unwrap();
    let finished = run(&mut resumed, &train, &test, &config(&dir_b), &StopSignal::new(), |_| {}).unwrap();
    assert!(matches!(finished, RunOutcome::Finished(_)));
    for file in [
        CHECKPOINT_FILE,
        "model/point_cloud.ply",
        "model/texture_color.npz",
        "model/texture_alpha.npz",
    ] {
        assert!(
            std::fs::read(dir_a.join(file)).unwrap() == std::fs::read(dir_b.join(file)).unwrap(),
            "{file} differs"
        );
    }
    std::fs::remove_dir_all(&dir_a).ok();
    std::fs::remove_dir_all(&dir_b).ok();
}

/// When the model cannot be saved after training (here `model` is a file), the trained state is
/// already in the checkpoint and the error says where.
#[test]
fn a_model_that_cannot_be_saved_leaves_the_trained_state_in_the_checkpoint() {
    let Setup {
        mut trainer,
        train,
        test,
    } = setup(6, |c| c);
    let dir = temp_dir("model-taken");
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join(MODEL_DIR), b"not a model").unwrap();
    let config = RunConfig {
        eval_every: 0,
        output: Some(dir.clone()),
        ..RunConfig::default()
    };
    let err = run(&mut trainer, &train, &test, &config, &StopSignal::new(), |_| {}).unwrap_err();
    let RunError::ModelSave { checkpoint, .. } = &err else {
        panic!("expected ModelSave, got {err:?}");
    };
    assert_eq!(checkpoint, &dir.join(CHECKPOINT_FILE));
    assert!(err.to_string().contains("the trained state is saved in"), "{err}");
    let saved = Trainer::load_checkpoint(checkpoint).unwrap();
    assert_eq!(saved.step_index(), 6);
    assert!(saved.checkpoint_bytes() == trainer.checkpoint_bytes());
    std::fs::remove_dir_all(&dir).ok();
}

/// Warnings given to the run and the run's own land in summary.json.
#[test]
fn every_warning_is_recorded_in_the_summary() {
    let Setup { mut trainer, train, .. } = setup(3, |c| c);
    let dir = temp_dir("warnings");
    let config = RunConfig {
        eval_every: 0,
        output: Some(dir.clone()),
        warnings: vec!["frame 7 skipped: image missing".into()],
        ..RunConfig::default()
    };
    run(&mut trainer, &train, &[], &config, &StopSignal::new(), |_| {}).unwrap();
    let text = std::fs::read_to_string(dir.join(SUMMARY_FILE)).unwrap();
    // Without test views the scores are NaN (null in JSON) and read back as NaN; the curve
    // holds no evaluation.
    let summary: TrainSummary = serde_json::from_str(&text).unwrap();
    assert_eq!(summary.test_views, 0);
    assert!(summary.test_psnr.is_nan() && summary.test_ssim.is_nan() && summary.render_ms_per_frame.is_nan());
    assert!(summary.curve.is_empty(), "{:?}", summary.curve);
    let file: serde_json::Value = serde_json::from_str(&text).unwrap();
    let warnings: Vec<String> = serde_json::from_value(file["warnings"].clone()).unwrap();
    assert_eq!(warnings.len(), 2, "{warnings:?}");
    assert_eq!(warnings[0], "frame 7 skipped: image missing");
    assert!(warnings[1].contains("no test views"), "{warnings:?}");
    std::fs::remove_dir_all(&dir).ok();
}

/// Failure 10: views kept as 8-bit values (3 bytes a pixel, converted per step) train exactly as
/// their float copies (`byte / 255`), bit for bit; a loaded scene view is kept as 8-bit.
#[test]
fn eight_bit_views_train_bit_for_bit_as_their_float_copies() {
    use bbsplat::train::ViewPixels;
    let Setup { train, test, .. } = setup(6, |c| c);
    let quantise = |views: &[TrainView]| -> Vec<Vec<u8>> {
        views
            .iter()
            .map(|v| {
                v.rgb
                    .to_f32()
                    .unwrap()
                    .iter()
                    .map(|x| (x * 255.0).round().clamp(0.0, 255.0) as u8)
                    .collect()
            })
            .collect()
    };
    let with = |bytes: &[Vec<u8>], views: &[TrainView], float: bool| -> Vec<TrainView> {
        bytes
            .iter()
            .zip(views)
            .map(|(b, v)| TrainView {
                camera: v.camera,
                rgb: if float {
                    ViewPixels::F32(b.iter().map(|&x| x as f32 / 255.0).collect())
                } else {
                    ViewPixels::U8(b.clone())
                },
                loss_mask: None,
            })
            .collect()
    };
    let (train_bytes, test_bytes) = (quantise(&train), quantise(&test));
    let mut results = Vec::new();
    for float in [false, true] {
        let (tr, te) = (with(&train_bytes, &train, float), with(&test_bytes, &test, float));
        assert_eq!(tr[0].rgb.bytes(), if float { 4 } else { 1 } * tr[0].rgb.len());
        let Setup { mut trainer, .. } = setup(6, |c| c);
        let config = RunConfig {
            eval_every: 3,
            ..RunConfig::default()
        };
        let outcome = run(&mut trainer, &tr, &te, &config, &StopSignal::new(), |_| {}).unwrap();
        let RunOutcome::Finished(summary) = outcome else {
            panic!()
        };
        results.push((
            trainer.checkpoint_bytes(),
            summary.test_psnr.to_bits(),
            summary.curve[0].psnr.to_bits(),
        ));
    }
    assert!(results[0] == results[1], "8-bit and float views differ");
}

/// An error-growth share outside `[0, 1]` (or NaN) is a typed error of the step, naming the
/// setting; the trainer is unchanged.
#[test]
fn an_out_of_range_error_growth_share_is_a_typed_error() {
    for bad in [-0.5f32, 1.5, f32::NAN] {
        let Setup { mut trainer, train, .. } = setup(4, |c| TrainConfig { error_growth: bad, ..c });
        let before = trainer.checkpoint_bytes();
        let err = trainer.step(&train).unwrap_err();
        assert!(
            matches!(&err, TrainError::InvalidConfig(what) if what.contains("error_growth")),
            "{bad}: {err}"
        );
        assert!(trainer.checkpoint_bytes() == before);
    }
}

/// Failure 3: a texture threshold that is negative, NaN or infinite (which panicked in worker
/// threads, or wrote NaN into the model) is a typed error of the step, naming the setting; the
/// trainer is unchanged.
#[test]
fn an_out_of_range_texture_threshold_is_a_typed_error() {
    for bad in [-5.0f32, f32::NAN, f32::INFINITY] {
        let Setup { mut trainer, train, .. } = setup(4, |c| TrainConfig {
            impact_threshold: bad,
            ..c
        });
        let before = trainer.checkpoint_bytes();
        let err = trainer.step(&train).unwrap_err();
        assert!(
            matches!(&err, TrainError::InvalidConfig(what) if what.contains("texture threshold")),
            "{bad}: {err}"
        );
        assert!(trainer.checkpoint_bytes() == before);
        let err = run(
            &mut trainer,
            &train,
            &[],
            &RunConfig::default(),
            &StopSignal::new(),
            |_| {},
        )
        .unwrap_err();
        assert!(
            matches!(
                err,
                RunError::Step {
                    source: TrainError::InvalidConfig(_),
                    ..
                }
            ),
            "{err}"
        );
    }
}

/// A run's instruction set (`TrainConfig::simd`) changes nothing but its speed: the baseline
/// build and the widest the CPU runs give the same checkpoint bytes and curve, on one thread and
/// on two (each trainer's choice is its own: the two builds run side by side in this process).
/// On a CPU without AVX2 both are the baseline, and the test says so.
#[test]
fn the_instruction_set_of_a_run_changes_no_bit() {
    use bbsplat::cpu::Simd;
    println!("the widest build on this CPU: {:?}", Simd::detect().level());
    let mut results = Vec::new();
    for (simd, threads) in [
        (Simd::BASELINE, 1),
        (Simd::detect(), 1),
        (Simd::BASELINE, 2),
        (Simd::detect(), 2),
    ] {
        let Setup {
            mut trainer,
            train,
            test,
        } = setup(8, |c| TrainConfig { simd, ..c });
        let config = RunConfig {
            eval_every: 4,
            ..RunConfig::default()
        };
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        let outcome = pool
            .install(|| run(&mut trainer, &train, &test, &config, &StopSignal::new(), |_| {}))
            .unwrap();
        let RunOutcome::Finished(summary) = outcome else {
            panic!("the run finishes")
        };
        assert_eq!(trainer.config().simd, simd);
        results.push((
            trainer.checkpoint_bytes(),
            summary.test_psnr.to_bits(),
            summary.curve.len(),
        ));
    }
    assert!(
        results.iter().all(|r| *r == results[0]),
        "the builds or thread counts differ"
    );
}
