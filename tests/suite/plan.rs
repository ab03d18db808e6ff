//! `bbsplat::plan`: the library's plan is the command line's. A scene trained through
//! [`TrainPlan`] with a request that fixes only the length gives the same model files, bit for
//! bit, as `bbsplat train` with only `--iterations`; the automatic choices are the ones the
//! summary records; bad requests are refused naming the setting.

use super::cli::{export_demo, run_ok, temp, write_tiny_blender_scene};
use bbsplat::plan::{InitMethod, PlanError, RunLength, TrainPlan, TrainRequest};
use bbsplat::report::RunReport;
use bbsplat::scene::LoadOptions;
use bbsplat::train::{RunConfig, RunOutcome, StopSignal, TrainView};
use std::path::Path;

const STEPS: usize = 40;

/// Trains `data` through the library with the default request of `STEPS` steps into `out`;
/// returns the plan.
fn train_through_the_library(data: &Path, out: &Path) -> TrainPlan {
    let options = LoadOptions {
        print_warnings: false,
        ..LoadOptions::default()
    };
    let (scene, background) = bbsplat::load_with_data_background(data, &options).unwrap();
    let request = TrainRequest {
        length: RunLength::Steps(STEPS),
        ..TrainRequest::default()
    };
    let plan = TrainPlan::new(&scene, Some(&background), &request).unwrap();
    let (model, _) = plan.init_model(&scene).unwrap();
    let mut trainer = plan.trainer(model);
    let (train, test) = (TrainView::from_views(&scene.train), TrainView::from_views(&scene.test));
    let settings = RunConfig {
        eval_every: 0,
        output: Some(out.to_path_buf()),
        ..plan.run_config()
    };
    let outcome = bbsplat::run(&mut trainer, &train, &test, &settings, &StopSignal::new(), |_| {}).unwrap();
    assert!(matches!(outcome, RunOutcome::Finished(_)), "{outcome:?}");
    plan
}

/// Trains `data` with `bbsplat train`, no flag but the length (and quiet, no evaluation).
fn train_through_the_cli(data: &Path, out: &Path) {
    let steps = STEPS.to_string();
    run_ok(&[
        "train",
        data.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--iterations",
        &steps,
        "--eval-every",
        "0",
        "--quiet",
    ]);
}

fn assert_same_model_and_choices(data: &Path, root: &Path, expected_choices: &[&str]) {
    let (cli, lib) = (root.join("cli"), root.join("lib"));
    train_through_the_cli(data, &cli);
    let plan = train_through_the_library(data, &lib);
    let settings: Vec<&str> = plan.choices.iter().map(|c| c.setting.as_str()).collect();
    assert_eq!(settings, expected_choices);
    for file in [
        "point_cloud.ply",
        "texture_color.npz",
        "texture_alpha.npz",
        "bbsplat.json",
    ] {
        let (a, b) = (cli.join("model").join(file), lib.join("model").join(file));
        let (a, b) = (std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap());
        assert!(a == b, "{file} differs between the command line and the library");
    }
    let summary: RunReport =
        serde_json::from_str(&std::fs::read_to_string(cli.join(bbsplat::train::run::SUMMARY_FILE)).unwrap()).unwrap();
    assert_eq!(
        summary.automatic, plan.choices,
        "the summary records the plan's choices"
    );
}

/// A COLMAP scene with SfM points (the exported demo): points + shell, growth by copies.
#[test]
fn the_library_plan_and_the_command_line_train_the_same_colmap_model() {
    let root = temp("plan-colmap");
    let data = export_demo(&root, 32, 300);
    assert_same_model_and_choices(
        &data,
        &root,
        &[
            "background",
            "billboards",
            "growth-cap",
            "error-growth",
            "lr-scale",
            "init",
        ],
    );
    std::fs::remove_dir_all(&root).ok();
}

/// A NeRF-synthetic scene with alpha: white background, visual-hull initialisation, growth on
/// the error.
#[test]
fn the_library_plan_and_the_command_line_train_the_same_hull_model() {
    let root = temp("plan-hull");
    let data = root.join("data");
    write_tiny_blender_scene(&data, true);
    assert_same_model_and_choices(
        &data,
        &root,
        &[
            "background",
            "billboards",
            "growth-cap",
            "error-growth",
            "lr-scale",
            "init",
        ],
    );
    let options = LoadOptions {
        print_warnings: false,
        ..LoadOptions::default()
    };
    let (scene, background) = bbsplat::load_with_data_background(&data, &options).unwrap();
    let plan = TrainPlan::new(&scene, Some(&background), &TrainRequest::default()).unwrap();
    let value = |setting: &str| {
        plan.choices
            .iter()
            .find(|c| c.setting == setting)
            .unwrap()
            .value
            .clone()
    };
    assert_eq!(
        (value("background"), value("init"), value("error-growth")),
        ("white".into(), "hull".into(), "1".into())
    );
    std::fs::remove_dir_all(&root).ok();
}

/// What the request fixes is not chosen, and is used as given.
#[test]
fn fixed_settings_are_not_chosen() {
    let root = temp("plan-fixed");
    let data = root.join("data");
    write_tiny_blender_scene(&data, false);
    let options = LoadOptions {
        print_warnings: false,
        ..LoadOptions::default()
    };
    let (scene, _) = bbsplat::load_with_data_background(&data, &options).unwrap();
    let request = TrainRequest {
        length: RunLength::Minutes(2.0),
        billboards: Some(77),
        growth_cap: Some(0),
        error_growth: Some(0.25),
        lr_scales: Some(bbsplat::train::LearningRateScales::uniform(2.0)),
        init: InitMethod::Random,
        ..TrainRequest::default()
    };
    let plan = TrainPlan::new(&scene, None, &request).unwrap();
    assert!(plan.choices.is_empty(), "{:?}", plan.choices);
    assert_eq!(
        (plan.billboards, plan.config.growth_cap, plan.config.error_growth),
        (77, 0, 0.25)
    );
    assert!(!plan.config.lr_by_run_length);
    assert_eq!(plan.config.lr_scales.position, 2.0);
    assert_eq!(plan.time_plan.map(|p| p.budget_seconds), Some(120.0));
    assert_eq!(plan.init_model(&scene).unwrap().0.len(), 77);
    // Left open, the learning rates follow the run length.
    let open = TrainPlan::new(&scene, None, &TrainRequest::default()).unwrap();
    assert!(open.config.lr_by_run_length);
    assert_eq!(open.time_plan, None);
    assert_eq!(open.config.iterations, bbsplat::plan::DEFAULT_STEPS);
    std::fs::remove_dir_all(&root).ok();
}

/// Each setting out of range is refused, named as its flag.
#[test]
fn requests_out_of_range_are_refused_naming_the_setting() {
    let bad: [(&str, TrainRequest); 10] = [
        (
            "texture-size",
            TrainRequest {
                texture_size: 1,
                ..TrainRequest::default()
            },
        ),
        (
            "texture-size",
            TrainRequest {
                texture_size: 4096,
                ..TrainRequest::default()
            },
        ),
        (
            "billboards",
            TrainRequest {
                billboards: Some(0),
                ..TrainRequest::default()
            },
        ),
        (
            "sh-degree",
            TrainRequest {
                sh_degree: 4,
                ..TrainRequest::default()
            },
        ),
        (
            "iterations",
            TrainRequest {
                length: RunLength::Steps(0),
                ..TrainRequest::default()
            },
        ),
        (
            "minutes",
            TrainRequest {
                length: RunLength::Minutes(f64::NAN),
                ..TrainRequest::default()
            },
        ),
        (
            "error-growth",
            TrainRequest {
                error_growth: Some(1.5),
                ..TrainRequest::default()
            },
        ),
        (
            "texture-threshold",
            TrainRequest {
                texture_threshold: -1.0,
                ..TrainRequest::default()
            },
        ),
        (
            "hull-resolution",
            TrainRequest {
                hull_resolution: 1,
                ..TrainRequest::default()
            },
        ),
        (
            "lr-scale",
            TrainRequest {
                lr_scales: Some(bbsplat::train::LearningRateScales::uniform(f32::INFINITY)),
                ..TrainRequest::default()
            },
        ),
    ];
    for (setting, request) in bad {
        let err: PlanError = request.check().unwrap_err();
        assert_eq!(err.setting, setting, "{err}");
        assert!(err.to_string().starts_with(setting), "{err}");
    }
    assert_eq!(TrainRequest::default().check(), Ok(()));
}
