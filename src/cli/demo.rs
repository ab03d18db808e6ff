//! `bbsplat demo`: train on the embedded analytic scene (no data needed).

use super::common::write_png_atomic;
use anyhow::{Context, Result};
use bbsplat::demo::{DemoConfig, generate};
use bbsplat::init::fps::farthest_point_sampling;
use bbsplat::model::RawBillboards;
use bbsplat::raster::{RenderSettings, render};
use bbsplat::scene::split::camera_extent;
use bbsplat::train::footprint::training_bytes;
use bbsplat::train::{self, RunConfig, RunOutcome, StopSignal, TrainConfig, TrainEvent, TrainView, Trainer};
use glam::Vec3;
use indicatif::{ProgressBar, ProgressStyle};
use std::path::PathBuf;
use std::time::Instant;

/// The size of the demo scene: `demo --resolution`, `--views` and `--billboards`.
#[derive(Clone, Copy, Debug)]
pub struct DemoSize {
    /// Image side in pixels.
    pub resolution: u32,
    /// Training views (the generator's 8 test views come on top).
    pub train_views: usize,
    /// Billboard budget (the scene has twice as many surface points).
    pub billboards: usize,
}

/// `bbsplat demo --export DIR --street COPIES`: writes the street as a COLMAP dataset.
pub fn export_street(copies: usize, resolution: u32, seed: u64, dir: &std::path::Path) -> Result<()> {
    use bbsplat::demo::street::{StreetConfig, export_street};
    anyhow::ensure!(
        (8..=super::validate::MAX_DEMO_RESOLUTION).contains(&resolution),
        "--resolution must be from 8 to {} (got {resolution})",
        super::validate::MAX_DEMO_RESOLUTION
    );
    let config = StreetConfig {
        copies,
        resolution,
        seed,
        ..StreetConfig::default()
    };
    let views = 2 * config.views_per_copy * copies;
    let pixels = resolution as u64 * resolution as u64;
    super::validate::memory(
        &format!("the street of {copies} copies at --resolution {resolution}"),
        (views as u64).saturating_mul(pixels).saturating_mul(24),
    )?;
    export_street(&config, dir).with_context(|| format!("exporting the street to {}", dir.display()))?;
    println!(
        "wrote the street ({copies} copies, {views} views at {resolution}x{resolution}, {} points) as a COLMAP dataset to {}",
        config.points,
        dir.display()
    );
    Ok(())
}

/// Runs `bbsplat demo`: generates the demo scene, trains it with [`bbsplat::train::run`] (no
/// files written, no intermediate evaluation) and reports the test PSNR before and after.
pub fn run(
    iterations: usize,
    size: DemoSize,
    texture_size: usize,
    seed: u64,
    output: Option<PathBuf>,
    export: Option<PathBuf>,
) -> Result<()> {
    let DemoSize {
        resolution,
        train_views,
        billboards,
    } = size;
    super::validate::demo_args(iterations, billboards, texture_size, resolution, train_views)?;
    let defaults = DemoConfig::default();
    let pixels = resolution as u64 * resolution as u64;
    let views = (train_views + defaults.test_views) as u64;
    // The demo's views are float images (12 bytes a pixel), traced with as much again.
    let view_bytes = views.saturating_mul(pixels).saturating_mul(24);
    let needed = if export.is_some() {
        view_bytes
    } else {
        training_bytes(billboards, texture_size, 0, pixels).saturating_add(view_bytes)
    };
    super::validate::memory(
        &format!(
            "the demo at --resolution {resolution} with --views {train_views} and --billboards {billboards} at --texture-size {texture_size}"
        ),
        needed,
    )?;
    let start = Instant::now();
    let scene = generate(&DemoConfig {
        resolution,
        train_views,
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
    let model = RawBillboards::from_points(&points, &colours, texture_size, seed);
    let train: Vec<TrainView> = scene.train.iter().map(TrainView::from_demo).collect();
    let test: Vec<TrainView> = scene.test.iter().map(TrainView::from_demo).collect();
    let cameras: Vec<_> = train.iter().map(|v| v.camera).collect();
    let config = TrainConfig {
        iterations,
        sh_degree: 3,
        background: Vec3::from_array(scene.background),
        seed,
        extent: camera_extent(&cameras),
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
    let before = trainer.evaluate(&test)?;
    let bar = ProgressBar::new(iterations as u64);
    bar.set_style(
        ProgressStyle::with_template("{bar:30} {pos}/{len} [{elapsed_precise} < {eta_precise}, {per_sec}] {msg}")
            .expect("valid template"),
    );
    let settings = RunConfig {
        eval_every: 0,
        scene: "demo".into(),
        command: std::env::args_os().map(|a| a.to_string_lossy().into_owned()).collect(),
        ..RunConfig::default()
    };
    let outcome = train::run(&mut trainer, &train, &test, &settings, &StopSignal::new(), |event| {
        if let TrainEvent::Step { log, running_psnr, .. } = event
            && ((log.step - 1) % 25 == 0 || log.step == iterations)
        {
            bar.set_position(log.step as u64);
            bar.set_message(format!("loss {:.4}, train PSNR {running_psnr:.2} dB", log.loss));
        }
    })
    .context("training on the demo scene")?;
    bar.finish();
    let RunOutcome::Finished(summary) = outcome else {
        anyhow::bail!("the demo run stopped early: {outcome:?}");
    };
    println!(
        "test PSNR: {before:.2} dB at initialisation -> {:.2} dB after {iterations} steps ({:.1} s)",
        summary.test_psnr, summary.train_seconds
    );
    if let Some(dir) = output {
        super::common::refuse_non_folder(&dir)?;
        std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
        let settings = RenderSettings {
            background: config.background,
            sh_degree: 3,
            ..Default::default()
        };
        for (i, v) in test.iter().enumerate() {
            let out = render(&trainer.activated().borrowed(), &v.camera, &settings);
            write_png_atomic(
                &dir.join(format!("test_{i:03}_render.png")),
                &out.rgb,
                v.camera.width,
                v.camera.height,
            )?;
            write_png_atomic(
                &dir.join(format!("test_{i:03}_truth.png")),
                &v.rgb.to_f32()?,
                v.camera.width,
                v.camera.height,
            )?;
        }
        println!("wrote {} render/truth pairs to {}", test.len(), dir.display());
    }
    Ok(())
}
