//! `bbsplat mesh <model> <scene> -o mesh.ply`: a triangle mesh of the model's surface by TSDF
//! fusion of its rendered depth (the library: `bbsplat::mesh`; conventions: docs/mesh.md).

use super::common::{SceneArgs, start_threads};
use anyhow::{Context, Result};
use bbsplat::mesh::chamfer::{chamfer, inside_box, sample_mesh};
use bbsplat::mesh::params::{DepthKind, MeshParams};
use bbsplat::mesh::pipeline::extract_mesh;
use bbsplat::mesh::ply::write_ply;
use bbsplat::mesh::tsdf::FusionView;
use bbsplat::raster::RenderSettings;
use clap::{Args, ValueEnum};
use glam::Vec3;
use std::path::PathBuf;
use std::time::Instant;

/// The depth flag.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum DepthArg {
    /// Alpha-weighted mean depth (the reference's default).
    Expected,
    /// Median depth (the reference's `--depth_ratio 1`).
    Median,
}

/// Flags of `bbsplat mesh`.
#[derive(Args, Clone, Debug)]
pub struct MeshArgs {
    /// A model folder written by `bbsplat train` (`<out>/model`).
    pub model: PathBuf,
    /// The dataset whose training views are rendered and fused.
    pub scene: PathBuf,
    #[command(flatten)]
    pub scene_args: SceneArgs,
    /// Output PLY file (binary, vertex normals and colours).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Which rendered depth is fused.
    #[arg(long, value_enum, default_value_t = DepthArg::Expected)]
    pub depth: DepthArg,
    /// Voxels along the grid's longest side (sets the voxel size unless --voxel-size is given).
    #[arg(long, default_value_t = 256)]
    pub resolution: usize,
    /// Voxel size in world units (default: the grid's longest side / --resolution).
    #[arg(long)]
    pub voxel_size: Option<f32>,
    /// Truncation of the signed distance in world units (default: 5 voxels, the reference's).
    #[arg(long)]
    pub sdf_trunc: Option<f32>,
    /// Depths beyond this are not fused (default: twice the smallest camera distance to the
    /// cameras' focus point, 2DGS's rule).
    #[arg(long)]
    pub depth_trunc: Option<f32>,
    /// Pixels whose rendered alpha is below this fuse nothing (0: only uncovered pixels, as the
    /// reference).
    #[arg(long, default_value_t = 0.0)]
    pub min_alpha: f32,
    /// Do not mask pixels by the images' own alpha (NeRF-synthetic), which the reference does.
    #[arg(long)]
    pub no_alpha_mask: bool,
    /// Keep the largest N connected components (the reference's num_cluster).
    #[arg(long, default_value_t = 1000)]
    pub components: usize,
    /// Drop components with fewer triangles (the reference's 50).
    #[arg(long, default_value_t = 50)]
    pub min_component_triangles: u32,
    /// The scene is the demo (`bbsplat demo --export`): measure the mesh against the demo's true
    /// surface seen by the training cameras inside the grid (Chamfer distance, normal
    /// consistency) with this many samples on each surface (at most 10 000 000).
    #[arg(long, value_parser = super::flag_parsers::count_between::<1, { super::flag_parsers::MAX_COMPARE_SAMPLES }>)]
    pub compare_demo: Option<usize>,
    /// Rayon worker threads (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
}

/// Runs `bbsplat mesh`.
pub fn run(args: MeshArgs) -> Result<()> {
    start_threads(args.threads)?;
    let start = Instant::now();
    let (model, meta, scene) = args.scene_args.load_model_and_scene(&args.model, &args.scene)?;
    anyhow::ensure!(
        !scene.train.is_empty(),
        "{}: no training view to fuse",
        args.scene.display()
    );
    let activated = model.activate();
    let set = activated.borrowed();
    // The billboards that bound the object: those with a visible alpha texel.
    let texels = set.texels();
    let centres: Vec<Vec3> = (0..set.len())
        .filter(|&i| set.texture_of(i).iter().any(|t| t[3] > 0.2))
        .map(|i| set.positions[i])
        .collect();
    anyhow::ensure!(texels > 0, "{}: the model has no texture", args.model.display());
    let cameras: Vec<_> = scene.train.iter().map(|v| v.camera).collect();
    let mut params = MeshParams::for_scene(&cameras, &centres, args.resolution).with_context(|| {
        format!(
            "{}: scaling the mesh parameters to {}",
            args.model.display(),
            args.scene.display()
        )
    })?;
    params.depth = match args.depth {
        DepthArg::Expected => DepthKind::Expected,
        DepthArg::Median => DepthKind::Median,
    };
    if let Some(v) = args.voxel_size {
        params.voxel_size = v;
        params.sdf_trunc = 5.0 * v;
    }
    if let Some(t) = args.sdf_trunc {
        params.sdf_trunc = t;
    }
    if let Some(d) = args.depth_trunc {
        params.depth_trunc = d;
    }
    params.min_alpha = args.min_alpha;
    params.use_coverage = !args.no_alpha_mask;
    params.keep_components = args.components;
    params.min_component_triangles = args.min_component_triangles;
    params.validate()?;
    let dims = params.dims();
    println!(
        "grid {}×{}×{} voxels of {:.5} from {:.3?} to {:.3?}; sdf_trunc {:.5}, depth_trunc {:.3}; {:?} depth, min alpha {}",
        dims[0],
        dims[1],
        dims[2],
        params.voxel_size,
        params.bounds_min.to_array(),
        params.bounds_max.to_array(),
        params.sdf_trunc,
        params.depth_trunc,
        params.depth,
        params.min_alpha
    );
    let views: Vec<FusionView> = scene
        .train
        .iter()
        .map(|v| FusionView {
            camera: &v.camera,
            coverage: v.coverage.as_deref(),
        })
        .collect();
    let settings = RenderSettings {
        background: Vec3::from_array(scene.background.rgb()),
        sh_degree: meta.sh_degree,
        ..RenderSettings::default()
    };
    let (mesh, report) = extract_mesh(&set, &views, &settings, &params)
        .with_context(|| format!("{}: extracting the mesh", args.model.display()))?;
    let size = write_ply(&args.output, &mesh)?;
    println!(
        "fused {} training views: {} of {} voxels observed; marching cubes {} triangles; kept {} of {} components (≥ {} triangles): {} vertices, {} triangles, area {:.4}",
        views.len(),
        report.observed,
        dims.iter().product::<usize>(),
        report.raw_triangles,
        report.components.kept,
        report.components.components,
        report.components.threshold,
        mesh.positions.len(),
        mesh.triangles.len(),
        mesh.area()
    );
    println!(
        "wrote {} ({size} bytes) in {:.1} s",
        args.output.display(),
        start.elapsed().as_secs_f64()
    );
    if let Some(count) = args.compare_demo {
        let truth = bbsplat::demo::surface::sample_true_surface(count, 1);
        let seen = bbsplat::demo::surface::visible_from(&truth, &cameras);
        let truth = inside_box(&seen, params.bounds_min, params.bounds_max);
        let samples = sample_mesh(&mesh, count, 2)?;
        let r = chamfer(&samples, &truth)?;
        println!(
            "against the demo's true surface ({} of {count} samples seen by the training cameras and inside the grid; {count} on the mesh):",
            truth.points.len()
        );
        println!(
            "  mesh→truth mean {:.5} median {:.5} p90 {:.5}; truth→mesh mean {:.5} median {:.5} p90 {:.5}; chamfer {:.5}; normal consistency {:.4}",
            r.a_to_b.mean,
            r.a_to_b.median,
            r.a_to_b.p90,
            r.b_to_a.mean,
            r.b_to_a.median,
            r.b_to_a.p90,
            r.chamfer,
            r.normal_consistency
        );
    }
    Ok(())
}
