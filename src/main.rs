//! The `bbsplat` command line.

use anyhow::{Context, Result};
use bbsplat::demo::{DemoConfig, generate};
use bbsplat::init::fps::farthest_point_sampling;
use bbsplat::model::Model;
use bbsplat::raster::{RenderSettings, render};
use bbsplat::train::{TrainConfig, TrainView, Trainer, scene_extent};
use clap::{Parser, Subcommand};
use glam::Vec3;
use indicatif::{ProgressBar, ProgressStyle};
use std::path::{Path, PathBuf};
use std::time::Instant;

#[derive(Parser)]
#[command(name = "bbsplat", version, about = "Billboard splatting on the CPU")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Train on the embedded demo scene (an analytic ray-traced world, no data needed) and report
    /// held-out PSNR before and after training.
    Demo {
        /// Optimisation steps.
        #[arg(long, default_value_t = 3000)]
        iterations: usize,
        /// Billboard budget (farthest point sampling of the scene's surface points).
        #[arg(long, default_value_t = 3000)]
        billboards: usize,
        /// Texture side.
        #[arg(long, default_value_t = 16)]
        texture_size: usize,
        /// Image side in pixels.
        #[arg(long, default_value_t = 96)]
        resolution: u32,
        /// Seed of the scene, the initialisation and the view order.
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Folder for the test renders (PNG); nothing is written when omitted.
        #[arg(short, long)]
        output: Option<PathBuf>,
        /// Rayon worker threads (default: all cores).
        #[arg(long)]
        threads: Option<usize>,
    },
}

fn write_png_atomic(path: &Path, rgb: &[f32], width: u32, height: u32) -> Result<()> {
    let bytes: Vec<u8> = rgb.iter().map(|&c| bbsplat::loss::psnr::quantize_u8(c)).collect();
    let tmp = path.with_extension("png.tmp");
    image::save_buffer_with_format(
        &tmp,
        &bytes,
        width,
        height,
        image::ExtendedColorType::Rgb8,
        image::ImageFormat::Png,
    )
    .with_context(|| format!("writing {}", tmp.display()))?;
    std::fs::rename(&tmp, path).with_context(|| format!("renaming {} to {}", tmp.display(), path.display()))?;
    Ok(())
}

#[allow(clippy::too_many_arguments)]
fn demo(
    iterations: usize,
    billboards: usize,
    texture_size: usize,
    resolution: u32,
    seed: u64,
    output: Option<PathBuf>,
) -> Result<()> {
    anyhow::ensure!(texture_size >= 2, "--texture-size must be at least 2");
    anyhow::ensure!(resolution >= 8, "--resolution must be at least 8");
    let start = Instant::now();
    let scene = generate(&DemoConfig {
        resolution,
        seed,
        points: billboards.max(1) * 2,
        ..DemoConfig::default()
    });
    let keep = farthest_point_sampling(&scene.points, billboards).context("sampling the initial points")?;
    let points: Vec<Vec3> = keep.iter().map(|&i| scene.points[i]).collect();
    let colours: Vec<[f32; 3]> = keep.iter().map(|&i| scene.colours[i]).collect();
    let model = Model::from_points(&points, &colours, texture_size, seed);
    let to_views = |v: &[bbsplat::demo::DemoView]| -> Vec<TrainView> {
        v.iter()
            .map(|v| TrainView {
                camera: v.camera,
                rgb: v.rgb.clone(),
            })
            .collect()
    };
    let (train, test) = (to_views(&scene.train), to_views(&scene.test));
    let cameras: Vec<_> = train.iter().map(|v| v.camera).collect();
    let config = TrainConfig {
        iterations,
        sh_degree: 3,
        background: Vec3::from_array(scene.background),
        seed,
        extent: scene_extent(&cameras),
        ..TrainConfig::default()
    };
    println!(
        "demo scene: {} train / {} test views at {res}x{res}, {} billboards (TS {texture_size}), generated in {:.1} s",
        train.len(),
        test.len(),
        model.len(),
        start.elapsed().as_secs_f64(),
        res = resolution
    );
    let mut trainer = Trainer::new(model, config);
    let before = trainer.evaluate(&test);
    let bar = ProgressBar::new(iterations as u64);
    bar.set_style(
        ProgressStyle::with_template("{bar:30} {pos}/{len} [{elapsed_precise} < {eta_precise}, {per_sec}] {msg}")
            .expect("valid template"),
    );
    let t0 = Instant::now();
    let mut running = 0.0;
    for i in 0..iterations {
        let log = trainer.step(&train)?;
        running = if i == 0 {
            log.psnr
        } else {
            0.95 * running + 0.05 * log.psnr
        };
        if i % 25 == 0 || i + 1 == iterations {
            bar.set_position(i as u64 + 1);
            bar.set_message(format!("loss {:.4}, train PSNR {:.2} dB", log.loss, running));
        }
    }
    bar.finish();
    let train_secs = t0.elapsed().as_secs_f64();
    let after = trainer.evaluate(&test);
    println!(
        "test PSNR: {before:.2} dB at initialisation -> {after:.2} dB after {iterations} steps ({train_secs:.1} s)"
    );
    if let Some(dir) = output {
        std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
        let settings = RenderSettings {
            background: config.background,
            sh_degree: 3,
            ..Default::default()
        };
        for (i, v) in test.iter().enumerate() {
            let out = render(&trainer.activated.as_set(), &v.camera, &settings);
            write_png_atomic(
                &dir.join(format!("test_{i:03}_render.png")),
                &out.rgb,
                v.camera.width,
                v.camera.height,
            )?;
            write_png_atomic(
                &dir.join(format!("test_{i:03}_truth.png")),
                &v.rgb,
                v.camera.width,
                v.camera.height,
            )?;
        }
        println!("wrote {} render/truth pairs to {}", test.len(), dir.display());
    }
    Ok(())
}

fn main() -> Result<()> {
    let cli = Cli::parse();
    match cli.command {
        Command::Demo {
            iterations,
            billboards,
            texture_size,
            resolution,
            seed,
            output,
            threads,
        } => {
            if let Some(n) = threads {
                rayon::ThreadPoolBuilder::new()
                    .num_threads(n)
                    .build_global()
                    .context("starting the thread pool")?;
            }
            demo(iterations, billboards, texture_size, resolution, seed, output)
        }
    }
}
