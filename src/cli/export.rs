//! `bbsplat export <model> <scene> -o <dir> --format obj|glb|splat-ply|gltf-splat`: the billboards
//! as textured planes, or as flat 3D Gaussians fitted to them (the library: `bbsplat::export`;
//! conventions: docs/export.md).

use super::common::{SceneArgs, start_threads};
use anyhow::{Context, Result};
use bbsplat::export::gaussians::{FitRule, billboards_as_gaussians};
use bbsplat::export::glb::{NamedCamera, write_glb};
use bbsplat::export::obj::write_obj;
use bbsplat::export::planes::plane_mesh;
use bbsplat::export::prune::{PruneRule, accumulate_impact, kept_billboards};
use bbsplat::export::splat_glb::write_splat_glb;
use bbsplat::export::splat_ply::write_splat_ply;
use bbsplat::raster::RenderSettings;
use clap::{Args, ValueEnum};
use glam::Vec3;
use std::path::PathBuf;

/// The file format written.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum ExportFormat {
    /// Wavefront OBJ + MTL + RGBA PNG atlas, as the reference's `--save_planes` (planes_mesh.*).
    Obj,
    /// glTF 2.0 binary (planes_mesh.glb): the quads, the atlas with alpha blending, unlit, and the
    /// dataset's cameras.
    Glb,
    /// 3D Gaussian Splatting PLY (gaussians.ply): flat Gaussians fitted to the billboards, the
    /// Inria field layout.
    SplatPly,
    /// glTF 2.0 binary with `KHR_gaussian_splatting` (gaussians.glb): the same Gaussians as POINTS,
    /// and the dataset's cameras.
    GltfSplat,
}

/// Flags of `bbsplat export`.
#[derive(Args, Clone, Debug)]
pub struct ExportArgs {
    /// A model folder written by `bbsplat train` (`<out>/model`).
    pub model: PathBuf,
    /// The dataset: its training views rank the billboards (impact), its cameras go into the glTF.
    pub scene: PathBuf,
    #[command(flatten)]
    pub scene_args: SceneArgs,
    /// Output folder (created if missing); files are named planes_mesh.* (planes) or gaussians.*
    /// (Gaussians).
    #[arg(short, long)]
    pub output: PathBuf,
    /// File format.
    #[arg(long, value_enum, default_value_t = ExportFormat::Glb)]
    pub format: ExportFormat,
    /// Keep a billboard only if its share of the total impact over the training views is above
    /// this (the reference's 1e-6).
    #[arg(long, default_value_t = 1e-6)]
    pub min_impact_share: f64,
    /// Keep a billboard only if its largest alpha texel is above this (the reference's 0.2).
    #[arg(long, default_value_t = 0.2)]
    pub min_max_alpha: f32,
    /// Gaussian formats: at most this many Gaussians per billboard (the library default, 8).
    #[arg(long, default_value_t = 8, value_parser = clap::value_parser!(u32).range(1..=256))]
    pub max_gaussians: u32,
    /// Gaussian formats: stop splitting a billboard once the RMS error of its fit (alpha and
    /// premultiplied colour at the texel centres, 0-1 units) is at most this.
    #[arg(long, default_value_t = FitRule::default().max_error)]
    pub max_fit_error: f32,
    /// Rayon worker threads (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
}

/// Runs `bbsplat export`.
pub fn run(args: ExportArgs) -> Result<()> {
    anyhow::ensure!(
        args.max_fit_error.is_finite() && args.max_fit_error >= 0.0,
        "--max-fit-error must be a finite number ≥ 0, got {}",
        args.max_fit_error
    );
    start_threads(args.threads)?;
    let (model, meta, scene) = args.scene_args.load_model_and_scene(&args.model, &args.scene)?;
    anyhow::ensure!(
        !scene.train.is_empty(),
        "{}: no training view to measure the billboards' impact",
        args.scene.display()
    );
    let activated = model.activate();
    let set = activated.borrowed();
    let background = Vec3::from_array(scene.background.rgb());
    let settings = RenderSettings {
        background,
        sh_degree: meta.sh_degree,
        ..RenderSettings::default()
    };
    let impact = accumulate_impact(&set, scene.train.iter().map(|v| &v.camera), &settings);
    let rule = PruneRule {
        min_impact_share: args.min_impact_share,
        min_max_alpha: args.min_max_alpha,
    };
    let kept = kept_billboards(&impact, set.textures, set.texels(), &rule);
    anyhow::ensure!(
        !kept.is_empty(),
        "{}: {}",
        args.model.display(),
        bbsplat::export::ExportError::NothingKept {
            total: set.len(),
            min_impact_share: rule.min_impact_share,
            min_max_alpha: rule.min_max_alpha,
        }
    );
    let cameras: Vec<NamedCamera> = scene
        .train
        .iter()
        .chain(&scene.test)
        .map(|v| NamedCamera {
            name: &v.name,
            camera: &v.camera,
        })
        .collect();
    let kept_line = format!(
        "kept {} of {} billboards (impact share > {:e} over {} training views, max alpha > {})",
        kept.len(),
        set.len(),
        rule.min_impact_share,
        scene.train.len(),
        rule.min_max_alpha,
    );
    let files = match args.format {
        ExportFormat::Obj | ExportFormat::Glb => {
            let mesh = plane_mesh(&set, &kept)?;
            println!(
                "{kept_line}; atlas {}×{}",
                mesh.atlas.layout.width, mesh.atlas.layout.height
            );
            create_output(&args.output)?;
            if args.format == ExportFormat::Obj {
                write_obj(&args.output, "planes_mesh", &mesh)?
            } else {
                let path = args.output.join("planes_mesh.glb");
                let size = write_glb(&path, &mesh, &cameras, background)?;
                vec![(path, size)]
            }
        }
        ExportFormat::SplatPly | ExportFormat::GltfSplat => {
            let fit = FitRule {
                max_gaussians: args.max_gaussians as usize,
                max_error: args.max_fit_error,
            };
            let gaussians = billboards_as_gaussians(&set, &kept, meta.sh_degree, &fit);
            anyhow::ensure!(
                !gaussians.is_empty(),
                "{}: no Gaussian left (every kept billboard's opacity is below 1/255)",
                args.model.display()
            );
            println!("{kept_line}");
            let mean_error = gaussians.fit_errors.iter().map(|&e| f64::from(e)).sum::<f64>() / kept.len() as f64;
            println!(
                "{} Gaussians: {:.2} per billboard (at most {}), mean fit error {mean_error:.4} (stop at {})",
                gaussians.len(),
                gaussians.len() as f64 / kept.len() as f64,
                fit.max_gaussians,
                fit.max_error
            );
            create_output(&args.output)?;
            if args.format == ExportFormat::SplatPly {
                let path = args.output.join("gaussians.ply");
                let size = write_splat_ply(&path, &gaussians)?;
                vec![(path, size)]
            } else {
                let path = args.output.join("gaussians.glb");
                let size = write_splat_glb(&path, &gaussians, &cameras, background)?;
                vec![(path, size)]
            }
        }
    };
    for (path, size) in files {
        println!("wrote {} ({size} bytes)", path.display());
    }
    Ok(())
}

fn create_output(dir: &std::path::Path) -> Result<()> {
    super::common::refuse_non_folder(dir)?;
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))
}
