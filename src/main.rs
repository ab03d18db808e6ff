//! The `bbsplat` command line.

mod cli;

use anyhow::Result;
use clap::{Parser, Subcommand};
use std::path::PathBuf;

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
        /// Training views (the 8 test views come on top).
        #[arg(long, default_value_t = 32)]
        views: usize,
        /// Seed of the scene, the initialisation and the view order.
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Folder for the test renders (PNG); nothing is written when omitted.
        #[arg(short, long)]
        output: Option<PathBuf>,
        /// Rayon worker threads (default: all cores).
        #[arg(long)]
        threads: Option<usize>,
        /// Write the demo scene as a COLMAP dataset (sparse/0 + images) to this folder instead of
        /// training, e.g. to try `bbsplat train` without downloading anything.
        #[arg(long)]
        export: Option<PathBuf>,
        /// With --export: write the street instead, this many copies of the demo's objects along
        /// a line seen from two tracks of cameras (8 per copy on each, at --resolution), the test
        /// scene of block-wise training (docs/cluster.md).
        #[arg(long, requires = "export", value_name = "COPIES", value_parser = clap::value_parser!(u16).range(1..=256))]
        street: Option<u16>,
    },
    /// Train a billboard model on a dataset (COLMAP, NeRF-synthetic, instant-ngp, NeuS/IDR or LLFF, detected).
    Train(Box<cli::train_args::TrainArgs>),
    /// Render a saved model from a dataset's cameras to PNG files.
    Render(cli::render::RenderArgs),
    /// Evaluate a saved model on a dataset's views: per-view and mean PSNR/SSIM (8-bit images).
    Eval(cli::render::EvalArgs),
    /// Export a saved model as textured planes: OBJ + MTL + PNG (as the reference) or glTF binary.
    Export(cli::export::ExportArgs),
    /// Extract a triangle mesh (PLY) by fusing the model's rendered depth of the training views
    /// into a TSDF volume (marching cubes, largest components kept).
    Mesh(cli::mesh::MeshArgs),
    /// Train each scene with the defaults for `--minutes` and write a table of test PSNR, SSIM,
    /// LPIPS, time, steps, billboards and peak memory beside the paper's published figures.
    Benchmark(cli::benchmark::BenchmarkArgs),
    /// The stages of a large scene trained as spatial blocks that are not `train` runs: `split`
    /// (cells, each block's views and initial billboards, from a coarse model) and `merge`
    /// (docs/cluster.md).
    Blocks {
        #[command(subcommand)]
        command: cli::blocks::BlocksCommand,
    },
    /// Write a self-contained WebGL2 viewer page of a saved model (optionally serve it locally).
    View(cli::view::ViewArgs),
}

fn main() -> Result<()> {
    let cli = Cli::parse();
    match cli.command {
        Command::Demo {
            iterations,
            billboards,
            texture_size,
            resolution,
            views,
            seed,
            output,
            threads,
            export,
            street,
        } => {
            cli::common::start_threads(threads)?;
            let size = cli::demo::DemoSize {
                resolution,
                train_views: views,
                billboards,
            };
            match (street, &export) {
                (Some(copies), Some(dir)) => cli::demo::export_street(copies.into(), resolution, seed, dir),
                _ => cli::demo::run(iterations, size, texture_size, seed, output, export),
            }
        }
        Command::Train(args) => cli::train::run(*args),
        Command::Render(args) => cli::render::render(args),
        Command::Eval(args) => cli::render::eval(args),
        Command::Export(args) => cli::export::run(args),
        Command::Mesh(args) => cli::mesh::run(args),
        Command::View(args) => cli::view::run(args),
        Command::Benchmark(args) => cli::benchmark::run(args),
        Command::Blocks { command } => cli::blocks::run(command),
    }
}
