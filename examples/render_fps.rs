//! Forward-only render speed (frames per second) at several billboard budgets and image sizes,
//! on the standard random benchmark scene (`RandomSceneConfig::benchmark`: TS = 16, SH degree 3,
//! footprint `width / sqrt(N)` so overlap per pixel stays roughly constant), one fixed view.
//!
//! ```text
//! cargo run --release --features examples --example render_fps -- --sizes 400,800 --budgets 10000,50000,100000,200000 --frames 7
//! ```
//!
//! Per (size, budget): one warm-up frame, then `--frames` timed frames; prints the median and
//! minimum frame time and the FPS of the median as a markdown table. Scene generation is not
//! timed. Memory: about 4.3 kB per billboard (TS = 16 textures), so 200k billboards take ~0.9 GB.
use anyhow::{Result, ensure};
use bbsplat::billboards::{RandomSceneConfig, random_scene, random_scene_camera};
use bbsplat::raster::{RenderSettings, render};
use clap::Parser;
use std::time::Instant;

#[derive(Parser)]
#[command(
    name = "render_fps",
    about = "Forward-only frames per second on the random benchmark scene"
)]
struct Args {
    /// Square image sides in pixels.
    #[arg(long, value_delimiter = ',', default_values_t = [400u32, 800])]
    sizes: Vec<u32>,
    /// Billboard counts.
    #[arg(long, value_delimiter = ',', default_values_t = [10_000usize, 50_000, 100_000, 200_000])]
    budgets: Vec<usize>,
    /// Timed frames per configuration (after one warm-up frame).
    #[arg(long, default_value_t = 7)]
    frames: usize,
    /// Rayon worker threads (default: all cores).
    #[arg(long)]
    threads: Option<usize>,
}

fn main() -> Result<()> {
    let args = Args::parse();
    ensure!(args.frames >= 1, "--frames must be at least 1");
    if let Some(t) = args.threads {
        rayon::ThreadPoolBuilder::new().num_threads(t).build_global()?;
    }
    println!(
        "forward render, random benchmark scene (TS 16, SH degree 3), {} rayon threads, median of {} frames\n",
        rayon::current_num_threads(),
        args.frames
    );
    println!("| image | billboards | median ms | min ms | FPS (median) |");
    println!("|---|--:|--:|--:|--:|");
    let settings = RenderSettings::default();
    for &size in &args.sizes {
        for &n in &args.budgets {
            let scene = random_scene(&RandomSceneConfig::benchmark(n, size, size));
            let cam = random_scene_camera(size, size);
            let set = scene.borrowed();
            std::hint::black_box(render(&set, &cam, &settings));
            let mut ms: Vec<f64> = (0..args.frames)
                .map(|_| {
                    let t = Instant::now();
                    std::hint::black_box(render(&set, &cam, &settings));
                    t.elapsed().as_secs_f64() * 1e3
                })
                .collect();
            ms.sort_by(f64::total_cmp);
            let median = if ms.len() % 2 == 1 {
                ms[ms.len() / 2]
            } else {
                0.5 * (ms[ms.len() / 2 - 1] + ms[ms.len() / 2])
            };
            println!(
                "| {size}×{size} | {n} | {median:.1} | {:.1} | {:.1} |",
                ms[0],
                1e3 / median
            );
        }
    }
    Ok(())
}
