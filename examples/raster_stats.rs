//! Work statistics and phase timings of the rasterizer on the standard benchmark scene, or on a
//! trained-like scene (`bbsplat::billboards::trained_like`).
//!
//! `cargo run --release --features examples --example raster_stats -- 256 50000`
//!
//! `raster_stats object 400 10000 ...` (or `capture`) uses the trained-like scene of that preset
//! instead of the random benchmark scene, with the same modes below, and prints its workload
//! statistics (`bbsplat::raster::WorkloadStats`).
//!
//! `raster_stats 256 50000 loop 20` only runs 20 forward+backward calls after one warm-up and
//! prints their mean (a steady harness for `perf record` and `valgrind`), recycling the render's
//! storage with `render_with` as the trainer does; `loopfresh` the same with fresh storage every
//! call (`render`); `loopf` the forward alone (storage recycled too).
use bbsplat::billboards::{
    RandomSceneConfig, TrainedLikeConfig, planar_textures, random_scene, random_scene_camera, trained_like_scene,
};
use bbsplat::raster::backward::ImageGradients;
use bbsplat::raster::binning::bin;
use bbsplat::raster::preprocess::preprocess;
use bbsplat::raster::{
    RenderBuffers, RenderGradients, RenderSettings, WorkloadStats, render, render_backward, render_backward_with,
    render_with,
};
use bbsplat::report::process_cpu_ms as cpu_ms;
use std::time::Instant;

fn main() {
    let mut args: Vec<String> = std::env::args().collect();
    let preset = args.get(1).filter(|a| *a == "object" || *a == "capture").cloned();
    if preset.is_some() {
        args.remove(1);
    }
    let size: u32 = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(256);
    let n: usize = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(50_000);
    let scene = match preset.as_deref() {
        Some("object") => trained_like_scene(&TrainedLikeConfig::object(n, size, size)),
        Some(_) => trained_like_scene(&TrainedLikeConfig::capture(n, size, size)),
        None => random_scene(&RandomSceneConfig::benchmark(n, size, size)),
    };
    let cam = random_scene_camera(size, size);
    let settings = RenderSettings::default();
    let set = scene.borrowed();
    if let Some(name) = &preset {
        let out = render(&set, &cam, &settings);
        println!("{}", WorkloadStats::table_header());
        println!(
            "{}",
            WorkloadStats::of(&set, &out).table_row(&format!("{name} {size}²/{n}"))
        );
    }
    if args.get(3).map(String::as_str) == Some("loopf") {
        let calls: usize = args.get(4).and_then(|s| s.parse().ok()).unwrap_or(20);
        // The render's storage recycled from call to call, as training and evaluation do.
        let mut out = render(&set, &cam, &settings);
        let (t, c) = (Instant::now(), cpu_ms());
        for _ in 0..calls {
            out = render_with(&set, &cam, &settings, out.into_buffers());
        }
        let ms = t.elapsed().as_secs_f64() * 1e3 / calls.max(1) as f64;
        let cpu = (cpu_ms() - c) / calls.max(1) as f64;
        let blended = out.stats.blended_pairs;
        println!(
            "{size}x{size}, N = {n}: {calls} fwd calls, {ms:.2} ms each, cpu {cpu:.2} ms each, {blended} blended pairs"
        );
        return;
    }
    let mode = args.get(3).map(String::as_str);
    if mode == Some("loop") || mode == Some("loopfresh") {
        let calls: usize = args.get(4).and_then(|s| s.parse().ok()).unwrap_or(20);
        let d_rgb = vec![1e-3f32; (size * size * 3) as usize];
        let mut grads = RenderGradients::zeros(n, set.texture_size);
        let mut backward_scratch = bbsplat::raster::BackwardScratch::default();
        // `loop` recycles the render's storage as the trainer does; `loopfresh` allocates it
        // afresh every call.
        let recycle = mode == Some("loop");
        let mut buffers = RenderBuffers::default();
        let mut once = || {
            let out = if recycle {
                render_with(&set, &cam, &settings, std::mem::take(&mut buffers))
            } else {
                render(&set, &cam, &settings)
            };
            let ig = ImageGradients::colour(&d_rgb);
            let touched = render_backward_with(&set, &out, &ig, &mut grads, &mut backward_scratch).len();
            if recycle {
                buffers = out.into_buffers();
            }
            touched
        };
        let touched = once();
        // Checksum of the first call's images and gradients, to confirm bit-identical changes.
        let out = render(&set, &cam, &settings);
        let mut g1 = RenderGradients::zeros(n, set.texture_size);
        let ig = ImageGradients::colour(&d_rgb);
        render_backward(&set, &out, &ig, &mut g1);
        let mut h = 0xcbf29ce484222325u64;
        let mix = |h: &mut u64, v: &[f32]| {
            for x in v {
                *h = (*h ^ x.to_bits() as u64).wrapping_mul(0x100000001b3);
            }
        };
        mix(&mut h, &out.rgb);
        mix(&mut h, &out.alpha);
        mix(&mut h, &out.depth);
        // The images alone (they do not depend on the tile size; the sums below do).
        println!("images checksum {h:016x}");
        mix(&mut h, &out.impact);
        mix(&mut h, &g1.sh);
        // Planar order (alpha, then colour by channel): the checksum of the planar layout.
        let (d_alpha, d_colour) = planar_textures(&g1.textures, set.texels());
        mix(&mut h, &d_alpha);
        mix(&mut h, &d_colour);
        mix(
            &mut h,
            &g1.positions.iter().flat_map(|p| p.to_array()).collect::<Vec<_>>(),
        );
        mix(&mut h, &g1.quaternions.concat());
        println!("checksum {h:016x}");
        let (t, c) = (Instant::now(), cpu_ms());
        for _ in 0..calls {
            once();
        }
        let ms = t.elapsed().as_secs_f64() * 1e3 / calls.max(1) as f64;
        let cpu = (cpu_ms() - c) / calls.max(1) as f64;
        println!(
            "{size}x{size}, N = {n}: {calls} fwd+bwd calls, {ms:.2} ms each, cpu {cpu:.2} ms each, {touched} billboards touched"
        );
        return;
    }
    let reps = 10;
    let time = |f: &mut dyn FnMut()| {
        f();
        let t = Instant::now();
        for _ in 0..reps {
            f();
        }
        t.elapsed().as_secs_f64() * 1e3 / reps as f64
    };
    let mut prepared = Vec::new();
    let t_pre = time(&mut || prepared = preprocess(&set, &cam, &settings));
    let t_bin = time(&mut || {
        bin(&prepared, size, size);
    });
    let mut out = render(&set, &cam, &settings);
    let t_fwd = time(&mut || out = render(&set, &cam, &settings));
    let d_rgb = vec![1e-3f32; (size * size * 3) as usize];
    let mut grads = RenderGradients::zeros(n, 16);
    let mut backward_scratch = bbsplat::raster::BackwardScratch::default();
    let t_bwd = time(&mut || {
        render_backward_with(
            &set,
            &out,
            &ImageGradients::colour(&d_rgb),
            &mut grads,
            &mut backward_scratch,
        );
    });
    let px = (size * size) as f64;
    let s = out.stats;
    println!(
        "{size}x{size}, N = {n}, tiles of {} px, {} threads",
        bbsplat::raster::TILE_SIZE,
        rayon::current_num_threads()
    );
    println!(
        "  tile entries {} ({:.1} per billboard)",
        s.tile_entries,
        s.tile_entries as f64 / n as f64
    );
    println!(
        "  evaluated pairs per pixel {:.1}, blended pairs per pixel {:.1}",
        s.evaluated_pairs as f64 / px,
        s.blended_pairs as f64 / px
    );
    println!("  preprocess {t_pre:.2} ms, binning {t_bin:.2} ms, forward total {t_fwd:.2} ms, backward {t_bwd:.2} ms");
    println!(
        "  forward ns per evaluated pair (whole forward / pairs): {:.1}",
        t_fwd * 1e6 / s.evaluated_pairs.max(1) as f64
    );
}
