//! Work counters of a trained model on a scene's test views: how many (pixel, billboard) pairs
//! the rasterizer evaluates and blends per pixel, and the forward time per view. These explain
//! why a training step on a real scene costs far more than the random benchmark scene of
//! `benches/raster.rs` (see `docs/quality.md`).
//!
//! ```text
//! cargo run --release --example model_stats -- MODEL_DIR SCENE_DIR [white|black] [VIEWS]
//! ```
//!
//! The background defaults to the one stored in the model; `VIEWS` (default 5) test views are
//! rendered, the first one also as a warm-up.
use bbsplat::model_file::load_model;
use bbsplat::raster::{RenderSettings, render};
use bbsplat::scene::{Background, LoadOptions, load};
use glam::Vec3;
use std::path::Path;
use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 3 {
        return Err("usage: model_stats MODEL_DIR SCENE_DIR [white|black] [VIEWS]".into());
    }
    let (model, meta) = load_model(Path::new(&args[1]))?;
    let background = match args.get(3).map(String::as_str) {
        Some("white") => Background::White,
        Some("black") => Background::Black,
        _ if meta.background == [1.0, 1.0, 1.0] => Background::White,
        _ => Background::Black,
    };
    let views: usize = args.get(4).map(|s| s.parse()).transpose()?.unwrap_or(5);
    let options = LoadOptions {
        background,
        ..LoadOptions::default()
    };
    let scene = load(Path::new(&args[2]), &options)?;
    let activated = model.activate();
    let set = activated.as_set();
    let settings = RenderSettings {
        background: Vec3::from_array(background.rgb()),
        sh_degree: meta.sh_degree,
        ..RenderSettings::default()
    };
    let test = if scene.test.is_empty() { &scene.train } else { &scene.test };
    if let Some(first) = test.first() {
        render(&set, &first.camera, &settings);
    }
    println!("{} billboards, TS {}, SH degree {}", set.len(), set.texture_size, meta.sh_degree);
    println!("| view | pixels | tile entries | evaluated pairs / px | blended pairs / px | forward ms |");
    println!("|---|--:|--:|--:|--:|--:|");
    for view in test.iter().take(views) {
        let start = Instant::now();
        let out = render(&set, &view.camera, &settings);
        let ms = start.elapsed().as_secs_f64() * 1e3;
        let pixels = f64::from(view.camera.width) * f64::from(view.camera.height);
        println!(
            "| {} | {} | {} | {:.1} | {:.1} | {:.1} |",
            view.name,
            pixels,
            out.stats.tile_entries,
            out.stats.evaluated_pairs as f64 / pixels,
            out.stats.blended_pairs as f64 / pixels,
            ms
        );
    }
    Ok(())
}
