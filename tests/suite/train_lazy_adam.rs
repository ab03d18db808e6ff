//! Lazy Adam (`AdamMode::Lazy`, `bbsplat::train::lazy_adam`): the closed-form catch-up equals
//! dense Adam's zero-gradient steps; training with it equals dense training where the algebra
//! says it should (the opacity regulariser off); it is deterministic across thread counts; the
//! rows it works on are exactly those the renderer keeps.

use bbsplat::demo::{DemoConfig, generate};
use bbsplat::model::RawBillboards;
use bbsplat::raster::RenderSettings;
use bbsplat::raster::preprocess::{kept_rows_into, preprocess};
use bbsplat::rng::Rng;
use bbsplat::scene::split::camera_extent;
use bbsplat::train::adam::{AdamGroup, AdamParams, StepFactors};
use bbsplat::train::lazy_adam::{LazyLog, MAX_TERMS, Pending, catch_up_row};
use bbsplat::train::regularise::{TextureTerm, regulariser_rows, regulariser_rows_of};
use bbsplat::train::street::{kept_share, street as street_of};
use bbsplat::train::{AdamMode, TrainConfig, TrainView, Trainer};
use glam::Vec3;

/// A row of `len` values after `a` dense steps with random gradients, then `k` dense steps with
/// zero gradient, and the same row brought from step `a` to `a + k` by the catch-up (rates
/// decaying along the run, as the trainer's). Returns the worst error of the parameters relative
/// to the size of their move over the `k` steps, and of the moments relative to their values.
fn catch_up_error(len: usize, a: u64, k: u64, seed: u64, scale_move: f32) -> (f64, f64) {
    let hp = AdamParams::default();
    let mut rng = Rng::new(seed);
    let lr = |t: u64| 0.01 * 0.999f32.powi(t as i32);
    let mut dense = AdamGroup::new(1, len);
    let mut p: Vec<f32> = (0..len).map(|_| rng.range(-2.0, 2.0)).collect();
    let mut log = LazyLog::default();
    for t in 1..=a {
        let g: Vec<f32> = (0..len)
            .map(|_| rng.range(-1.0, 1.0) * 10f32.powf(rng.range(-3.0, 0.0)))
            .collect();
        dense.step_row_global(0, &mut p, &g, lr(t), &hp, t);
        log.record(StepFactors::new(lr(t), &hp, t));
    }
    let (mut m, mut v, mut q) = (dense.m.clone(), dense.v.clone(), p.clone());
    let before = p.clone();
    let zero = vec![0.0f32; len];
    for t in a + 1..=a + k {
        dense.step_row_global(0, &mut p, &zero, lr(t), &hp, t);
        log.record(StepFactors::new(lr(t), &hp, t));
    }
    let pending = log.pending(a, &hp).expect("k > 0 steps are pending");
    let pending = Pending {
        move_size: pending.move_size * scale_move,
        ..pending
    };
    catch_up_row(&mut m, &mut v, &mut q, pending);
    let mut worst_p = 0.0f64;
    let mut worst_moment = 0.0f64;
    for i in 0..len {
        // Against the size of the move, on the values whose move is at least 10⁴ times the
        // rounding of `p` (an ulp at each of the `k` dense steps and the catch-up's one), where
        // that rounding is at most 1e-4 of it; on the others, what is beyond that rounding.
        let moved = (p[i] as f64 - before[i] as f64).abs();
        let rounding = (k + 1) as f64 * f32::EPSILON as f64 * p[i].abs().max(q[i].abs()) as f64;
        let error = (q[i] as f64 - p[i] as f64).abs();
        if moved >= 1e4 * rounding {
            worst_p = worst_p.max(error / moved);
        } else {
            worst_p = worst_p.max((error - rounding).max(0.0) / moved.max(1e-30));
        }
        for (lazy, dense) in [(m[i], dense.m[i]), (v[i], dense.v[i])] {
            let scale = (dense as f64).abs().max(1e-30);
            worst_moment = worst_moment.max((lazy as f64 - dense as f64).abs() / scale);
        }
    }
    (worst_p, worst_moment)
}

/// Measured worst over the cases below (2026-12-03): parameters 1.5e-5 of their move, moments
/// 1.8e-6 of their value (f32 rounding of `k` decays against one power). Tolerances below 10×
/// those.
const MOVE_TOLERANCE: f64 = 1e-4;
const MOMENT_TOLERANCE: f64 = 1e-5;

const CASES: [(u64, u64); 7] = [
    (1, 1),
    (3, 2),
    (20, 5),
    (50, 17),
    (200, 60),
    (10, MAX_TERMS as u64 + 44),
    (400, 900),
];

#[test]
fn the_catch_up_equals_dense_zero_gradient_steps() {
    let (mut worst_p, mut worst_m) = (0.0f64, 0.0f64);
    for (seed, &(a, k)) in CASES.iter().enumerate() {
        let (ep, em) = catch_up_error(64, a, k, seed as u64, 1.0);
        eprintln!("a = {a}, k = {k}: parameters {ep:.2e} of their move, moments {em:.2e}");
        worst_p = worst_p.max(ep);
        worst_m = worst_m.max(em);
    }
    eprintln!("worst: parameters {worst_p:.2e}, moments {worst_m:.2e}");
    assert!(worst_p < MOVE_TOLERANCE, "parameters: {worst_p:e}");
    assert!(worst_m < MOMENT_TOLERANCE, "moments: {worst_m:e}");
}

/// The comparison above fails for a catch-up that moves 1 % too far (so its tolerance is tight
/// enough to see a wrong coefficient) and for one that forgets the steps after the first 5.
#[test]
fn the_catch_up_comparison_catches_a_wrong_move() {
    let (ep, _) = catch_up_error(64, 20, 5, 3, 1.01);
    assert!(ep > MOVE_TOLERANCE, "a 1 % larger move passed: {ep:e}");
    // Forgetting steps: a log that stops recording after 5 of 40 pending steps.
    let hp = AdamParams::default();
    let mut log = LazyLog::default();
    for t in 1..=45u64 {
        log.record(StepFactors::new(0.01, &hp, t));
    }
    let full = log.pending(5, &hp).unwrap().move_size;
    log.factors.truncate(10);
    let short = log.pending(5, &hp).unwrap().move_size;
    assert!((full - short) / full > MOVE_TOLERANCE as f32, "{full} vs {short}");
}

/// Nothing is pending for a row up to date; the decays are β₁ᵏ and β₂ᵏ.
#[test]
fn pending_is_none_when_up_to_date_and_decays_by_the_step_count() {
    let hp = AdamParams::default();
    let mut log = LazyLog::default();
    assert!(log.pending(0, &hp).is_none());
    for t in 1..=7u64 {
        log.record(StepFactors::new(0.1, &hp, t));
    }
    assert!(log.pending(7, &hp).is_none());
    let p = log.pending(4, &hp).unwrap();
    assert_eq!(p.decay1, (0.9f32 as f64).powi(3) as f32);
    assert_eq!(p.decay2, (0.999f32 as f64).powi(3) as f32);
}

/// Two copies of a small demo world 12 apart along x, each with the demo views that look across
/// the row of copies: a view sees its own copy only, so half the texture rows wait each step.
fn street() -> (RawBillboards, Vec<TrainView>, TrainConfig) {
    let scene = generate(&DemoConfig {
        resolution: 32,
        train_views: 16,
        test_views: 1,
        points: 300,
        seed: 4,
    });
    let one = RawBillboards::from_points(&scene.points, &scene.colours, 4, 4);
    let one_views: Vec<TrainView> = scene.train.iter().map(TrainView::from_demo).collect();
    let (model, views) = street_of(&one, &one_views, 2, 12.0, 2.0);
    let cams: Vec<_> = views.iter().map(|v| v.camera).collect();
    let config = TrainConfig {
        iterations: 120,
        seed: 4,
        background: Vec3::from_array(scene.background),
        extent: camera_extent(&cams),
        relocate_every: 10,
        ..TrainConfig::default()
    };
    (model, views, config)
}

/// With the opacity regulariser off (the one term lazy Adam changes), 120 steps of lazy Adam
/// give dense Adam's model, up to the catch-up's rounding: measured worst differences
/// (2026-12-03) 3.8e-6 in a texture logit, 2.4e-7 in a position, 8.3e-7 in an SH coefficient;
/// tolerances about 5× those. Mid-run,
/// some rows are pending (the model and its export differ), so the test is not dense against
/// dense.
#[test]
fn lazy_training_equals_dense_without_the_opacity_regulariser() {
    let (model, views, config) = street();
    let share = kept_share(&model, &views);
    eprintln!("a view keeps {:.1} % of {} billboards", 100.0 * share, model.len());
    assert!(share < 0.6, "the views must leave rows out: {share}");
    let config = TrainConfig {
        opacity_reg_weight: 0.0,
        ..config
    };
    let run = |adam: AdamMode| {
        let mut tr = Trainer::new(model.clone(), TrainConfig { adam, ..config });
        let mut pending_seen = false;
        for _ in 0..config.iterations {
            tr.step(&views).unwrap();
            pending_seen |= tr.export_model() != *tr.model();
        }
        (tr.export_model(), pending_seen)
    };
    let (dense, dense_pending) = run(AdamMode::Dense);
    let (lazy, lazy_pending) = run(AdamMode::Lazy);
    assert!(!dense_pending, "dense Adam has nothing pending");
    assert!(
        lazy_pending,
        "lazy Adam left no row waiting: the comparison would be dense against dense"
    );
    let max_diff = |a: &[f32], b: &[f32]| a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0f32, f32::max);
    let texture =
        max_diff(&dense.alpha_logits, &lazy.alpha_logits).max(max_diff(&dense.colour_logits, &lazy.colour_logits));
    let position = dense
        .positions
        .iter()
        .zip(&lazy.positions)
        .map(|(a, b)| (*a - *b).abs().max_element())
        .fold(0.0f32, f32::max);
    let sh = max_diff(&dense.sh, &lazy.sh);
    eprintln!("lazy against dense: texture logits {texture:.2e}, positions {position:.2e}, SH {sh:.2e}");
    assert!(texture < 2e-5, "texture logits differ by {texture:e}");
    assert!(position < 1.5e-6, "positions differ by {position:e}");
    assert!(sh < 5e-6, "SH differs by {sh:e}");
}

/// The same seed gives the same lazy run on one thread and on two, and a lazy run with the
/// opacity regulariser on (where it differs from dense by design) still learns.
#[test]
fn lazy_training_is_deterministic_across_thread_counts() {
    let (model, views, config) = street();
    let config = TrainConfig {
        adam: AdamMode::Lazy,
        iterations: 60,
        ..config
    };
    let run = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| {
                let mut tr = Trainer::new(model.clone(), config);
                let first = tr.step(&views).unwrap().loss;
                let mut last = first;
                for _ in 1..config.iterations {
                    last = tr.step(&views).unwrap().loss;
                }
                (tr.export_model(), tr.adam().clone(), first, last)
            })
    };
    let (one, two) = (run(1), run(2));
    assert!(one.0 == two.0, "models differ between 1 and 2 threads");
    assert!(one.1 == two.1, "Adam states differ between 1 and 2 threads");
    assert!(one.3 < one.2, "the loss fell: {} -> {}", one.2, one.3);
}

/// The rows lazy Adam brings up to date are those the renderer keeps, on every view of the
/// street and of the demo.
#[test]
fn kept_rows_are_the_rows_preprocess_keeps() {
    let (model, views, _) = street();
    let set = model.activate();
    let mut kept = Vec::new();
    for v in &views {
        kept_rows_into(&set.borrowed(), &v.camera, &mut kept);
        let prepared = preprocess(&set.borrowed(), &v.camera, &RenderSettings::default());
        let expected: Vec<bool> = prepared.iter().map(Option::is_some).collect();
        assert_eq!(kept, expected);
    }
}

/// The regularisers restricted to every row give `regulariser_rows`' bits; restricted to some,
/// the others get nothing.
#[test]
fn regularisers_of_selected_rows() {
    let (model, views, _) = street();
    let set = model.activate();
    let t = model.texture_size * model.texture_size;
    let impact: Vec<f32> = (0..model.len()).map(|i| (i % 7) as f32 * 100.0).collect();
    let alpha0 = vec![0.5f32; t];
    let term = TextureTerm {
        alpha0: &alpha0,
        impact: &impact,
        threshold: 500.0,
        weight: 1e-4,
    };
    let simd = bbsplat::cpu::Simd::detect();
    let (mut all, mut every) = (Vec::new(), Vec::new());
    let a = regulariser_rows(&set.textures, t, Some(term), Some(0.01), &mut all, simd);
    let flags = vec![true; model.len()];
    let b = regulariser_rows_of(&set.textures, t, Some(term), Some(0.01), Some(&flags), &mut every, simd);
    assert_eq!(a, b);
    assert_eq!(all, every);
    let mut kept = Vec::new();
    kept_rows_into(&set.borrowed(), &views[0].camera, &mut kept);
    let mut some = Vec::new();
    regulariser_rows_of(&set.textures, t, Some(term), Some(0.01), Some(&kept), &mut some, simd);
    for (i, (&k, (row, full))) in kept.iter().zip(some.iter().zip(&all)).enumerate() {
        if k {
            assert_eq!(row, full, "row {i}");
        } else {
            assert_eq!(*row, Default::default(), "row {i}");
        }
    }
}
