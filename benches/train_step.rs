//! One whole training step (render, loss, backward, regularisers, Adam, re-activation) on the
//! demo scene (`step/96px/3000`, `step/192px/10000`) and on the trained-like scene of
//! `bbsplat::billboards::trained_like` (`step/trained/400/10000`: the object preset, whose
//! per-pixel work matches a trained lego state at 400×400; `docs/benchmarks.md`), and the
//! row-sparse Adam update on its own, and the texture step on its own (`texture_step/dense/10000`:
//! both texture groups of 10 000 billboards at TS = 16, dense, as every step of a run does;
//! `texture_step/pair/10000`: the same two groups chunk by chunk, as the trainer steps them).
//!
//! `cargo bench --features bench --bench train_step` (all), or e.g. `cargo bench --features bench --bench train_step -- 'step/96px'`.
//!
//! The step's cost depends on the schedule: textures train only from 1/64 of the run on and the
//! SH degree rises every 1/32. Each timed batch of `iters` steps therefore starts from a fresh
//! trainer on a run of `16·iters + 64` steps and first runs, untimed, the steps up to 3/32 of the
//! run, so every timed step has textures on and SH degree 3 (as in most of a real run).
use bbsplat::demo::{DemoConfig, generate};
use bbsplat::init::fps::farthest_point_sampling;
use bbsplat::model::RawBillboards;
use bbsplat::scene::split::camera_extent;
use bbsplat::train::adam::{AdamGroup, AdamParams};
use bbsplat::train::street::{kept_share, street};
use bbsplat::train::texture_step::{GroupStep, RowSelection, step_texture_group, step_texture_pair};
use bbsplat::train::{AdamMode, TrainConfig, TrainView, Trainer};
use criterion::{BenchmarkId, Criterion, Throughput, black_box, criterion_group, criterion_main};
use glam::Vec3;
use std::time::{Duration, Instant};

/// One step. If `Trainer::step` returns a `Result`, append `.expect("training step")` here.
fn step(trainer: &mut Trainer, views: &[TrainView]) {
    black_box(trainer.step(views).expect("the demo views match their cameras"));
}

struct Setup {
    model: RawBillboards,
    views: Vec<TrainView>,
    config: TrainConfig,
}

/// The `bbsplat demo` scene at `resolution` with `billboards` billboards (FPS of the surface
/// points), TS = 16, SH degree 3.
fn demo_setup(resolution: u32, billboards: usize) -> Setup {
    let scene = generate(&DemoConfig {
        resolution,
        points: billboards * 2,
        ..DemoConfig::default()
    });
    let keep = farthest_point_sampling(&scene.points, billboards).expect("enough points");
    let points: Vec<Vec3> = keep.iter().map(|&i| scene.points[i]).collect();
    let colours: Vec<[f32; 3]> = keep.iter().map(|&i| scene.colours[i]).collect();
    let model = RawBillboards::from_points(&points, &colours, 16, 0);
    let views: Vec<TrainView> = scene
        .train
        .iter()
        .map(|v| TrainView {
            camera: v.camera,
            rgb: v.rgb.clone().into(),
            loss_mask: None,
        })
        .collect();
    let cameras: Vec<_> = views.iter().map(|v| v.camera).collect();
    let config = TrainConfig {
        iterations: 0,
        sh_degree: 3,
        background: Vec3::from_array(scene.background),
        seed: 0,
        extent: camera_extent(&cameras),
        ..TrainConfig::default()
    };
    Setup { model, views, config }
}

/// The trained-like object scene as a model to train, with one view
/// ([`bbsplat::train::trained_like_case::trained_like_case`]).
fn trained_like_setup(size: u32, billboards: usize) -> Setup {
    let (model, views, config) = bbsplat::train::trained_like_case::trained_like_case(size, billboards);
    Setup { model, views, config }
}

fn train_step(c: &mut Criterion) {
    let mut group = c.benchmark_group("step");
    group
        .sample_size(10)
        .warm_up_time(Duration::from_secs(2))
        .measurement_time(Duration::from_secs(8));
    let setups = [
        (format!("96px/{}", 3_000), demo_setup(96, 3_000)),
        (format!("192px/{}", 10_000), demo_setup(192, 10_000)),
        (format!("trained/400/{}", 10_000), trained_like_setup(400, 10_000)),
    ];
    for (name, setup) in &setups {
        group.bench_function(name.as_str(), |b| {
            b.iter_custom(|iters| {
                let iters = iters as usize;
                let config = TrainConfig {
                    iterations: 16 * iters + 64,
                    ..setup.config
                };
                let mut trainer = Trainer::new(setup.model.clone(), config);
                for _ in 0..(3 * config.iterations).div_ceil(32) {
                    step(&mut trainer, &setup.views);
                }
                let t = Instant::now();
                for _ in 0..iters {
                    step(&mut trainer, &setup.views);
                }
                t.elapsed()
            })
        });
    }
    group.finish();
}

/// The "street" scene: `copies` copies of the demo world at `resolution` (`per_copy` billboards
/// each, FPS of its surface points, TS = 16) 20 units apart along x, each with the demo's
/// training views that look across the street (camera centre within 2 of the copy's axis), moved
/// with it. A view sees its own copy and none of the others (the setup prints what share a view
/// keeps), so a step at 10 × 30 000 billboards touches what one at 30 000 does: the scene of
/// a large capture where each photo sees a part.
fn street_setup(resolution: u32, per_copy: usize, copies: usize) -> Setup {
    let one = demo_setup(resolution, per_copy);
    let (model, views) = street(&one.model, &one.views, copies, 20.0, 2.0);
    let cameras: Vec<_> = views.iter().map(|v| v.camera).collect();
    let config = TrainConfig {
        extent: camera_extent(&cameras),
        ..one.config
    };
    eprintln!(
        "street {resolution}px {copies}x{per_copy}: {} views, a view keeps {:.1} % of {} billboards",
        views.len(),
        100.0 * kept_share(&model, &views),
        model.len()
    );
    Setup { model, views, config }
}

/// Training steps on the street scene ([`street_setup`]) at 1024 px: one and ten copies of 30 000
/// billboards, dense and lazy Adam. The target of lazy Adam: ten copies cost at most 1.5 times
/// one copy. Each trainer first takes 110 untimed steps of an 800-step run (every view once, so
/// that every row's storage has been touched, and past 3/32 of the run: textures on, SH degree
/// 3), then the timed steps continue the same run (relocation every 100 steps included, as in a
/// real run).
fn street_step(c: &mut Criterion) {
    let mut group = c.benchmark_group("street");
    group
        .sample_size(10)
        .warm_up_time(Duration::from_secs(2))
        .measurement_time(Duration::from_secs(12));
    for copies in [1usize, 10] {
        let setup = street_setup(1024, 30_000, copies);
        for adam in [AdamMode::Dense, AdamMode::Lazy] {
            let name = format!(
                "1024px/{copies}x30000/{}",
                if adam == AdamMode::Dense { "dense" } else { "lazy" }
            );
            let config = TrainConfig {
                iterations: 800,
                adam,
                ..setup.config
            };
            let mut trainer = Trainer::new(setup.model.clone(), config);
            for _ in 0..110 {
                step(&mut trainer, &setup.views);
            }
            group.bench_function(name.as_str(), |b| {
                b.iter_custom(|iters| {
                    let t = Instant::now();
                    for _ in 0..iters {
                        step(&mut trainer, &setup.views);
                    }
                    t.elapsed()
                })
            });
        }
    }
    group.finish();
}

fn adam(c: &mut Criterion) {
    let mut group = c.benchmark_group("adam");
    let rows = 1_000;
    // Row lengths of the trainer's groups: position, SH rest, alpha TS=16, colour TS=16.
    for row_len in [3usize, 45, 256, 768] {
        let mut opt = AdamGroup::new(rows, row_len);
        let mut params = vec![0.5f32; rows * row_len];
        let grads: Vec<f32> = (0..rows * row_len).map(|i| ((i % 17) as f32 - 8.0) * 1e-3).collect();
        let hp = AdamParams::default();
        group.throughput(Throughput::Elements((rows * row_len) as u64));
        group.bench_function(BenchmarkId::new("step_row_x1000", row_len), |b| {
            b.iter(|| {
                for r in 0..rows {
                    let span = r * row_len..(r + 1) * row_len;
                    opt.step_row(r, &mut params[span.clone()], &grads[span], 1e-3, &hp);
                }
            })
        });
    }
    group.finish();
}

/// The texture step of one training step on 10 000 billboards at TS = 16: the alpha group, then
/// the colour group (Adam, the sigmoid chain and re-activation over 10.24 million logits).
fn texture_step(c: &mut Criterion) {
    let mut group = c.benchmark_group("texture_step");
    group.sample_size(20);
    let (rows, texels) = (10_000usize, 256usize);
    let mut alpha = AdamGroup::new(rows, texels);
    let mut colour = AdamGroup::new(rows, 3 * texels);
    let mut alpha_logits: Vec<f32> = (0..rows * texels).map(|i| ((i % 29) as f32 - 14.0) * 0.3).collect();
    let mut colour_logits: Vec<f32> = (0..rows * 3 * texels).map(|i| ((i % 31) as f32 - 15.0) * 0.2).collect();
    let mut activated = vec![[0.5f32; 4]; rows * texels];
    let grads0: Vec<[f32; 4]> = (0..rows * texels)
        .map(|i| [0, 1, 2, 3].map(|c| (((i * 4 + c) % 17) as f32 - 8.0) * 1e-3))
        .collect();
    let mut grads = grads0.clone();
    let mask = vec![true; texels];
    let hp = AdamParams::default();
    group.throughput(Throughput::Elements((rows * 4 * texels) as u64));
    group.bench_function(BenchmarkId::new("dense", rows), |b| {
        b.iter(|| {
            grads.copy_from_slice(&grads0);
            alpha.global_step += 1;
            colour.global_step += 1;
            step_texture_group(
                &mut alpha,
                &mut alpha_logits,
                &mut activated,
                &mut grads,
                3..4,
                Some(&mask),
                RowSelection::Dense,
                None,
                1e-3,
                &hp,
                true,
                bbsplat::cpu::Simd::detect(),
            );
            step_texture_group(
                &mut colour,
                &mut colour_logits,
                &mut activated,
                &mut grads,
                0..3,
                None,
                RowSelection::Dense,
                None,
                1e-3,
                &hp,
                true,
                bbsplat::cpu::Simd::detect(),
            );
        })
    });
    group.bench_function(BenchmarkId::new("pair", rows), |b| {
        b.iter(|| {
            grads.copy_from_slice(&grads0);
            alpha.global_step += 1;
            colour.global_step += 1;
            step_texture_pair(
                GroupStep {
                    group: &mut alpha,
                    logits: &mut alpha_logits,
                    channels: 3..4,
                    mask: Some(&mask),
                    lr: 1e-3,
                },
                GroupStep {
                    group: &mut colour,
                    logits: &mut colour_logits,
                    channels: 0..3,
                    mask: None,
                    lr: 1e-3,
                },
                &mut activated,
                &mut grads,
                RowSelection::Dense,
                None,
                &hp,
                true,
                bbsplat::cpu::Simd::detect(),
            )
        })
    });
    group.finish();
}

criterion_group!(benches, train_step, street_step, adam, texture_step);
criterion_main!(benches);
