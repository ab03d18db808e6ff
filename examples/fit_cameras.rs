//! Test-view scores of a trained model before and after aligning each test camera to its image
//! under the frozen model ([`bbsplat::train::camera_fit::fit_camera`]).
//!
//! ```text
//! cargo run --release --features examples --example fit_cameras -- MODEL SCENE_DIR [ITERATIONS] [ROTATION] [TRANSLATION] [FOCAL]
//! ```
//!
//! `MODEL` is a model folder written by `bbsplat train`; the step sizes default to 1e-3 rad,
//! 1e-3 world units and 1e-3 (log focal scale), decaying to a hundredth over the iterations
//! (default 100).
use bbsplat::eval::image_metrics;
use bbsplat::model_file::load_model;
use bbsplat::raster::{RenderSettings, render};
use bbsplat::scene::{Background, LoadOptions, load};
use bbsplat::train::camera_fit::{CameraStepSizes, fit_camera};
use glam::Vec3;
use std::path::Path;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 3 {
        return Err("usage: fit_cameras MODEL SCENE_DIR [ITERATIONS] [ROTATION] [TRANSLATION] [FOCAL]".into());
    }
    let (model, meta) = load_model(Path::new(&args[1]))?;
    let number = |i: usize, default: f64| -> Result<f64, Box<dyn std::error::Error>> {
        Ok(args.get(i).map(|s| s.parse()).transpose()?.unwrap_or(default))
    };
    let iterations = number(3, 100.0)? as usize;
    let sizes = CameraStepSizes {
        rotation: number(4, 1e-3)? as f32,
        translation: number(5, 1e-3)? as f32,
        focal: number(6, 1e-3)? as f32,
    };
    let background = if meta.background == [1.0, 1.0, 1.0] {
        Background::White
    } else {
        Background::Black
    };
    let scene = load(
        Path::new(&args[2]),
        &LoadOptions {
            background,
            ..LoadOptions::default()
        },
    )?;
    let activated = model.activate();
    let set = activated.borrowed();
    let settings = RenderSettings {
        background: Vec3::from_array(meta.background),
        sh_degree: meta.sh_degree,
        ..RenderSettings::default()
    };
    let (mut before_sum, mut after_sum) = (0.0, 0.0);
    println!("| view | PSNR before | PSNR after | SSIM before | SSIM after | loss before | loss after |");
    println!("|---|--:|--:|--:|--:|--:|--:|");
    // FIT_SPLIT=train:K fits every K-th training view instead of the test views.
    let chosen: Vec<&bbsplat::scene::View> = match std::env::var("FIT_SPLIT").ok() {
        Some(spec) if spec.starts_with("train:") => {
            let k: usize = spec[6..].parse()?;
            scene.train.iter().step_by(k.max(1)).collect()
        }
        _ => scene.test.iter().collect(),
    };
    for view in chosen.iter().copied() {
        let target = view.image.get().unwrap().to_f32_rgb();
        let (w, h) = (view.camera.width as usize, view.camera.height as usize);
        let before = image_metrics(&render(&set, &view.camera, &settings).rgb, &target, w, h)?;
        let fit = fit_camera(&set, &view.camera, &target, &settings, iterations, &sizes)?;
        let after = image_metrics(&render(&set, &fit.camera, &settings).rgb, &target, w, h)?;
        before_sum += before.psnr;
        after_sum += after.psnr;
        println!(
            "| {} | {:.2} | {:.2} | {:.4} | {:.4} | {:.4} | {:.4} |",
            view.name, before.psnr, after.psnr, before.ssim, after.ssim, fit.loss_before, fit.loss_after
        );
    }
    let n = chosen.len().max(1) as f64;
    println!("mean PSNR {:.3} -> {:.3}", before_sum / n, after_sum / n);
    Ok(())
}
