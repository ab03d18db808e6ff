//! `bbsplat demo`: train on the embedded analytic scene (no data needed).

use super::common::write_png_atomic;
use anyhow::{Context, Result};
use bbsplat::demo::{DemoConfig, generate};
use bbsplat::init::fps::farthest_point_sampling;
use bbsplat::model::Model;
use bbsplat::raster::{RenderSettings, render};
use bbsplat::train::{TrainConfig, TrainView, Trainer, scene_extent};
use glam::Vec3;
use indicatif::{ProgressBar, ProgressStyle};
use std::path::PathBuf;
use std::time::Instant;

#[allow(clippy::too_many_arguments)]
pub fn run(
    iterations: usize,
    billboards: usize,
    texture_size: usize,
    resolution: u32,
    seed: u64,
    output: Option<PathBuf>,
    export: Option<PathBuf>,
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
    if let Some(dir) = export {
        bbsplat::demo::export_colmap(&scene, &dir)
            .with_context(|| format!("exporting the demo scene to {}", dir.display()))?;
        println!(
            "wrote the demo scene ({} views at {resolution}x{resolution}, {} points) as a COLMAP dataset to {}",
            scene.train.len() + scene.test.len(),
            scene.points.len(),
            dir.display()
        );
        return Ok(());
    }
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
