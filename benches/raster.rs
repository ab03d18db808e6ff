//! Rasterizer benches on the standard random scene (issue 3): forward and forward+backward at
//! 256×256 and 400×400 for N = 10k, 50k, 100k billboards, TS = 16, SH degree 3.
//!
//! `cargo bench --bench raster` (all), or e.g. `cargo bench --bench raster -- 'fwd_bwd/256/50000'`.
use bbsplat::billboards::{RandomSceneConfig, random_scene, random_scene_camera};
use bbsplat::raster::backward::ImageGradients;
use bbsplat::raster::{RenderGradients, RenderSettings, render, render_backward};
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
            let set = scene.as_set();
            group.bench_function(format!("fwd/{size}/{n}"), |b| b.iter(|| render(&set, &cam, &settings)));
            let d_rgb = vec![1e-3f32; (size * size * 3) as usize];
            let mut grads = RenderGradients::zeros(n, 16);
            group.bench_function(format!("fwd_bwd/{size}/{n}"), |b| {
                b.iter(|| {
                    let out = render(&set, &cam, &settings);
                    let ig = ImageGradients {
                        rgb: &d_rgb,
                        alpha: None,
                        depth: None,
                    };
                    render_backward(&set, &out, &ig, &mut grads)
                })
            });
        }
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
