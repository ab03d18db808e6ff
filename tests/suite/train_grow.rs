//! Growth toward a cap (spec §6): +5 % per relocation step, new rows copied from sources drawn
//! ∝ mean alpha with the texel-wise alpha split, zero Adam state for new rows and sources,
//! deterministic across thread counts, bit-exact through a checkpoint across a growth step.

use bbsplat::demo::{DemoConfig, generate};
use bbsplat::model::{RawBillboards, sigmoid};
use bbsplat::raster::SH_FLOATS;
use bbsplat::rng::Rng;
use bbsplat::scene::split::camera_extent;
use bbsplat::train::grow::{growth_target, plan_growth};
use bbsplat::train::{TextureMode, TrainConfig, TrainView, Trainer, group};
use glam::Vec3;
use std::path::Path;

const TS: usize = 4;
const T: usize = TS * TS;

/// 40 billboards on a line with varied alphas, growth toward `cap`.
fn synthetic(cap: usize, mode: TextureMode) -> Trainer {
    let points: Vec<Vec3> = (0..40).map(|i| Vec3::new(i as f32, 0.1 * i as f32, 0.0)).collect();
    let colours: Vec<[f32; 3]> = (0..40).map(|i| [0.02 * i as f32, 0.5, 0.9]).collect();
    let mut model = RawBillboards::from_points(&points, &colours, TS, 3);
    for i in 0..40 {
        for k in 0..T {
            model.alpha_logits[i * T + k] = -3.0 + 0.15 * i as f32 + 0.05 * k as f32;
        }
    }
    let config = TrainConfig {
        seed: 5,
        texture_mode: mode,
        growth_cap: cap,
        ..TrainConfig::default()
    };
    Trainer::new(model, config)
}

#[test]
fn counts_follow_five_percent_steps_up_to_the_cap() {
    let mut tr = synthetic(50, TextureMode::Full);
    let mut counts = vec![tr.model().len()];
    for _ in 0..8 {
        let before = tr.model().len();
        let added = tr.grow();
        assert_eq!(tr.model().len(), before + added);
        counts.push(tr.model().len());
    }
    // ⌊40·1.05⌋ = 42, ⌊42·1.05⌋ = 44, 46, 48, then the cap 50, then nothing.
    assert_eq!(counts, [40, 42, 44, 46, 48, 50, 50, 50, 50]);
    // Every array follows the count.
    let n = tr.model().len();
    assert_eq!(tr.activated().len(), n);
    assert_eq!(tr.model().alpha_logits.len(), n * T);
    assert_eq!(tr.model().colour_logits.len(), 3 * n * T);
    assert_eq!(tr.model().sh.len(), n * SH_FLOATS);
    for g in tr.adam() {
        assert_eq!(g.rows(), n);
    }
    // No growth without a cap above the count.
    let mut off = synthetic(0, TextureMode::Full);
    assert_eq!(off.grow(), 0);
    assert_eq!(off.model().len(), 40);
    assert_eq!(growth_target(40, 1000), 42);
}

#[test]
fn new_rows_are_copies_with_the_split_alpha_and_zero_adam_state() {
    let mut tr = synthetic(1000, TextureMode::Full);
    // Give every row some optimiser state first.
    let demo_views = views_of_line();
    for _ in 0..3 {
        tr.step(&demo_views).unwrap();
    }
    let before_model = tr.model().clone();
    let before_alpha: Vec<f32> = tr.activated().textures.iter().map(|t| t[3]).collect();
    let before_adam = tr.adam().clone();
    // The plan the trainer will draw (same RNG state): sources ∝ mean alpha over all rows.
    let n = tr.model().len();
    let added = tr.grow();
    assert_eq!(added, growth_target(n, 1000) - n);
    let source_of = |d: usize| {
        (0..n)
            .find(|&s| before_model.positions[s] == tr.model().positions[d])
            .expect("a new row copies an existing billboard")
    };
    let sources: Vec<usize> = (n..n + added).map(source_of).collect();
    let m = tr.model();
    for (d, &s) in (n..n + added).zip(&sources) {
        assert_eq!(m.quaternions[d], before_model.quaternions[s]);
        assert_eq!(m.log_scales[d], before_model.log_scales[s]);
        assert_eq!(
            m.sh[d * SH_FLOATS..(d + 1) * SH_FLOATS],
            before_model.sh[s * SH_FLOATS..(s + 1) * SH_FLOATS]
        );
        assert_eq!(
            m.colour_logits[d * 3 * T..(d + 1) * 3 * T],
            before_model.colour_logits[s * 3 * T..(s + 1) * 3 * T]
        );
        assert_eq!(m.alpha_logits[d * T..(d + 1) * T], m.alpha_logits[s * T..(s + 1) * T]);
        // New rows: zero moments and counts in every group.
        for g in tr.adam() {
            let r = g.row_len;
            assert!(g.m[d * r..(d + 1) * r].iter().all(|&x| x == 0.0));
            assert!(g.v[d * r..(d + 1) * r].iter().all(|&x| x == 0.0));
            assert_eq!(g.steps[d], 0);
        }
    }
    for s in 0..n {
        let copies = sources.iter().filter(|&&x| x == s).count();
        let g = &tr.adam()[group::POSITION];
        if copies == 0 {
            // Not a source: unchanged parameters and optimiser state.
            assert_eq!(
                m.alpha_logits[s * T..(s + 1) * T],
                before_model.alpha_logits[s * T..(s + 1) * T]
            );
            assert_eq!(g.m[3 * s..3 * s + 3], before_adam[group::POSITION].m[3 * s..3 * s + 3]);
            continue;
        }
        // Sources: moments zeroed, alpha split so that the copies composite back.
        assert!(g.m[3 * s..3 * s + 3].iter().all(|&x| x == 0.0));
        assert_eq!(g.steps[s], 0);
        for k in 0..T {
            if !m.alpha_mask[k] {
                continue;
            }
            let split = sigmoid(m.alpha_logits[s * T + k]) as f64;
            let recomposed = 1.0 - (1.0 - split).powi(copies as i32 + 1);
            let original = before_alpha[s * T + k] as f64;
            assert!(
                (recomposed - original).abs() < 1e-5,
                "source {s} texel {k}: {recomposed} vs {original}"
            );
        }
    }
    // Sources were drawn ∝ mean alpha: the brightest half of the line supplies most copies.
    let bright = sources.iter().filter(|&&s| s >= n / 2).count();
    assert!(bright * 2 >= sources.len(), "{sources:?}");
}

#[test]
fn growth_sampling_follows_the_weights_and_skips_zero_weights() {
    let mut alpha = vec![0.0f32; 10];
    alpha[3] = 0.1;
    alpha[8] = 0.3;
    let plan = plan_growth(&alpha, 4000, &mut Rng::new(4));
    assert_eq!(plan.moves.len(), 4000);
    assert!(plan.moves.iter().enumerate().all(|(k, &(d, _))| d == 10 + k));
    assert!(plan.moves.iter().all(|&(_, s)| s == 3 || s == 8));
    let n8 = plan.moves.iter().filter(|m| m.1 == 8).count() as f64;
    let ratio = n8 / (4000.0 - n8);
    assert!((2.6..3.4).contains(&ratio), "{ratio}");
    let mut rng = Rng::new(4);
    assert!(plan_growth(&[0.0; 5], 3, &mut rng).is_empty());
    assert_eq!(rng, Rng::new(4), "nothing drawn when no billboard has alpha");
}

#[test]
fn gaussian_mode_splits_the_opacity_of_grown_rows() {
    let mut tr = synthetic(100, TextureMode::Gaussian);
    let n = tr.model().len();
    let before: Vec<f32> = tr.opacity_logits().to_vec();
    let added = tr.grow();
    assert!(added > 0);
    assert_eq!(tr.opacity_logits().len(), n + added);
    for d in n..n + added {
        let s = (0..n)
            .find(|&s| tr.model().positions[s] == tr.model().positions[d])
            .unwrap();
        assert_eq!(tr.opacity_logits()[d], tr.opacity_logits()[s]);
        assert!(tr.opacity_logits()[s] < before[s], "the source's opacity was split");
    }
}

/// Views of a small demo scene (32 px): enough for real steps with growth.
fn views_of_line() -> Vec<TrainView> {
    demo().1
}

fn demo() -> (RawBillboards, Vec<TrainView>, TrainConfig) {
    let demo = DemoConfig {
        resolution: 32,
        train_views: 8,
        test_views: 2,
        points: 300,
        seed: 1,
    };
    let scene = generate(&demo);
    let model = RawBillboards::from_points(&scene.points[..120], &scene.colours[..120], TS, 1);
    let train: Vec<TrainView> = scene.train.iter().map(TrainView::from_demo).collect();
    let cams: Vec<_> = train.iter().map(|v| v.camera).collect();
    let config = TrainConfig {
        iterations: 300,
        background: Vec3::from_array(scene.background),
        seed: 1,
        extent: camera_extent(&cams),
        growth_cap: 400,
        lr_by_run_length: true,
        ..TrainConfig::default()
    };
    (model, train, config)
}

/// Growth runs inside training (steps 100 and 200 of 300) and is deterministic for any thread
/// count, with copies alone and with half the new rows placed on the error.
#[test]
fn growth_in_training_is_deterministic_across_thread_counts() {
    for error_growth in [0.0, 0.5] {
        growth_in_training_is_deterministic(error_growth);
    }
}

fn growth_in_training_is_deterministic(error_growth: f32) {
    let run = |threads| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| {
                let (model, train, config) = demo();
                let config = TrainConfig { error_growth, ..config };
                let mut tr = Trainer::new(model, config);
                let mut grown = Vec::new();
                for _ in 0..220 {
                    let log = tr.step(&train).unwrap();
                    if log.grown > 0 {
                        grown.push((log.step, log.grown));
                    }
                }
                (grown, tr.checkpoint_bytes())
            })
    };
    let (grown, bytes) = run(1);
    // ⌊120·1.05⌋ = 126 after step 100, ⌊126·1.05⌋ = 132 after step 200.
    assert_eq!(grown, [(100, 6), (200, 6)]);
    assert_eq!(run(2), (grown, bytes));
}

/// 150 steps, a checkpoint, 150 more equal 300 straight, across the growth at step 200 and with
/// the growth at step 100 inside the first half; copies alone and half placed on the error.
#[test]
fn resume_across_a_growth_step_is_bit_exact() {
    for error_growth in [0.0, 0.5] {
        resume_across_a_growth_step(error_growth);
    }
}

fn resume_across_a_growth_step(error_growth: f32) {
    let (model, train, config) = demo();
    let config = TrainConfig { error_growth, ..config };
    let mut straight = Trainer::new(model.clone(), config);
    for _ in 0..300 {
        straight.step(&train).unwrap();
    }
    let mut first = Trainer::new(model, config);
    for _ in 0..150 {
        first.step(&train).unwrap();
    }
    assert_eq!(first.model().len(), 126);
    let bytes = first.checkpoint_bytes();
    let mut resumed = Trainer::from_checkpoint_bytes(&bytes, Path::new("mem")).unwrap();
    assert_eq!(resumed.config().growth_cap, 400);
    assert_eq!(resumed.config().error_growth, error_growth);
    for _ in 0..150 {
        resumed.step(&train).unwrap();
    }
    assert_eq!(resumed.model().len(), 132);
    assert_eq!(resumed.checkpoint_bytes(), straight.checkpoint_bytes());
}
