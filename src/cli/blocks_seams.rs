//! `bbsplat blocks seams CHAIN [--model DIR]...`: the test views' quality where the chain's
//! cells meet ([`bbsplat::blocks::seams`]), for the chain's polished model and for any other
//! model of the same scene (e.g. a single run of equal time), written as `CHAIN/seams.json` and
//! printed.
//!
//! The band: pixels whose surface, by the chain's *coarse* model's expected depth (one depth for
//! every model compared), lies within `--width` of a seam on the ground (default: the
//! partition's margin, the strip where two blocks both trained). Per model: PSNR and SSIM over
//! the whole views, over the band's pixels and over the other pixels with a surface, each the
//! mean over the test views that have such pixels (masked figures as `eval --masked` computes
//! them: [`bbsplat::eval::masked_image_metrics`]).

use super::blocks_files::read_plan;
use super::common::SceneArgs;
use anyhow::{Context, Result};
use bbsplat::blocks::seams::{MIN_ALPHA, seam_band_mask};
use bbsplat::eval::{image_metrics, masked_image_metrics};
use bbsplat::model_file::load_model;
use bbsplat::raster::{RenderSettings, render};
use bbsplat::train::run::MODEL_DIR;
use clap::Args;
use glam::Vec3;
use serde::Serialize;
use std::path::{Path, PathBuf};

/// The file `bbsplat blocks seams` writes in the chain's folder.
pub const SEAMS_FILE: &str = "seams.json";

/// Flags of `bbsplat blocks seams`.
#[derive(Args, Clone, Debug)]
pub struct SeamsArgs {
    /// The chain's folder (`bbsplat blocks run -o`).
    pub chain: PathBuf,
    /// Another model of the scene to measure the same way (a `bbsplat train` output's `model/`
    /// or the output folder holding it); repeatable.
    #[arg(long = "model")]
    pub models: Vec<PathBuf>,
    /// The band's half-width on the ground, in world units (default: the partition's margin).
    #[arg(long)]
    pub width: Option<f32>,
    #[command(flatten)]
    pub scene_args: SceneArgs,
}

/// Means over the test views of one model.
#[derive(Clone, Debug, Serialize)]
struct ModelSeams {
    model: PathBuf,
    psnr: f64,
    ssim: f64,
    band_psnr: Option<f64>,
    band_ssim: Option<f64>,
    off_band_psnr: Option<f64>,
    off_band_ssim: Option<f64>,
}

#[derive(Clone, Debug, Serialize)]
struct SeamsReport {
    width: f32,
    test_views: usize,
    /// Test views with at least one band pixel.
    views_with_band: usize,
    /// Band pixels over the pixels with a surface, all test views pooled.
    band_share: f64,
    models: Vec<ModelSeams>,
}

/// A model folder, or the `model/` inside a training's output folder.
fn model_folder(path: &Path) -> PathBuf {
    let inner = path.join(MODEL_DIR);
    if inner.is_dir() { inner } else { path.to_path_buf() }
}

fn mean(values: &[f64]) -> Option<f64> {
    (!values.is_empty()).then(|| values.iter().sum::<f64>() / values.len() as f64)
}

/// Runs `bbsplat blocks seams`.
pub fn run(args: &SeamsArgs) -> Result<()> {
    let plan = read_plan(&args.chain.join("blocks"))?;
    let partition = &plan.partition;
    let width = args.width.unwrap_or(partition.margin);
    anyhow::ensure!(
        width.is_finite() && width > 0.0,
        "the band's width must be a positive distance (got {width}; the partition's margin is {}): give --width",
        partition.margin
    );
    let coarse_dir = args.chain.join("coarse").join(MODEL_DIR);
    let (coarse, coarse_meta) = load_model(&coarse_dir)
        .with_context(|| format!("reading the chain's coarse model {}", coarse_dir.display()))?;
    let scene = args.scene_args.load_for_model(&plan.scene, &coarse_dir, &coarse_meta)?;
    anyhow::ensure!(
        !scene.test.is_empty(),
        "{}: the scene has no test view",
        plan.scene.display()
    );
    let settings_of = |sh_degree| RenderSettings {
        background: Vec3::from_array(scene.background.rgb()),
        sh_degree,
        ..RenderSettings::default()
    };
    // Band and off-band masks from the coarse model's depth, per test view.
    let coarse_set = coarse.activate();
    let mut masks = Vec::with_capacity(scene.test.len());
    let (mut band_pixels, mut surface_pixels) = (0usize, 0usize);
    for view in &scene.test {
        let out = render(
            &coarse_set.borrowed(),
            &view.camera,
            &settings_of(coarse_meta.sh_degree),
        );
        let band = seam_band_mask(partition, &view.camera, &out.alpha, &out.depth, width);
        let off: Vec<u8> = band
            .iter()
            .zip(&out.alpha)
            .map(|(&b, &a)| if b == 0 && a >= MIN_ALPHA { 255 } else { 0 })
            .collect();
        band_pixels += band.iter().filter(|&&b| b != 0).count();
        surface_pixels += out.alpha.iter().filter(|&&a| a >= MIN_ALPHA).count();
        masks.push((band, off));
    }
    let mut paths = vec![args.chain.join("polish").join(MODEL_DIR)];
    paths.extend(args.models.iter().map(|m| model_folder(m)));
    let mut models = Vec::new();
    for path in paths {
        let (model, meta) = load_model(&path).with_context(|| format!("reading the model {}", path.display()))?;
        let set = model.activate();
        let (mut whole, mut band, mut off) = (Vec::new(), Vec::new(), Vec::new());
        for (view, (band_mask, off_mask)) in scene.test.iter().zip(&masks) {
            let out = render(&set.borrowed(), &view.camera, &settings_of(meta.sh_degree));
            let truth = view.image.get()?.to_f32_rgb();
            let (w, h) = (view.camera.width as usize, view.camera.height as usize);
            whole.push(image_metrics(&out.rgb, &truth, w, h)?);
            band.extend(masked_image_metrics(&out.rgb, &truth, band_mask, w, h)?);
            off.extend(masked_image_metrics(&out.rgb, &truth, off_mask, w, h)?);
        }
        let psnr = |m: &[bbsplat::eval::ImageMetrics]| mean(&m.iter().map(|m| m.psnr).collect::<Vec<_>>());
        let ssim = |m: &[bbsplat::eval::ImageMetrics]| mean(&m.iter().map(|m| m.ssim).collect::<Vec<_>>());
        models.push(ModelSeams {
            model: path,
            psnr: psnr(&whole).unwrap_or(f64::NAN),
            ssim: ssim(&whole).unwrap_or(f64::NAN),
            band_psnr: psnr(&band),
            band_ssim: ssim(&band),
            off_band_psnr: psnr(&off),
            off_band_ssim: ssim(&off),
        });
    }
    let report = SeamsReport {
        width,
        test_views: scene.test.len(),
        views_with_band: masks.iter().filter(|(b, _)| b.iter().any(|&v| v != 0)).count(),
        band_share: band_pixels as f64 / surface_pixels.max(1) as f64,
        models,
    };
    let json = serde_json::to_string_pretty(&report).context("encoding the seams report")?;
    bbsplat::file_io::write_atomic(&args.chain.join(SEAMS_FILE), json.as_bytes())?;
    let db = |v: Option<f64>| v.map_or("-".to_string(), |p| format!("{p:.2} dB"));
    println!(
        "seam band: within {width} of a cut, {:.1} % of the surface pixels, in {} of {} test views",
        100.0 * report.band_share,
        report.views_with_band,
        report.test_views
    );
    for m in &report.models {
        println!(
            "{}: PSNR {:.2} dB, in the band {}, off it {}",
            m.model.display(),
            m.psnr,
            db(m.band_psnr),
            db(m.off_band_psnr)
        );
    }
    println!("wrote {}", args.chain.join(SEAMS_FILE).display());
    Ok(())
}
