//! `bbsplat render <model> <scene> -o <dir>` and `bbsplat eval <model> <scene>`.

use super::common::{
    SceneArgs, Split, render_file_name, split_views, start_threads, write_png_atomic, write_text_atomic,
};
use anyhow::{Context, Result};
use bbsplat::eval::{EvalReport, EvalView, evaluate_views};
use bbsplat::model_file::load_model;
use bbsplat::raster::RenderSettings;
use bbsplat::scene::Background;
use clap::Args;
use glam::Vec3;
use std::path::PathBuf;

/// Flags shared by `render` and `eval`.
#[derive(Args, Clone, Debug)]
pub struct ModelSceneArgs {
    /// A model folder written by `bbsplat train` (`<out>/model`).
    pub model: PathBuf,
    /// The dataset whose cameras are rendered.
    pub scene: PathBuf,
    #[command(flatten)]
    pub scene_args: SceneArgs,
    /// Which views to use.
    #[arg(long, value_enum, default_value_t = Split::Test)]
    pub split: Split,
    /// Rayon worker threads (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
}

/// Flags of `bbsplat render`.
#[derive(Args, Clone, Debug)]
pub struct RenderArgs {
    #[command(flatten)]
    pub common: ModelSceneArgs,
    /// Output folder for the PNG renders (created if missing).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Also write the ground-truth images beside the renders (`*_truth.png`).
    #[arg(long)]
    pub with_truth: bool,
}

/// Flags of `bbsplat eval`.
#[derive(Args, Clone, Debug)]
pub struct EvalArgs {
    #[command(flatten)]
    pub common: ModelSceneArgs,
    /// Print machine-readable JSON (per view and mean) instead of a table.
    #[arg(long)]
    pub json: bool,
    /// Also write the JSON report to this file.
    #[arg(long)]
    pub report: Option<PathBuf>,
}

fn run_views(
    common: &ModelSceneArgs,
    mut on_render: impl FnMut(usize, &str, &[f32], &[f32], u32, u32) -> Result<()>,
) -> Result<EvalReport> {
    start_threads(common.threads)?;
    let (model, meta) =
        load_model(&common.model).with_context(|| format!("loading the model {}", common.model.display()))?;
    // The model's background unless --background overrides it (the truth images are composited
    // on the same one).
    let model_background = Background::from_rgb(meta.background).ok_or_else(|| {
        anyhow::anyhow!(
            "{}: background {:?} is neither black nor white; give --background",
            common.model.display(),
            meta.background
        )
    });
    let background = match common.scene_args.background {
        Some(arg) => arg.into(),
        None => model_background?,
    };
    let scene = common.scene_args.load(&common.scene, true, background)?;
    let views = split_views(&scene, common.split);
    anyhow::ensure!(
        !views.is_empty(),
        "{}: the {:?} split has no view",
        common.scene.display(),
        common.split
    );
    let activated = model.activate();
    let settings = RenderSettings {
        background: Vec3::from_array(scene.background.rgb()),
        sh_degree: meta.sh_degree,
        ..RenderSettings::default()
    };
    let mut failure = None;
    let mut index = 0;
    let report = evaluate_views(
        &activated.borrowed(),
        // Each view's float values are made for its evaluation only (not all views at once).
        views.iter().map(|v| EvalView {
            name: &v.name,
            camera: &v.camera,
            rgb: std::borrow::Cow::Owned(v.image.to_f32_rgb()),
        }),
        &settings,
        |view, rendered| {
            if failure.is_none()
                && let Err(e) = on_render(
                    index,
                    view.name,
                    rendered,
                    &view.rgb,
                    view.camera.width,
                    view.camera.height,
                )
            {
                failure = Some(e);
            }
            index += 1;
        },
    )?;
    match failure {
        Some(e) => Err(e),
        None => Ok(report),
    }
}

/// Runs `bbsplat render`.
pub fn render(args: RenderArgs) -> Result<()> {
    std::fs::create_dir_all(&args.output).with_context(|| format!("creating {}", args.output.display()))?;
    let report = run_views(&args.common, |i, name, rendered, truth, w, h| {
        let file = render_file_name(i, name);
        write_png_atomic(&args.output.join(&file), rendered, w, h)?;
        if args.with_truth {
            write_png_atomic(&args.output.join(file.replace(".png", "_truth.png")), truth, w, h)?;
        }
        Ok(())
    })?;
    println!(
        "wrote {} renders to {} (mean PSNR {:.2} dB, SSIM {:.4}, {:.1} ms per frame)",
        report.views.len(),
        args.output.display(),
        report.mean_psnr,
        report.mean_ssim,
        report.mean_render_ms
    );
    Ok(())
}

/// Runs `bbsplat eval`.
pub fn eval(args: EvalArgs) -> Result<()> {
    let report = run_views(&args.common, |_, _, _, _, _, _| Ok(()))?;
    let json = serde_json::to_string_pretty(&report).context("encoding the report")?;
    if let Some(path) = &args.report {
        write_text_atomic(path, &json)?;
    }
    if args.json {
        println!("{json}");
    } else {
        print!("{}", report.table());
    }
    Ok(())
}
