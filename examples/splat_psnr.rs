//! PSNR of an exported 3DGS PLY (`bbsplat export --format splat-ply`) drawn by the tests'
//! independent 3DGS renderer (`tests/suite/splat_reference.rs`, included by path: no code shared
//! with the crate's renderer) against `bbsplat render` of the billboards, over a dataset's test
//! views.
//!
//! ```text
//! bbsplat render MODEL SCENE -o RENDERS                   # RENDERS/0000_<name>.png, ...
//! bbsplat export MODEL SCENE -o OUT --format splat-ply    # OUT/gaussians.ply
//! cargo run --release --features examples --example splat_psnr -- OUT/gaussians.ply MODEL SCENE RENDERS [--views N] [--save DIR]
//! ```
//! The model folder gives the background and the SH degree (`bbsplat.json`); the scene is loaded
//! with the default options (those of `bbsplat render` without flags). Prints one line per view
//! and the mean; `--views N` takes the first N test views (default: all), `--save DIR` writes
//! each 3DGS image beside its render (left 3DGS, right `bbsplat render`).
//! Used for the figures of docs/export.md.

// The included test files are written for the test suite's lints (tests/suite/main.rs).
#![allow(clippy::needless_range_loop, clippy::len_without_is_empty)]

#[allow(dead_code)]
#[path = "../tests/suite/f64_reference/renderer.rs"]
pub mod renderer;

mod f64_reference {
    pub use super::renderer;
}

#[allow(dead_code)]
#[path = "../tests/suite/splat_reference.rs"]
mod splat_reference;

use std::path::{Path, PathBuf};
use std::process::ExitCode;

fn run() -> Result<(), String> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 4 {
        return Err("usage: splat_psnr PLY MODEL SCENE RENDERS [--views N] [--save DIR]".into());
    }
    let (ply, model, scene, renders) = (&args[0], Path::new(&args[1]), Path::new(&args[2]), Path::new(&args[3]));
    let mut views = usize::MAX;
    let mut save: Option<PathBuf> = None;
    let mut rest = args[4..].iter();
    while let Some(flag) = rest.next() {
        let value = rest.next().ok_or(format!("{flag} needs a value"))?;
        match flag.as_str() {
            "--views" => views = value.parse().map_err(|e| format!("--views {value}: {e}"))?,
            "--save" => save = Some(PathBuf::from(value)),
            other => return Err(format!("unknown option {other}")),
        }
    }
    let bytes = std::fs::read(ply).map_err(|e| format!("{ply}: {e}"))?;
    let splats = splat_reference::splats_from_ply(&bytes);
    let meta_path = model.join("bbsplat.json");
    let meta: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&meta_path).map_err(|e| format!("{}: {e}", meta_path.display()))?)
            .map_err(|e| format!("{}: {e}", meta_path.display()))?;
    let background: [f64; 3] = serde_json::from_value(meta["background"].clone()).map_err(|e| e.to_string())?;
    let sh_degree = meta["sh_degree"].as_u64().ok_or("no sh_degree")? as u32;
    let options = bbsplat::scene::LoadOptions {
        print_warnings: false,
        ..Default::default()
    };
    let scene = bbsplat::scene::load(scene, &options).map_err(|e| e.to_string())?;
    let mut names: Vec<PathBuf> = std::fs::read_dir(renders)
        .map_err(|e| format!("{}: {e}", renders.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "png"))
        .collect();
    names.sort();
    if let Some(dir) = &save {
        std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    }
    let mut total = 0.0;
    let mut count = 0;
    for (view, png) in scene.test.iter().zip(&names).take(views) {
        let expected = image::open(png)
            .map_err(|e| format!("{}: {e}", png.display()))?
            .to_rgb8();
        let cam = &view.camera;
        if expected.dimensions() != (cam.width, cam.height) {
            return Err(format!("{}: not {}×{}", png.display(), cam.width, cam.height));
        }
        let got = splat_reference::to_bytes(&splat_reference::render_splats(&splats, cam, sh_degree, background));
        let f = |x: &[u8]| x.iter().map(|&v| f32::from(v) / 255.0).collect::<Vec<f32>>();
        let psnr = bbsplat::loss::psnr::psnr(&f(&got), &f(expected.as_raw())).map_err(|e| e.to_string())?;
        println!("{}: {psnr:.2} dB", view.name);
        if let Some(dir) = &save {
            let (w, h) = (cam.width, cam.height);
            let mut both = image::RgbImage::new(2 * w, h);
            for y in 0..h {
                for x in 0..w {
                    let at = 3 * (y * w + x) as usize;
                    both.put_pixel(x, y, image::Rgb([got[at], got[at + 1], got[at + 2]]));
                    both.put_pixel(w + x, y, *expected.get_pixel(x, y));
                }
            }
            let out = dir.join(png.file_name().unwrap());
            both.save(&out).map_err(|e| format!("{}: {e}", out.display()))?;
        }
        total += psnr;
        count += 1;
    }
    if count == 0 {
        return Err("no test view with a render".into());
    }
    println!(
        "mean over {count} views: {:.2} dB ({} Gaussians)",
        total / count as f64,
        splats.len()
    );
    Ok(())
}

fn main() -> ExitCode {
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("splat_psnr: {e}");
            ExitCode::FAILURE
        }
    }
}
