//! Benchmarks of the geometry stages (ns per call).
//!
//! `cargo bench --features bench --bench geometry -- --warm-up-time 1 --measurement-time 3`
//!
//! Per-billboard stages are timed over a batch of 64 different billboards, per-pixel stages over
//! a 16×16 tile of pixel centres, so each iteration sees varied inputs; criterion's throughput
//! figure (elements/s) gives the time per call.

use bbsplat::camera::Camera;
use bbsplat::rng::Rng;
use bbsplat::stages::ray_plane::{intersect, intersect_vjp};
use bbsplat::stages::rotation::{quat_to_rotation, quat_to_rotation_vjp};
use bbsplat::stages::splat_transform::{
    SplatTransform, project_splat, project_splat_vjp, square_screen_bounds, support_half_side,
};
use criterion::{BenchmarkId, Criterion, Throughput, black_box, criterion_group, criterion_main};
use glam::{Mat3, Vec2, Vec3};

const BATCH: usize = 64;

struct Billboard {
    position: Vec3,
    log_scales: Vec2,
    quaternion: [f32; 4],
}

fn camera() -> Camera {
    Camera::look_at(Vec3::new(0.5, -0.3, -5.0), Vec3::ZERO, Vec3::Y, 800.0, 800.0, 1280, 720)
}

fn billboards(rng: &mut Rng) -> Vec<Billboard> {
    (0..BATCH)
        .map(|_| Billboard {
            position: Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0)),
            log_scales: Vec2::new(rng.range(-3.0, -1.0), rng.range(-3.0, -1.0)),
            quaternion: [
                rng.range(0.0, 1.0),
                rng.range(0.0, 1.0),
                rng.range(0.0, 1.0),
                rng.range(0.0, 1.0),
            ],
        })
        .collect()
}

fn rotation(c: &mut Criterion) {
    let mut rng = Rng::new(1);
    let bs = billboards(&mut rng);
    let d = Mat3::from_cols_array(&[0.3, -0.2, 0.5, 0.1, 0.9, -0.4, 0.7, 0.2, -0.6]);
    let mut g = c.benchmark_group("rotation");
    g.throughput(Throughput::Elements(BATCH as u64));
    g.bench_function("quat_to_rotation", |bench| {
        bench.iter(|| {
            for b in &bs {
                black_box(quat_to_rotation(black_box(b.quaternion)));
            }
        })
    });
    g.bench_function("quat_to_rotation_vjp", |bench| {
        bench.iter(|| {
            for b in &bs {
                black_box(quat_to_rotation_vjp(black_box(b.quaternion), black_box(d)));
            }
        })
    });
    g.finish();
}

fn splat_transform(c: &mut Criterion) {
    let mut rng = Rng::new(2);
    let bs = billboards(&mut rng);
    let cam = camera();
    let d_t = SplatTransform {
        tu: Vec3::new(0.1, -0.2, 0.3),
        tv: Vec3::new(-0.4, 0.5, 0.6),
        tw: Vec3::new(0.7, -0.8, 0.9),
    };
    let transforms: Vec<SplatTransform> = bs
        .iter()
        .filter_map(|b| project_splat(b.position, b.log_scales, b.quaternion, &cam))
        .map(|p| p.transform)
        .collect();
    let mut g = c.benchmark_group("splat_transform");
    g.throughput(Throughput::Elements(BATCH as u64));
    g.bench_function("project_splat", |bench| {
        bench.iter(|| {
            for b in &bs {
                black_box(project_splat(black_box(b.position), b.log_scales, b.quaternion, &cam));
            }
        })
    });
    g.bench_function("project_splat_vjp", |bench| {
        bench.iter(|| {
            for b in &bs {
                black_box(project_splat_vjp(
                    black_box(b.position),
                    b.log_scales,
                    b.quaternion,
                    &cam,
                    &d_t,
                    Vec3::ONE,
                ));
            }
        })
    });
    g.throughput(Throughput::Elements(transforms.len() as u64));
    g.bench_function("square_screen_bounds", |bench| {
        bench.iter(|| {
            for t in &transforms {
                black_box(square_screen_bounds(black_box(t), support_half_side(16)));
            }
        })
    });
    g.finish();
}

fn ray_plane(c: &mut Criterion) {
    let cam = camera();
    // A billboard seen at an angle, filling a good part of a 16×16 tile around its centre.
    let p = project_splat(Vec3::ZERO, Vec2::splat(-3.0), [0.9, 0.3, 0.2, 0.1], &cam).expect("visible");
    let t = p.transform;
    let (x0, y0) = (p.centre.x.floor() - 8.0, p.centre.y.floor() - 8.0);
    let pixels: Vec<(f32, f32)> = (0..16)
        .flat_map(|j| (0..16).map(move |i| (x0 + i as f32 + 0.5, y0 + j as f32 + 0.5)))
        .collect();
    let mut g = c.benchmark_group("ray_plane");
    g.throughput(Throughput::Elements(pixels.len() as u64));
    g.bench_with_input(BenchmarkId::new("intersect", "16x16 tile"), &t, |bench, t| {
        bench.iter(|| {
            for &(px, py) in &pixels {
                black_box(intersect(black_box(t), px, py));
            }
        })
    });
    g.bench_with_input(BenchmarkId::new("intersect_vjp", "16x16 tile"), &t, |bench, t| {
        bench.iter(|| {
            for &(px, py) in &pixels {
                black_box(intersect_vjp(black_box(t), px, py, 0.3, -0.2, 0.1));
            }
        })
    });
    g.finish();
}

criterion_group!(benches, rotation, splat_transform, ray_plane);
criterion_main!(benches);
