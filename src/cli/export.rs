//! `bbsplat export <model> <scene> -o <dir> --format obj|glb`: the billboards as textured planes
//! (the library: `bbsplat::export`; conventions: docs/export.md).

use super::common::{SceneArgs, start_threads};
use anyhow::{Context, Result};
use bbsplat::export::glb::{NamedCamera, write_glb};
use bbsplat::export::obj::write_obj;
use bbsplat::export::planes::plane_mesh;
use bbsplat::export::prune::{PruneRule, accumulate_impact, kept_billboards};
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
    /// Output folder (created if missing); files are named planes_mesh.*.
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
    /// Rayon worker threads (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
}

/// Runs `bbsplat export`.
pub fn run(args: ExportArgs) -> Result<()> {
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
    let mesh = plane_mesh(&set, &kept)?;
    super::common::refuse_non_folder(&args.output)?;
    std::fs::create_dir_all(&args.output).with_context(|| format!("creating {}", args.output.display()))?;
    let files = match args.format {
        ExportFormat::Obj => write_obj(&args.output, "planes_mesh", &mesh)?,
        ExportFormat::Glb => {
            let cameras: Vec<NamedCamera> = scene
                .train
                .iter()
                .chain(&scene.test)
                .map(|v| NamedCamera {
                    name: &v.name,
                    camera: &v.camera,
                })
                .collect();
            let path = args.output.join("planes_mesh.glb");
            let size = write_glb(&path, &mesh, &cameras, background)?;
            vec![(path, size)]
        }
    };
    println!(
        "kept {} of {} billboards (impact share > {:e} over {} training views, max alpha > {}); atlas {}×{}",
        kept.len(),
        set.len(),
        rule.min_impact_share,
        scene.train.len(),
        rule.min_max_alpha,
        mesh.atlas.layout.width,
        mesh.atlas.layout.height
    );
    for (path, size) in files {
        println!("wrote {} ({size} bytes)", path.display());
    }
    Ok(())
}
