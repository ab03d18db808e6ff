//! PSNR between two PNG images of the same size (8-bit RGB, `bbsplat::loss::psnr::psnr` on
//! `byte / 255` values), and optionally the two side by side (first left) in one PNG.
//!
//! ```text
//! cargo run --release --features examples --example compare_images -- A.png B.png [--side-by-side OUT.png]
//! ```
//! Used for the Blender and browser comparisons of docs/export.md.

use std::process::ExitCode;

fn load(path: &str) -> Result<image::RgbImage, String> {
    image::open(path)
        .map(|i| i.to_rgb8())
        .map_err(|e| format!("{path}: {e}"))
}

fn run() -> Result<(), String> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (a_path, b_path) = match (args.first(), args.get(1)) {
        (Some(a), Some(b)) => (a, b),
        _ => return Err("usage: compare_images A.png B.png [--side-by-side OUT.png]".into()),
    };
    let side = match args.get(2).map(String::as_str) {
        Some("--side-by-side") => Some(args.get(3).ok_or("--side-by-side needs a file")?),
        Some(other) => return Err(format!("unknown option {other}")),
        None => None,
    };
    let (a, b) = (load(a_path)?, load(b_path)?);
    if a.dimensions() != b.dimensions() {
        return Err(format!(
            "{a_path} is {:?} but {b_path} is {:?}",
            a.dimensions(),
            b.dimensions()
        ));
    }
    let to_f32 = |im: &image::RgbImage| im.as_raw().iter().map(|&x| f32::from(x) / 255.0).collect::<Vec<f32>>();
    let psnr = bbsplat::loss::psnr::psnr(&to_f32(&a), &to_f32(&b)).map_err(|e| e.to_string())?;
    println!("PSNR {psnr:.2} dB ({}x{})", a.width(), a.height());
    if let Some(out) = side {
        const GAP: u32 = 4;
        let (w, h) = a.dimensions();
        let mut both = image::RgbImage::from_pixel(2 * w + GAP, h, image::Rgb([255, 255, 255]));
        image::imageops::replace(&mut both, &a, 0, 0);
        image::imageops::replace(&mut both, &b, i64::from(w + GAP), 0);
        both.save(out).map_err(|e| format!("{out}: {e}"))?;
        println!("wrote {out}");
    }
    Ok(())
}

fn main() -> ExitCode {
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("compare_images: {e}");
            ExitCode::FAILURE
        }
    }
}
