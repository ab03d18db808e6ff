//! `bbsplat render <model> <scene> -o <dir>` and `bbsplat eval <model> <scene>`.

use super::common::{
    LpipsNetwork, OutputDir, SceneArgs, Split, render_file_name, split_views, start_threads, write_png_atomic,
    write_text_atomic,
};
use anyhow::{Context, Result};
use bbsplat::eval::{EvalReport, EvalView, evaluate_views, lpips_u8, until_error};
use bbsplat::lpips::Lpips;
use bbsplat::raster::RenderSettings;
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
    /// Instead of the dataset's views, render N frames on a circle around the scene
    /// (`bbsplat::export::orbit`: placed from the training cameras) to `orbit_NNNN.png` and an
    /// animated `orbit.gif` (looping, --frame-ms per frame).
    /// At most 100 000 frames.
    #[arg(long, value_name = "N", value_parser = super::flag_parsers::count_between::<1, { super::flag_parsers::MAX_ORBIT_FRAMES }>)]
    pub orbit: Option<usize>,
    /// Milliseconds per frame of `orbit.gif`: 10 to 655 350, a multiple of 10 (a GIF stores
    /// hundredths of a second).
    #[arg(long, default_value_t = 80, value_parser = super::flag_parsers::frame_ms)]
    pub frame_ms: u32,
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
    /// Also compute LPIPS of the 8-bit images: `--lpips` is VGG16 as the reference evaluates
    /// (images in [0, 1] as given), `--lpips=alex` AlexNet as the `lpips` package is commonly
    /// used (images in [-1, 1]). Needs the weights, set up once with `python3
    /// tools/lpips_weights.py` (docs/lpips.md).
    #[arg(long, value_enum, num_args = 0..=1, require_equals = true, default_missing_value = "vgg", value_name = "NETWORK")]
    pub lpips: Option<LpipsNetwork>,
    /// Also report PSNR and SSIM over each view's mask pixels (mask value at least 128: the
    /// NeuS `mask/`, `--masks DIR`, or the image's alpha), labelled "masked", beside the
    /// whole-image figures.
    #[arg(long)]
    pub masked: bool,
}

/// Renders and measures the views of `common`; with `masked`, also over each view's mask (or
/// its image's alpha) where it has one.
fn run_views(
    common: &ModelSceneArgs,
    masked: bool,
    mut on_render: impl FnMut(usize, &str, &[f32], &[f32], u32, u32) -> Result<()>,
) -> Result<EvalReport> {
    start_threads(common.threads)?;
    let (model, meta, scene) = common.scene_args.load_model_and_scene(&common.model, &common.scene)?;
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
    let mut unread = None;
    let mut index = 0;
    // Each view's float values are made for its evaluation only (not all views at once; an
    // on-demand image is decoded then).
    let read = views.iter().map(|v| {
        Ok::<_, bbsplat::scene::SceneError>(EvalView {
            name: &v.name,
            camera: &v.camera,
            rgb: std::borrow::Cow::Owned(v.image.get()?.to_f32_rgb()),
            mask: if masked {
                v.mask.as_deref().or(v.coverage.as_deref())
            } else {
                None
            },
        })
    });
    let report = evaluate_views(
        &activated.borrowed(),
        until_error(read, &mut unread),
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
    if let Some(e) = unread {
        return Err(e.into());
    }
    match failure {
        Some(e) => Err(e),
        None => Ok(report),
    }
}

/// Runs `bbsplat render`.
pub fn render(args: RenderArgs) -> Result<()> {
    if let Some(frames) = args.orbit {
        return render_orbit(&args, frames);
    }
    // Created as the first render is written (after the model and scene loaded), removed again
    // if the command fails.
    let mut output: Option<OutputDir> = None;
    let report = run_views(&args.common, false, |i, name, rendered, truth, w, h| {
        if output.is_none() {
            output = Some(OutputDir::create(&args.output)?);
        }
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
    if let Some(output) = output {
        output.keep();
    }
    Ok(())
}

/// Runs `bbsplat eval`.
pub fn eval(args: EvalArgs) -> Result<()> {
    // Loaded first: missing weights refuse the command before anything is rendered.
    let net = match args.lpips {
        Some(network) => Some(Lpips::load_cached(network.into())?),
        None => None,
    };
    let mut lpips = Vec::new();
    let mut report = run_views(&args.common, args.masked, |_, name, rendered, truth, w, h| {
        if let Some(net) = &net {
            let d = lpips_u8(net, rendered, truth, w as usize, h as usize)
                .with_context(|| format!("LPIPS of view {name}"))?;
            lpips.push(d);
        }
        Ok(())
    })?;
    if let Some(net) = &net {
        report = report.with_lpips(net.variant(), &lpips);
    }
    if args.masked && report.mean_masked_psnr.is_none() {
        eprintln!(
            "warning: --masked: no evaluated view of {} has a mask (mask/, --masks or an alpha channel); only whole-image figures",
            args.common.scene.display()
        );
    }
    let json = serde_json::to_string_pretty(&report).context("encoding the report")?;
    if let Some(path) = &args.report {
        write_text_atomic(path, &json).with_context(|| format!("writing the report {}", path.display()))?;
    }
    if args.json {
        println!("{json}");
    } else {
        print!("{}", report.table());
    }
    Ok(())
}

/// `bbsplat render --orbit N`: N frames around the scene, as PNG files and one looping GIF.
fn render_orbit(args: &RenderArgs, frames: usize) -> Result<()> {
    use image::codecs::gif::{GifEncoder, Repeat};
    let common = &args.common;
    start_threads(common.threads)?;
    let (model, meta, scene) = common.scene_args.load_model_and_scene(&common.model, &common.scene)?;
    let cameras: Vec<_> = scene.train.iter().map(|v| v.camera).collect();
    let output = OutputDir::create(&args.output)?;
    if let Some(first) = cameras.first() {
        // Each frame: a PNG of at most 3 bytes a pixel plus its share of the GIF (1 byte a pixel).
        let bytes = (frames as u64)
            .saturating_mul(first.pixel_count() as u64)
            .saturating_mul(4);
        super::preflight::free_space(&args.output, bytes)?;
    }
    let path = bbsplat::export::orbit::orbit_cameras(&cameras, frames)
        .with_context(|| format!("{}: placing the orbit", common.scene.display()))?;
    let activated = model.activate();
    let settings = RenderSettings {
        background: Vec3::from_array(scene.background.rgb()),
        sh_degree: meta.sh_degree,
        ..RenderSettings::default()
    };
    let gif_path = args.output.join("orbit.gif");
    // The frames go to a temporary file beside the GIF, renamed over it once complete
    // ([`bbsplat::file_io::write_atomic_with`]); an error of a frame is kept here, the write
    // told only that it failed.
    let mut frame_error = None;
    let write_frames = |writer: &mut std::io::BufWriter<&mut std::fs::File>| -> Result<()> {
        let mut gif = GifEncoder::new_with_speed(writer, 10);
        gif.set_repeat(Repeat::Infinite)
            .with_context(|| format!("writing {}", gif_path.display()))?;
        let delay = image::Delay::from_numer_denom_ms(args.frame_ms, 1);
        // The render's storage recycled from frame to frame (the same images, fewer fresh pages).
        let mut buffers = bbsplat::raster::RenderBuffers::default();
        for (k, camera) in path.iter().enumerate() {
            let out =
                bbsplat::raster::render_with(&activated.borrowed(), camera, &settings, std::mem::take(&mut buffers));
            write_png_atomic(
                &args.output.join(format!("orbit_{k:04}.png")),
                &out.rgb,
                out.width,
                out.height,
            )?;
            let rgba: Vec<u8> = out
                .rgb
                .chunks_exact(3)
                .flat_map(|c| {
                    [c[0], c[1], c[2]]
                        .map(bbsplat::loss::psnr::quantize_u8)
                        .into_iter()
                        .chain([255])
                })
                .collect();
            let frame = image::RgbaImage::from_raw(out.width, out.height, rgba).context("frame size")?;
            gif.encode_frame(image::Frame::from_parts(frame, 0, 0, delay))
                .with_context(|| format!("writing {}", gif_path.display()))?;
            buffers = out.into_buffers();
        }
        // Dropping the encoder writes the GIF's trailer into the writer.
        Ok(())
    };
    let written = bbsplat::file_io::write_atomic_with(&gif_path, |file| {
        let mut writer = std::io::BufWriter::new(file);
        if let Err(e) = write_frames(&mut writer) {
            frame_error = Some(e);
            return Err(std::io::Error::other("an orbit frame failed"));
        }
        // Errors the buffer held back (a full disk) surface here, not in a silent drop.
        std::io::Write::flush(&mut writer)
    });
    if let Some(e) = frame_error {
        return Err(e);
    }
    written?;
    output.keep();
    println!(
        "wrote {frames} orbit frames and {} ({} bytes) to {}",
        gif_path.display(),
        std::fs::metadata(&gif_path).map(|m| m.len()).unwrap_or(0),
        args.output.display()
    );
    Ok(())
}
