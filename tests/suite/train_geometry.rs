//! The geometry regularisers in training: off (weight 0, or not yet started) changes no bit of a
//! run; on, they change it, report their values, and stay deterministic across thread counts
//! and through a checkpoint.

use super::train_demo::run;
use bbsplat::demo::{DemoConfig, generate};
use bbsplat::model::RawBillboards;
use bbsplat::scene::split::camera_extent;
use bbsplat::train::geometry::GeometryRegularisers;
use bbsplat::train::{TrainConfig, TrainView, Trainer};
use glam::Vec3;
use std::path::PathBuf;

fn demo() -> DemoConfig {
    DemoConfig {
        resolution: 32,
        train_views: 12,
        test_views: 4,
        points: 400,
        seed: 2,
    }
}

fn with(geometry: GeometryRegularisers) -> impl Fn(TrainConfig) -> TrainConfig {
    move |c| TrainConfig { geometry, ..c }
}

const ON: GeometryRegularisers = GeometryRegularisers {
    lambda_normal: 0.05,
    lambda_distortion: 100.0,
    normal_from: 0.0,
    distortion_from: 0.0,
};

/// Weights 0 (with any start), or weights given but starting after the run's end: the model,
/// Adam state and RNG are those of the default configuration, bit for bit.
#[test]
fn regularisers_that_are_off_change_no_bit() {
    let steps = 40;
    let plain = run(&demo(), 8, steps, |c| c).3;
    let zero = run(
        &demo(),
        8,
        steps,
        with(GeometryRegularisers {
            normal_from: 0.0,
            distortion_from: 0.0,
            ..GeometryRegularisers::default()
        }),
    )
    .3;
    let later = run(
        &demo(),
        8,
        steps,
        with(GeometryRegularisers {
            normal_from: 1.0,
            distortion_from: 1.0,
            ..ON
        }),
    )
    .3;
    assert_eq!(plain.model(), later.model());
    assert_eq!(plain.model(), zero.model());
}

/// On, they change the model, their values are reported, and the run stays deterministic for
/// any thread count.
#[test]
fn regularisers_that_are_on_train_deterministically() {
    let steps = 30;
    let plain = run(&demo(), 8, steps, |c| c).3;
    let on = |threads| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| run(&demo(), 8, steps, with(ON)).3)
    };
    let (one, two) = (on(1), on(2));
    assert_eq!(one.model(), two.model());
    assert_ne!(one.model(), plain.model());
}

/// A step with both terms on reports positive values that are part of its total loss.
#[test]
fn the_step_log_reports_the_regularisers() {
    let (mut tr, views) = trainer(10, ON);
    let log = tr.step(&views).unwrap();
    assert!(log.normal_reg > 0.0 && log.distortion_reg > 0.0, "{log:?}");
    let parts = log.photometric + log.texture_reg + log.opacity_reg + log.normal_reg + log.distortion_reg;
    assert!((log.loss - parts).abs() <= 1e-12 * log.loss, "{log:?}");
}

/// A trainer for `iterations` steps on the demo scene with `geometry`, and its training views
/// (as `train_demo::run` builds them).
fn trainer(iterations: usize, geometry: GeometryRegularisers) -> (Trainer, Vec<TrainView>) {
    let d = demo();
    let scene = generate(&d);
    let model = RawBillboards::from_points(&scene.points, &scene.colours, 8, d.seed);
    let views: Vec<TrainView> = scene.train.iter().map(TrainView::from_demo).collect();
    let cams: Vec<_> = views.iter().map(|v| v.camera).collect();
    let config = TrainConfig {
        iterations,
        background: Vec3::from_array(scene.background),
        seed: d.seed,
        extent: camera_extent(&cams),
        geometry,
        ..TrainConfig::default()
    };
    (Trainer::new(model, config), views)
}

/// The settings survive a checkpoint, and continuing from it equals not stopping.
#[test]
fn regularised_runs_resume_bit_for_bit() {
    let (mut straight, views) = trainer(20, ON);
    for _ in 0..20 {
        straight.step(&views).unwrap();
    }
    let (mut half, _) = trainer(20, ON);
    for _ in 0..10 {
        half.step(&views).unwrap();
    }
    let mut resumed = Trainer::from_checkpoint_bytes(&half.checkpoint_bytes(), &PathBuf::from("g.ckpt")).unwrap();
    assert_eq!(resumed.config().geometry, ON);
    for _ in 0..10 {
        resumed.step(&views).unwrap();
    }
    assert_eq!(resumed.model(), straight.model());
}

/// Bad settings are refused by the step, naming the setting.
#[test]
fn bad_settings_are_refused() {
    for bad in [
        GeometryRegularisers {
            lambda_normal: -1.0,
            ..ON
        },
        GeometryRegularisers {
            lambda_distortion: f32::NAN,
            ..ON
        },
        GeometryRegularisers { normal_from: 1.5, ..ON },
    ] {
        let problem = TrainConfig {
            geometry: bad,
            ..TrainConfig::default()
        }
        .problem()
        .expect("refused");
        assert!(problem.contains("lambda") || problem.contains("from"), "{problem}");
    }
}
