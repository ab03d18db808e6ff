//! Work counters of a trained model on a scene's test views: how many (pixel, billboard) pairs
//! the rasterizer evaluates and blends per pixel, and the forward and forward+backward times per
//! view. These explain why a training step on a real scene costs far more than the random
//! benchmark scene of `benches/raster.rs` (see `docs/quality.md`), and give a realistic A/B
//! harness for rasterizer changes (the printed checksum covers the images and every gradient).
//!
//! ```text
//! cargo run --release --features examples --example model_stats -- MODEL SCENE_DIR [white|black] [VIEWS] [REPEATS] [DOWNSCALE]
//! ```
//!
//! `MODEL` is a model folder written by `bbsplat train` or a checkpoint file
//! (`checkpoint.bin`, e.g. from `--stop-after`). The background defaults to the one stored in
//! the model; `VIEWS` (default 5) test views are rendered `REPEATS` times each (default 1), after
//! one warm-up render, at the dataset's resolution divided by `DOWNSCALE` (default 1). The backward pass is fed the gradient of `½‖render − image‖²`. Times are
//! wall clock and process CPU time (all threads, without the time spent waiting for a core:
//! the steadier figure on a shared machine).
use bbsplat::billboards::planar_textures;
use bbsplat::raster::backward::ImageGradients;
use bbsplat::raster::{RenderGradients, RenderSettings, WorkloadStats, render, render_backward_with};
use bbsplat::report::process_cpu_ms;
use bbsplat::scene::{Background, LoadOptions, load};
use glam::Vec3;
use std::hash::{DefaultHasher, Hash, Hasher};
use std::path::Path;
use std::time::Instant;

#[path = "support/model_input.rs"]
mod model_input;
use model_input::load_any;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 3 {
        return Err("usage: model_stats MODEL SCENE_DIR [white|black] [VIEWS] [REPEATS] [DOWNSCALE]".into());
    }
    let (model, sh_degree, stored_background) = load_any(Path::new(&args[1]))?;
    let background = match args.get(3).map(String::as_str) {
        Some("white") => Background::White,
        Some("black") => Background::Black,
        _ if stored_background == [1.0, 1.0, 1.0] => Background::White,
        _ => Background::Black,
    };
    let views: usize = args.get(4).map(|s| s.parse()).transpose()?.unwrap_or(5);
    let repeats: usize = args.get(5).map(|s| s.parse()).transpose()?.unwrap_or(1).max(1);
    let downscale: u32 = args.get(6).map(|s| s.parse()).transpose()?.unwrap_or(1).max(1);
    let options = LoadOptions {
        background,
        downscale,
        ..LoadOptions::default()
    };
    let scene = load(Path::new(&args[2]), &options)?;
    let activated = model.activate();
    let set = activated.borrowed();
    let settings = RenderSettings {
        background: Vec3::from_array(background.rgb()),
        sh_degree,
        ..RenderSettings::default()
    };
    let test = if scene.test.is_empty() {
        &scene.train
    } else {
        &scene.test
    };
    if let Some(first) = test.first() {
        render(&set, &first.camera, &settings);
    }
    println!(
        "{} billboards, TS {}, SH degree {sh_degree}",
        set.len(),
        set.texture_size
    );
    println!(
        "| view | pixels | tile entries | evaluated pairs / px | blended pairs / px | forward ms | forward+backward ms | forward CPU ms | forward+backward CPU ms |"
    );
    println!("|---|--:|--:|--:|--:|--:|--:|--:|--:|");
    let mut grads = RenderGradients::zeros(set.len(), set.texture_size);
    let mut backward_scratch = bbsplat::raster::BackwardScratch::default();
    let mut hasher = DefaultHasher::new();
    let mut workload = Vec::new();
    let (mut sum_fwd, mut sum_both, mut count) = (0.0, 0.0, 0usize);
    let (mut sum_fwd_cpu, mut sum_both_cpu) = (0.0, 0.0);
    for view in test.iter().take(views) {
        let target = view.image.get()?.to_f32_rgb();
        let (mut fwd_ms, mut both_ms) = (0.0, 0.0);
        let (mut fwd_cpu, mut both_cpu) = (0.0, 0.0);
        let mut stats = None;
        for _ in 0..repeats {
            let (start, cpu_start) = (Instant::now(), process_cpu_ms());
            let out = render(&set, &view.camera, &settings);
            fwd_ms += start.elapsed().as_secs_f64() * 1e3;
            fwd_cpu += process_cpu_ms() - cpu_start;
            let d_rgb: Vec<f32> = out.rgb.iter().zip(&target).map(|(r, t)| r - t).collect();
            let ig = ImageGradients::colour(&d_rgb);
            let touched = render_backward_with(&set, &out, &ig, &mut grads, &mut backward_scratch);
            both_ms += start.elapsed().as_secs_f64() * 1e3;
            both_cpu += process_cpu_ms() - cpu_start;
            out.rgb.iter().for_each(|v| v.to_bits().hash(&mut hasher));
            touched.hash(&mut hasher);
            // Planar order (alpha, then colour by channel): the checksum of the planar layout.
            let (d_alpha, d_colour) = planar_textures(&grads.textures, set.texels());
            d_alpha
                .iter()
                .chain(&d_colour)
                .chain(&grads.sh)
                .for_each(|v| v.to_bits().hash(&mut hasher));
            for b in touched {
                grads.positions[b as usize]
                    .to_array()
                    .map(f32::to_bits)
                    .hash(&mut hasher);
                grads.clear_row(b as usize);
            }
            stats = Some(out.stats);
            if workload.len() == count {
                workload.push(WorkloadStats::of(&set, &out));
            }
        }
        let stats = stats.expect("at least one repeat");
        let (fwd_ms, both_ms) = (fwd_ms / repeats as f64, both_ms / repeats as f64);
        sum_fwd += fwd_ms;
        sum_both += both_ms;
        let (fwd_cpu, both_cpu) = (fwd_cpu / repeats as f64, both_cpu / repeats as f64);
        sum_fwd_cpu += fwd_cpu;
        sum_both_cpu += both_cpu;
        count += 1;
        let pixels = f64::from(view.camera.width) * f64::from(view.camera.height);
        println!(
            "| {} | {} | {} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} |",
            view.name,
            pixels,
            stats.tile_entries,
            stats.evaluated_pairs as f64 / pixels,
            stats.blended_pairs as f64 / pixels,
            fwd_ms,
            both_ms,
            fwd_cpu,
            both_cpu
        );
    }
    let n = count.max(1) as f64;
    println!(
        "mean: forward {:.1} ms, forward+backward {:.1} ms (CPU {:.1}, {:.1} ms); checksum {:016x}",
        sum_fwd / n,
        sum_both / n,
        sum_fwd_cpu / n,
        sum_both_cpu / n,
        hasher.finish()
    );
    println!("\nWorkload (mean over the views; `bbsplat::raster::WorkloadStats`):\n");
    println!("{}", WorkloadStats::table_header());
    println!("{}", WorkloadStats::mean(&workload).table_row(&args[1]));
    Ok(())
}
