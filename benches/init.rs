//! Initialisation benches: farthest point sampling, the Fibonacci sphere and the 3-NN scale
//! statistic (k-d tree and brute force).
//!
//! `cargo bench --features bench --bench init -- --warm-up-time 1 --measurement-time 3`

use bbsplat::init::fibonacci::{fibonacci_sphere, sky_radius};
use bbsplat::init::fps::{farthest_point_sampling, farthest_point_sampling_dense};
use bbsplat::init::knn::{mean_sq_dist_3nn, mean_sq_dist_3nn_brute};
use criterion::{BenchmarkId, Criterion, black_box, criterion_group, criterion_main};
use glam::Vec3;

fn cloud(n: usize) -> Vec<Vec3> {
    bbsplat::strategies::box_cloud(n, 42, [10.0, 10.0, 3.0])
}

fn fps(c: &mut Criterion) {
    let mut group = c.benchmark_group("fps");
    group.sample_size(10);
    let points = cloud(100_000);
    for k in [1_000usize, 10_000] {
        group.bench_with_input(BenchmarkId::new("pruned_n100k", k), &k, |b, &k| {
            b.iter(|| farthest_point_sampling(black_box(&points), k).unwrap())
        });
    }
    // The O(N·k) oracle, for comparison (10k picks take seconds: 1k only).
    group.bench_with_input(BenchmarkId::new("dense_n100k", 1_000), &1_000, |b, &k| {
        b.iter(|| farthest_point_sampling_dense(black_box(&points), k).unwrap())
    });
    // The reference's scale: 300k SfM points down to a 140k budget.
    let big = cloud(300_000);
    group.bench_with_input(BenchmarkId::new("pruned_n300k", 140_000), &140_000, |b, &k| {
        b.iter(|| farthest_point_sampling(black_box(&big), k).unwrap())
    });
    group.finish();
}

fn fibonacci(c: &mut Criterion) {
    c.bench_function("fibonacci_sphere/10k", |b| {
        b.iter(|| fibonacci_sphere(black_box(10_000), 100.0, Vec3::ZERO))
    });
    let points = cloud(300_000);
    c.bench_function("sky_radius_robust/300k", |b| b.iter(|| sky_radius(black_box(&points))));
}

fn knn(c: &mut Criterion) {
    let mut group = c.benchmark_group("knn3");
    group.sample_size(10);
    let points = cloud(100_000);
    group.bench_function("kdtree_n100k", |b| b.iter(|| mean_sq_dist_3nn(black_box(&points))));
    // The O(N²) oracle at a tenth of the size (100k would take minutes).
    let small = cloud(10_000);
    group.bench_function("kdtree_n10k", |b| b.iter(|| mean_sq_dist_3nn(black_box(&small))));
    group.bench_function("brute_n10k", |b| b.iter(|| mean_sq_dist_3nn_brute(black_box(&small))));
    group.finish();
}

criterion_group!(benches, fps, fibonacci, knn);
criterion_main!(benches);
