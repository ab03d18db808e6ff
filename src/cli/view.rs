//! `bbsplat view <model> [scene] -o <page.html> [--serve]`: the self-contained WebGL2 viewer
//! page (the library: `bbsplat::export::viewer`; docs/export.md).

use super::common::SceneArgs;
use super::common::read_model;
use super::http;
use anyhow::Result;
use bbsplat::camera::Camera;
use bbsplat::export::viewer::{ViewerCamera, write_viewer};
use clap::Args;
use glam::Vec3;
use std::io::Write;
use std::path::PathBuf;
use std::sync::Arc;

/// Flags of `bbsplat view`.
#[derive(Args, Clone, Debug)]
pub struct ViewArgs {
    /// A model folder written by `bbsplat train` (`<out>/model`).
    pub model: PathBuf,
    /// The dataset whose cameras the page can jump to (optional: without it the page starts at a
    /// camera framing the billboards, over the model's background).
    pub scene: Option<PathBuf>,
    #[command(flatten)]
    pub scene_args: SceneArgs,
    /// The page to write.
    #[arg(short, long, default_value = "bbsplat_view.html")]
    pub output: PathBuf,
    /// Also serve the page on http://127.0.0.1:<port>/ until interrupted (to this machine only:
    /// the `Host` must be localhost or 127.0.0.1; docs/export.md).
    #[arg(long)]
    pub serve: bool,
    /// Port for --serve (0: any free port, printed).
    #[arg(long, default_value_t = 8080)]
    pub port: u16,
}

/// A camera framing `positions`: looking at the centroid from a
/// distance of 2.5 times the RMS radius, 800 × 600 pixels.
fn framing_camera(positions: &[Vec3]) -> Camera {
    let n = positions.len().max(1) as f32;
    let centre = positions.iter().copied().sum::<Vec3>() / n;
    let rms = (positions.iter().map(|p| (*p - centre).length_squared()).sum::<f32>() / n).sqrt();
    let eye = centre + Vec3::new(0.0, -1.0, 0.5).normalize() * (2.5 * rms.max(1e-3));
    Camera::look_at(eye, centre, Vec3::Z, 800.0, 800.0, 800, 600)
}

/// Runs `bbsplat view`.
pub fn run(args: ViewArgs) -> Result<()> {
    let (model, meta) = read_model(&args.model)?;
    let activated = model.activate();
    let set = activated.borrowed();
    let (background, views) = match &args.scene {
        Some(path) => {
            let scene = args.scene_args.load_for_model(path, &args.model, &meta)?;
            let views: Vec<(String, Camera)> = scene
                .train
                .iter()
                .chain(&scene.test)
                .map(|v| (v.name.clone(), v.camera))
                .collect();
            (Vec3::from_array(scene.background.rgb()), views)
        }
        None => (
            Vec3::from_array(meta.background),
            vec![("framing".to_string(), framing_camera(set.positions))],
        ),
    };
    let cameras: Vec<ViewerCamera> = views
        .iter()
        .map(|(name, camera)| ViewerCamera { name, camera })
        .collect();
    let size = write_viewer(&args.output, &set, meta.sh_degree, background, &cameras)?;
    println!(
        "wrote {} ({size} bytes, {} billboards, {} cameras)",
        args.output.display(),
        set.len(),
        cameras.len()
    );
    if args.serve {
        serve(&args.output, args.port)?;
    }
    Ok(())
}

/// Serves the file at `path` as `/` (and `/index.html`) on 127.0.0.1:`port` ([`super::http`]:
/// clients served side by side, bounded and timed requests, loopback `Host` only).
fn serve(path: &std::path::Path, port: u16) -> Result<()> {
    let limit = bbsplat::file_io::Limit {
        what: "viewer page",
        plural: "viewer pages",
        ..bbsplat::file_io::MODEL_FILE
    };
    let page = Arc::new(bbsplat::file_io::read_bounded(path, limit)?);
    let listener = http::bind(port)?;
    let address = listener.local_addr()?;
    println!("serving on http://{address}/ (Ctrl-C to stop)");
    std::io::stdout().flush()?;
    let handler = move |target: &str| {
        let path = target.split(['?', '#']).next().unwrap_or_default();
        matches!(path, "/" | "/index.html").then(|| http::Response {
            status: "200 OK",
            content_type: "text/html; charset=utf-8",
            body: Arc::clone(&page),
        })
    };
    http::serve(listener, Arc::new(handler))
}
