//! Building a [`Scene`] from an LLFF dataset: `poses_bounds.npy` beside `images/` and/or
//! `images_N/` (the NeRF forward-facing scenes).
//!
//! - `poses_bounds.npy` is an `N × 17` float array (f4 or f8). Row `i` is the 3×5 matrix
//!   `[R | c | hwf]` in row-major order, then the two depth bounds `near, far`: the columns of
//!   `R` are the camera's **down, right and backwards** axes in world coordinates, `c` its
//!   centre, `hwf = (H, W, focal)` the full-size image height, width and focal length (pixels).
//!   The crate's camera (OpenCV: x right, y down, z forward) has the world-to-camera rotation
//!   whose rows are `right, down, −backwards`, and `t = −R·c`. Units are those of the file (not
//!   rescaled by the bounds, nor recentred, as NeRF's loader does).
//! - Images: the files of the chosen folder in name order, image `i` for row `i`; their number
//!   must equal `N`. The folder: `images_D` when [`LoadOptions::downscale`] is `D > 1` and that
//!   folder exists (LLFF's `factor`: the folder is already downscaled, so the images are taken
//!   as they are); otherwise the one with the largest images among `images` and `images_N`
//!   (smallest `N`) holding `N` images, `--downscale` then applying as for every format.
//! - Intrinsics: `fx = fy = focal`, principal point at the image centre, scaled from `H × W`
//!   to the image found ([`super::reference_size::ReferenceSize::Given`]; another aspect ratio
//!   is refused).
//! - Split: every [`LoadOptions::test_every`]-th image (index 0, 8, 16, ...: the NeRF benchmark's
//!   `llffhold = 8`) is held out.
//! - Depth bounds: checked (`0 < near < far`, finite) and used for the initial points, which
//!   LLFF does not ship: [`POINTS_PER_VIEW`] points per training view at pixels and depths of a
//!   low-discrepancy sequence, the depth uniform in disparity between the view's `near` and
//!   `far` (as NeRF samples forward-facing scenes), each coloured by its pixel. The cloud fills
//!   the volume the cameras see between the bounds; the SfM initialisation then samples it.

use super::error::{Location, SceneError};
use super::npy::{NpyError, parse_npy};
use super::reference_size::ReferenceSize;
use super::views::{self, CameraSpec, ViewSource};
use super::{LoadOptions, PointCloud, Scene, SceneFormat, View, split};
use crate::scene::colmap::Intrinsics;
use glam::{Mat3, Vec3};
use std::path::{Path, PathBuf};

/// The pose file.
pub const POSES_FILE: &str = "poses_bounds.npy";
/// Initial points per training view (see the module documentation).
pub const POINTS_PER_VIEW: usize = 2_000;
/// Image extensions listed.
const IMAGE_EXTENSIONS: [&str; 6] = ["png", "jpg", "jpeg", "PNG", "JPG", "JPEG"];

/// One row of `poses_bounds.npy`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LlffPose {
    /// Camera-to-world rotation, columns down, right, backwards (world coordinates), as rows
    /// of 3: `r[row][column]`.
    pub c2w_down_right_back: [[f64; 3]; 3],
    /// Camera centre, world units.
    pub centre: [f64; 3],
    /// Full-size image height, width and focal length, pixels.
    pub hwf: [f64; 3],
    /// Near and far depth bounds, world units.
    pub bounds: [f64; 2],
}

impl LlffPose {
    /// World-to-camera rotation (OpenCV axes) and translation, f64.
    pub fn world_to_camera(&self) -> ([[f64; 3]; 3], [f64; 3]) {
        let col = |c: usize| [0, 1, 2].map(|r| self.c2w_down_right_back[r][c]);
        let (down, right, back) = (col(0), col(1), col(2));
        let rotation = [right, down, back.map(|v| -v)];
        let t = rotation.map(|row| -(row[0] * self.centre[0] + row[1] * self.centre[1] + row[2] * self.centre[2]));
        (rotation, t)
    }
}

/// Parses the bytes of a `poses_bounds.npy` (`file`, for messages) into its rows, each
/// checked: finite, a rotation block whose columns are orthonormal within 1e-3, positive
/// `H`, `W` and focal, `0 < near < far`.
///
/// # Errors
/// [`SceneError::Npy`] for a malformed array or another shape than `N × 17`,
/// [`SceneError::Parse`] naming the row for a bad value.
pub fn parse_poses(bytes: &[u8], file: &Path) -> Result<Vec<LlffPose>, SceneError> {
    let npy_error = |problem| SceneError::Npy {
        file: file.to_path_buf(),
        array: None,
        problem,
    };
    let array = parse_npy(bytes).map_err(npy_error)?;
    let n = match array.shape.as_slice() {
        [n, 17] => *n,
        _ => {
            return Err(npy_error(NpyError::Shape {
                found: array.shape,
                expected: "(N, 17)".into(),
            }));
        }
    };
    let mut poses = Vec::with_capacity(n);
    for (i, row) in array.data.chunks_exact(17).enumerate() {
        let bad = |m: String| SceneError::parse(file, Location::Record(format!("row {i}")), m);
        if let Some(j) = row.iter().position(|v| !v.is_finite()) {
            return Err(bad(format!("value {j} is not finite")));
        }
        let m = |r: usize, c: usize| row[r * 5 + c];
        let pose = LlffPose {
            c2w_down_right_back: [0, 1, 2].map(|r| [m(r, 0), m(r, 1), m(r, 2)]),
            centre: [m(0, 3), m(1, 3), m(2, 3)],
            hwf: [m(0, 4), m(1, 4), m(2, 4)],
            bounds: [row[15], row[16]],
        };
        let r = &pose.c2w_down_right_back;
        for a in 0..3 {
            for b in 0..3 {
                let dot: f64 = (0..3).map(|k| r[k][a] * r[k][b]).sum();
                let want = if a == b { 1.0 } else { 0.0 };
                if (dot - want).abs() > 1e-3 {
                    return Err(bad(format!(
                        "the rotation's columns {a} and {b} have dot product {dot:.6}, not {want}: not a rotation"
                    )));
                }
            }
        }
        if pose.hwf.iter().any(|v| *v <= 0.0) {
            return Err(bad(format!("height, width and focal {:?} must be positive", pose.hwf)));
        }
        let [near, far] = pose.bounds;
        if !(near > 0.0 && far > near) {
            return Err(bad(format!("depth bounds near {near}, far {far}: need 0 < near < far")));
        }
        poses.push(pose);
    }
    Ok(poses)
}

/// The image folder for `n` poses (module rule) and whether `--downscale` is consumed by it.
fn choose_images_dir(dir: &Path, n: usize, downscale: u32) -> Result<(PathBuf, bool), SceneError> {
    let count = |d: &Path| {
        super::neus::list_images(d, &IMAGE_EXTENSIONS)
            .map(|l| l.len())
            .unwrap_or(0)
    };
    if downscale > 1 {
        let d = dir.join(format!("images_{downscale}"));
        if d.is_dir() {
            return Ok((d, true));
        }
    }
    let mut candidates: Vec<(u32, PathBuf)> = std::fs::read_dir(dir)
        .map_err(|e| SceneError::io(dir, e))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_dir())
        .filter_map(|p| {
            let name = p.file_name()?.to_str()?.to_string();
            let factor = if name == "images" {
                1
            } else {
                name.strip_prefix("images_")?.parse::<u32>().ok()?
            };
            Some((factor, p))
        })
        .collect();
    candidates.sort();
    let found: Vec<String> = candidates
        .iter()
        .map(|(_, p)| format!("{} ({} images)", p.display(), count(p)))
        .collect();
    match candidates.into_iter().find(|(_, p)| count(p) == n) {
        Some((_, p)) => Ok((p, false)),
        None => Err(SceneError::NotDetected {
            path: dir.to_path_buf(),
            looked_for: format!(
                "an image folder (images or images_N) holding the {n} images of {POSES_FILE}; found {}",
                if found.is_empty() {
                    "none".to_string()
                } else {
                    found.join(", ")
                }
            ),
        }),
    }
}

/// The `k`-th point of the R3 low-discrepancy sequence (fractions of the plastic number's
/// powers), three values in `[0, 1)`.
fn r3(k: usize) -> [f64; 3] {
    const G: f64 = 1.220_744_084_605_759_5;
    let a = [1.0 / G, 1.0 / (G * G), 1.0 / (G * G * G)];
    a.map(|ai| (0.5 + ai * (k as f64 + 1.0)).fract())
}

/// The initial points of the views (module rule): `per_view` points each, view `v` using the
/// points `v·per_view ..` of the sequence, at depth uniform in disparity between its bounds.
///
/// # Errors
/// An on-demand image ([`super::on_demand`]) that cannot be decoded again for the colours.
pub fn frustum_points(views: &[(&View, [f64; 2])], per_view: usize) -> Result<PointCloud, SceneError> {
    let mut cloud = PointCloud::default();
    for (v, (view, [near, far])) in views.iter().enumerate() {
        let image = view.image.get()?;
        let cam = &view.camera;
        let (w, h) = (cam.width as f64, cam.height as f64);
        let r_t = cam.rotation.as_dmat3().transpose();
        let centre = cam.centre_f64();
        for j in 0..per_view {
            let [u, s, d] = r3(v * per_view + j);
            let (px, py) = (u * w, s * h);
            let disparity = 1.0 / near + d * (1.0 / far - 1.0 / near);
            let depth = 1.0 / disparity;
            let ray = glam::DVec3::new(
                (px - cam.cx as f64) / cam.fx as f64,
                (py - cam.cy as f64) / cam.fy as f64,
                1.0,
            );
            let p = centre + r_t * (ray * depth);
            cloud.positions.push(p.as_vec3());
            let (x, y) = ((px as u32).min(cam.width - 1), (py as u32).min(cam.height - 1));
            cloud.colours.push(image.pixel_f32(x, y));
        }
    }
    Ok(cloud)
}

pub(crate) fn load(file: &Path, options: &LoadOptions, warnings: &mut Vec<String>) -> Result<Scene, SceneError> {
    let dir = file.parent().unwrap_or(Path::new("."));
    let bytes = crate::file_io::read_bounded(file, crate::file_io::SCENE_FILE)?;
    let poses = parse_poses(&bytes, file)?;
    if poses.is_empty() {
        return Err(SceneError::Empty {
            path: file.to_path_buf(),
            reason: "the array has no row".into(),
        });
    }
    let (images_dir, consumed) = choose_images_dir(dir, poses.len(), options.downscale)?;
    let images = super::neus::list_images(&images_dir, &IMAGE_EXTENSIONS)?;
    if images.len() != poses.len() {
        return Err(SceneError::parse(
            file,
            Location::File,
            format!(
                "{} poses but {} images in {}",
                poses.len(),
                images.len(),
                images_dir.display()
            ),
        ));
    }
    let mut sources = Vec::with_capacity(poses.len());
    for (i, (pose, image_path)) in poses.iter().zip(images).enumerate() {
        let name = image_path
            .file_name()
            .and_then(|n| n.to_str())
            .unwrap_or_default()
            .to_string();
        let (r, t) = pose.world_to_camera();
        let rotation = Mat3::from_cols_array_2d(&r.map(|row| row.map(|v| v as f32))).transpose();
        let translation = Vec3::from_array(t.map(|v| v as f32));
        let location = Location::Record(format!("row {i} (image {name:?})"));
        if !rotation.is_finite() || !translation.is_finite() {
            return Err(SceneError::parse(file, location, "pose overflows single precision"));
        }
        let [height, width, focal] = pose.hwf;
        sources.push(ViewSource {
            name,
            image_path,
            file: file.to_path_buf(),
            location,
            camera: CameraSpec::Scaled {
                intrinsics: Intrinsics {
                    fx: focal,
                    fy: focal,
                    cx: 0.5 * width,
                    cy: 0.5 * height,
                    distortion: Default::default(),
                },
                reference: ReferenceSize::Given { width, height },
            },
            rotation,
            translation,
            mask: None,
        });
    }
    let view_options = LoadOptions {
        downscale: if consumed { 1 } else { options.downscale },
        ..options.clone()
    };
    let views = views::load_all(sources, &view_options, warnings)?;
    let bounds: Vec<[f64; 2]> = poses.iter().map(|p| p.bounds).collect();
    let indexed: Vec<(View, [f64; 2])> = views.into_iter().zip(bounds).collect();
    let (train, test) = split::split_every(indexed, options.test_every);
    let points = frustum_points(&train.iter().map(|(v, b)| (v, *b)).collect::<Vec<_>>(), POINTS_PER_VIEW)?;
    Ok(Scene {
        name: dir.file_name().and_then(|n| n.to_str()).unwrap_or("scene").to_string(),
        format: SceneFormat::Llff,
        source: file.to_path_buf(),
        background: options.background,
        train: train.into_iter().map(|(v, _)| v).collect(),
        test: test.into_iter().map(|(v, _)| v).collect(),
        points: Some(points),
        extent: 0.0,
        warnings: Vec::new(),
    })
}
