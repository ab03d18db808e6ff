//! Writes the ground-truth images of the embedded demo scene as PNG files.
//!
//! `cargo run --release --features examples --example demo_scene_images -- out/demo_gt`
use bbsplat::demo::{DemoConfig, generate};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let dir = std::env::args().nth(1).unwrap_or_else(|| "out/demo_gt".into());
    std::fs::create_dir_all(&dir)?;
    let scene = generate(&DemoConfig::default());
    for (split, views) in [("train", &scene.train), ("test", &scene.test)] {
        for (i, view) in views.iter().enumerate() {
            let bytes: Vec<u8> = view.rgb.iter().map(|&c| bbsplat::loss::psnr::quantize_u8(c)).collect();
            let path = format!("{dir}/{split}_{i:03}.png");
            image::save_buffer(
                &path,
                &bytes,
                view.camera.width,
                view.camera.height,
                image::ExtendedColorType::Rgb8,
            )?;
        }
    }
    println!(
        "wrote {} train and {} test views to {dir}",
        scene.train.len(),
        scene.test.len()
    );
    Ok(())
}
