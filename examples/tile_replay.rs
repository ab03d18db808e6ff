//! How a training step's render (forward and backward) would scale to 4-64 cores: every tile's
//! cost is measured on one thread ([`bbsplat::raster::replay::traced`]), the tile passes are
//! replayed on simulated workers ([`bbsplat::raster::replay::replay`]), and the work outside
//! them is split into a serial part and a part that scales, from one and two threads. The
//! two-thread prediction is checked against the two-thread measurement. docs/perf.md, "All the
//! cores of a bigger machine", has the figures.
//!
//! ```text
//! cargo run --release --features examples --example tile_replay -- MODEL SCENE_DIR [VIEWS] [REPEATS]
//! ```
//!
//! `MODEL` is a model folder or a checkpoint; `VIEWS` test views (default 4), each measured
//! `REPEATS` times (default 3) after a warm-up, the fastest kept.

#[path = "support/model_input.rs"]
mod model_input;

use bbsplat::raster::backward::ImageGradients;
use bbsplat::raster::replay::{PassTrace, lower_bound, predicted_time, replay, traced};
use bbsplat::raster::{
    ActivatedRef, BackwardScratch, RenderBuffers, RenderGradients, RenderSettings, render_backward_with, render_with,
};
use bbsplat::scene::{Background, LoadOptions, load};
use glam::Vec3;
use model_input::load_any;
use std::path::Path;
use std::time::Instant;

/// One forward and backward of `camera`, traced, with the trainer's recycled buffers: the
/// wall time of the two calls (the image gradient between them not counted) and the tile
/// passes.
fn step(
    set: &ActivatedRef<'_>,
    camera: &bbsplat::camera::Camera,
    settings: &RenderSettings,
    target: &[f32],
    state: &mut State,
) -> (u64, Vec<PassTrace>) {
    let mut nanos = 0;
    let (_, passes) = traced(|| {
        let start = Instant::now();
        let out = render_with(set, camera, settings, std::mem::take(&mut state.buffers));
        nanos += start.elapsed().as_nanos() as u64;
        let d_rgb: Vec<f32> = out.rgb.iter().zip(target).map(|(r, t)| r - t).collect();
        let ig = ImageGradients::colour(&d_rgb);
        let start = Instant::now();
        let touched = render_backward_with(set, &out, &ig, &mut state.grads, &mut state.scratch);
        nanos += start.elapsed().as_nanos() as u64;
        for b in touched {
            state.grads.clear_row(b as usize);
        }
        state.buffers = out.into_buffers();
    });
    (nanos, passes)
}

/// What a step recycles, as the trainer does.
struct State {
    buffers: RenderBuffers,
    grads: RenderGradients,
    scratch: BackwardScratch,
}

/// The fastest of `repeats` traced steps on a pool of `threads` threads.
fn fastest(
    threads: usize,
    repeats: usize,
    set: &ActivatedRef<'_>,
    camera: &bbsplat::camera::Camera,
    settings: &RenderSettings,
    target: &[f32],
    state: &mut State,
) -> (u64, Vec<PassTrace>) {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .expect("a pool");
    pool.install(|| {
        step(set, camera, settings, target, state);
        (0..repeats)
            .map(|_| step(set, camera, settings, target, state))
            .min_by_key(|(t, _)| *t)
            .expect("at least one repeat")
    })
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 3 {
        return Err("usage: tile_replay MODEL SCENE_DIR [VIEWS] [REPEATS]".into());
    }
    let (model, sh_degree, background) = load_any(Path::new(&args[1]))?;
    let views: usize = args.get(3).map(|s| s.parse()).transpose()?.unwrap_or(4);
    let repeats: usize = args.get(4).map(|s| s.parse()).transpose()?.unwrap_or(3).max(1);
    let options = LoadOptions {
        background: if background == [1.0; 3] {
            Background::White
        } else {
            Background::Black
        },
        print_warnings: false,
        ..LoadOptions::default()
    };
    let scene = load(Path::new(&args[2]), &options)?;
    let activated = model.activate();
    let set = activated.borrowed();
    let settings = RenderSettings {
        background: Vec3::from_array(background),
        sh_degree,
        ..RenderSettings::default()
    };
    let test = if scene.test.is_empty() {
        &scene.train
    } else {
        &scene.test
    };
    let mut state = State {
        buffers: RenderBuffers::default(),
        grads: RenderGradients::zeros(set.len(), set.texture_size),
        scratch: BackwardScratch::default(),
    };
    const WORKERS: [usize; 7] = [1, 2, 4, 8, 16, 32, 64];
    // Summed over the views: predicted times per worker count, tiles-only makespans and bounds.
    let mut predicted = [0u64; 7];
    let (mut tiles_makespan, mut tiles_bound) = ([0u64; 7], [0u64; 7]);
    let (mut t1_sum, mut t2_sum, mut serial_sum, mut scaling_sum, mut tile_sum) = (0u64, 0u64, 0u64, 0u64, 0u64);
    let mut heaviest_share: f64 = 0.0;
    println!(
        "{} billboards, TS {}; {} views of {}x{}",
        set.len(),
        set.texture_size,
        views.min(test.len()),
        test[0].camera.width,
        test[0].camera.height
    );
    for view in test.iter().take(views) {
        let target = view.image.get()?.to_f32_rgb();
        let (t1, passes) = fastest(1, repeats, &set, &view.camera, &settings, &target, &mut state);
        let (t2, passes2) = fastest(2, repeats, &set, &view.camera, &settings, &target, &mut state);
        let tiles1: u64 = passes.iter().flat_map(|p| &p.nanos).sum();
        let walls1: u64 = passes.iter().map(|p| p.wall).sum();
        let walls2: u64 = passes2.iter().map(|p| p.wall).sum();
        // Outside the tile passes: s + p on one thread, s + p/2 on two.
        let (outside1, outside2) = (t1.saturating_sub(walls1), t2.saturating_sub(walls2));
        let scaling = 2 * outside1.saturating_sub(outside2).min(outside1);
        let serial = outside1 - scaling.min(outside1);
        t1_sum += t1;
        t2_sum += t2;
        serial_sum += serial;
        scaling_sum += scaling;
        tile_sum += tiles1;
        for (k, &n) in WORKERS.iter().enumerate() {
            predicted[k] += predicted_time(serial, scaling, &passes, n);
            for p in &passes {
                tiles_makespan[k] += replay(&p.estimated, &p.nanos, n).makespan;
                tiles_bound[k] += lower_bound(&p.nanos, n);
            }
        }
        for (k, p) in passes.iter().enumerate() {
            let sum = p.nanos.iter().sum::<u64>().max(1) as f64;
            let max = p.nanos.iter().copied().max().unwrap_or(0) as f64;
            heaviest_share = heaviest_share.max(max / sum);
            let mut by_cost: Vec<usize> = (0..p.nanos.len()).collect();
            by_cost.sort_by_key(|&i| std::cmp::Reverse(p.nanos[i]));
            let top: Vec<String> = by_cost
                .iter()
                .take(3)
                .map(|&i| {
                    format!(
                        "tile {i}: {:.2} ms (estimate {})",
                        p.nanos[i] as f64 / 1e6,
                        p.estimated[i]
                    )
                })
                .collect();
            println!(
                "  pass {k}: {} tiles, {:.1} ms; heaviest {:.1} % ({})",
                p.nanos.len(),
                sum / 1e6,
                100.0 * max / sum,
                top.join(", ")
            );
        }
        println!(
            "{}: 1 thread {:.1} ms (tiles {:.1}, outside the passes {:.1}: serial {:.1}, scaling {:.1}); 2 threads {:.1} ms, predicted {:.1}",
            view.name,
            t1 as f64 / 1e6,
            tiles1 as f64 / 1e6,
            outside1 as f64 / 1e6,
            serial as f64 / 1e6,
            scaling as f64 / 1e6,
            t2 as f64 / 1e6,
            predicted_time(serial, scaling, &passes, 2) as f64 / 1e6
        );
    }
    println!(
        "\nsums: 1 thread {:.1} ms = tiles {:.1} + serial {:.1} + scaling {:.1} (+ pass overhead); 2 threads measured {:.1} ms, predicted {:.1} ({:+.1} %); heaviest tile {:.2} % of its pass\n",
        t1_sum as f64 / 1e6,
        tile_sum as f64 / 1e6,
        serial_sum as f64 / 1e6,
        scaling_sum as f64 / 1e6,
        t2_sum as f64 / 1e6,
        predicted[1] as f64 / 1e6,
        100.0 * (predicted[1] as f64 / t2_sum as f64 - 1.0),
        100.0 * heaviest_share
    );
    println!(
        "| cores | predicted ms | speed-up | efficiency | tile passes: makespan ms | their efficiency | lower bound ms |"
    );
    println!("|--:|--:|--:|--:|--:|--:|--:|");
    for (k, &n) in WORKERS.iter().enumerate() {
        let speedup = predicted[0] as f64 / predicted[k] as f64;
        println!(
            "| {n} | {:.1} | {:.2} | {:.0} % | {:.1} | {:.0} % | {:.1} |",
            predicted[k] as f64 / 1e6,
            speedup,
            100.0 * speedup / n as f64,
            tiles_makespan[k] as f64 / 1e6,
            100.0 * tile_sum as f64 / (n as f64 * tiles_makespan[k] as f64),
            tiles_bound[k] as f64 / 1e6
        );
    }
    Ok(())
}
