//! Rasterizer benches on the standard random scene (issue 3): forward and forward+backward at
//! 256×256 and 400×400 for N = 10k, 50k, 100k billboards, TS = 16, SH degree 3, recycling the
//! render's storage between calls (`render_with`, as the trainer does); `fwd_bwd_fresh/256/50000`
//! allocates it afresh every call (`render`).
//!
//! `cargo bench --features bench --bench raster` (all), or e.g. `cargo bench --features bench --bench raster -- 'fwd_bwd/256/50000'`.
use bbsplat::billboards::{RandomSceneConfig, random_scene, random_scene_camera};
use bbsplat::raster::backward::ImageGradients;
use bbsplat::raster::{RenderBuffers, RenderGradients, RenderSettings, render, render_backward, render_with};
use criterion::{Criterion, criterion_group, criterion_main};
use std::time::Duration;

fn bench(c: &mut Criterion) {
    let mut group = c.benchmark_group("raster");
    group
        .sample_size(10)
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(4));
    for size in [256u32, 400] {
        for n in [10_000usize, 50_000, 100_000] {
            let scene = random_scene(&RandomSceneConfig::benchmark(n, size, size));
            let cam = random_scene_camera(size, size);
            let settings = RenderSettings::default();
            let set = scene.borrowed();
            // Storage recycled from call to call, as the trainer and `eval` do (`render_with`).
            let mut buffers = RenderBuffers::default();
            group.bench_function(format!("fwd/{size}/{n}"), |b| {
                b.iter(|| {
                    let out = render_with(&set, &cam, &settings, std::mem::take(&mut buffers));
                    let blended = out.stats.blended_pairs;
                    buffers = out.into_buffers();
                    blended
                })
            });
            let d_rgb = vec![1e-3f32; (size * size * 3) as usize];
            let mut grads = RenderGradients::zeros(n, set.texture_size);
            let ig = ImageGradients {
                rgb: &d_rgb,
                alpha: None,
                depth: None,
            };
            group.bench_function(format!("fwd_bwd/{size}/{n}"), |b| {
                b.iter(|| {
                    let out = render_with(&set, &cam, &settings, std::mem::take(&mut buffers));
                    let touched = render_backward(&set, &out, &ig, &mut grads);
                    buffers = out.into_buffers();
                    touched
                })
            });
            if (size, n) == (256, 50_000) {
                // The same with every buffer allocated afresh (`render`), for comparison.
                group.bench_function(format!("fwd_bwd_fresh/{size}/{n}"), |b| {
                    b.iter(|| render_backward(&set, &render(&set, &cam, &settings), &ig, &mut grads))
                });
            }
        }
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
