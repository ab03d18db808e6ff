//! Rasterizer benches.
//!
//! - `raster/fwd…/{256,400}/{10000,50000,100000}`: the standard random scene (issue 3), forward
//!   and forward+backward at 256×256 and 400×400, TS = 16, SH degree 3, recycling the render's
//!   storage between calls (`render_with`, as the trainer does); `fwd_bwd_fresh/256/50000`
//!   allocates it afresh every call (`render`). A pixel blends 0.7 billboards here.
//! - `raster/trained/{object,capture}/400/{10000,30000}/{fwd,fwd_bwd}`: the trained-like scenes
//!   of `bbsplat::billboards::trained_like`, whose per-pixel work matches trained lego and
//!   beer_colmap states (9-20 blended billboards per pixel; `docs/benchmarks.md`). Throughput is
//!   counted in blended (pixel, billboard) pairs, so criterion's `thrpt` gives the time per
//!   blended pair.
//!
//! `cargo bench --features bench --bench raster` (all), or e.g.
//! `cargo bench --features bench --bench raster -- 'fwd_bwd/256/50000'` or `-- raster/trained/object`.
use bbsplat::billboards::{
    ActivatedBillboards, RandomSceneConfig, TrainedLikeConfig, random_scene, random_scene_camera, trained_like_scene,
};
use bbsplat::camera::Camera;
use bbsplat::raster::backward::ImageGradients;
use bbsplat::raster::{
    RenderBuffers, RenderGradients, RenderSettings, render, render_backward, render_backward_with, render_with,
};
use criterion::Throughput;
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
            let mut backward_scratch = bbsplat::raster::BackwardScratch::default();
            let ig = ImageGradients::colour(&d_rgb);
            group.bench_function(format!("fwd_bwd/{size}/{n}"), |b| {
                b.iter(|| {
                    let out = render_with(&set, &cam, &settings, std::mem::take(&mut buffers));
                    let touched = render_backward_with(&set, &out, &ig, &mut grads, &mut backward_scratch);
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

/// Forward and forward+backward of one scene seen by `cam`, as `{name}/fwd/...` and
/// `{name}/fwd_bwd/...`, throughput in blended pairs.
fn bench_scene(c: &mut Criterion, group_name: &str, name: &str, scene: &ActivatedBillboards, cam: &Camera) {
    let settings = RenderSettings::default();
    let set = scene.borrowed();
    let blended = render(&set, cam, &settings).stats.blended_pairs;
    let mut group = c.benchmark_group(group_name);
    group
        .sample_size(10)
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(6))
        .throughput(Throughput::Elements(blended));
    let mut buffers = RenderBuffers::default();
    group.bench_function(format!("{name}/fwd"), |b| {
        b.iter(|| {
            let out = render_with(&set, cam, &settings, std::mem::take(&mut buffers));
            let blended = out.stats.blended_pairs;
            buffers = out.into_buffers();
            blended
        })
    });
    let d_rgb = vec![1e-3f32; (cam.width * cam.height * 3) as usize];
    let mut grads = RenderGradients::zeros(set.len(), set.texture_size);
    let mut backward_scratch = bbsplat::raster::BackwardScratch::default();
    let ig = ImageGradients::colour(&d_rgb);
    group.bench_function(format!("{name}/fwd_bwd"), |b| {
        b.iter(|| {
            let out = render_with(&set, cam, &settings, std::mem::take(&mut buffers));
            let touched = render_backward_with(&set, &out, &ig, &mut grads, &mut backward_scratch);
            buffers = out.into_buffers();
            touched
        })
    });
    group.finish();
}

fn trained(c: &mut Criterion) {
    let size = 400;
    let cam = random_scene_camera(size, size);
    for n in [10_000usize, 30_000] {
        let object = trained_like_scene(&TrainedLikeConfig::object(n, size, size));
        bench_scene(c, "raster/trained", &format!("object/{size}/{n}"), &object, &cam);
        let capture = trained_like_scene(&TrainedLikeConfig::capture(n, size, size));
        bench_scene(c, "raster/trained", &format!("capture/{size}/{n}"), &capture, &cam);
    }
}

criterion_group!(benches, bench, trained);
criterion_main!(benches);
