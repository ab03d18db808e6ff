//! Building a [`Scene`] from a NeuS/IDR dataset: `cameras_sphere.npz` (or IDR's `cameras.npz`)
//! beside `image/` and, when present, `mask/` (the layout of NeuS's DTU and BlendedMVS data,
//! 2DGS's DTU data and MonoSDF's).
//!
//! - Image `i` is the `i`-th file of `image/` in name order (`.png`, `.jpg`, `.jpeg`), as NeuS
//!   lists them; its camera is `P = world_mat_i · scale_mat_i` (both 4×4, `world_mat_i` may be
//!   3×4), whose 3×4 top is decomposed into `K` and `[R | t]`
//!   ([`super::projection::decompose_projection`]). `scale_mat_i` maps the unit sphere around
//!   the object into DTU's world frame, so the scene's world frame is the sphere's: the object
//!   lies in the unit ball, the cameras outside it looking in. An archive without
//!   `scale_mat_i` is refused (the frame would be DTU's millimetres).
//! - `K`'s principal point is in OpenCV's pixel convention (pixel centres at integers, as NeuS
//!   casts its rays); it is moved by half a pixel to the crate's (top-left corner at `(0, 0)`).
//!   `K`'s skew (`K[0][1]`, under 1e-3 of the focal length on DTU) is dropped, with a warning
//!   when it exceeds 1e-3 of `fx`.
//! - The matrices are for the full-size images (DTU: 1600×1200) whatever size the images are:
//!   the intrinsics are scaled to the image found, by the integer factor nearest to
//!   `2·cx / width` ([`super::reference_size::ReferenceSize::FromPrincipalPoint`]).
//! - Masks: the file of `mask/` whose stem is the image's, or the same number with other
//!   leading zeros (`image/000012.png` and `mask/012.png`) ([`super::mask::find_mask`]); every
//!   image needs one when `mask/` exists. [`LoadOptions::masks_dir`] replaces `mask/`.
//! - Split: every [`LoadOptions::test_every`]-th view (index % 8 == 0 by default, the DTU
//!   protocol of the BBSplat and 2DGS papers) is held out. No point cloud.

use super::error::{Location, SceneError};
use super::npy::{NpyArray, NpyError, Npz};
use super::projection::decompose_projection;
use super::reference_size::ReferenceSize;
use super::views::{self, CameraSpec, ViewSource};
use super::{LoadOptions, Scene, SceneFormat, mask, split};
use crate::file_io::names_a_file;
use crate::scene::colmap::Intrinsics;
use glam::{DMat4, Mat3, Vec3};
use std::path::{Path, PathBuf};

/// The camera files looked for, in order.
pub const CAMERA_FILES: [&str; 2] = ["cameras_sphere.npz", "cameras.npz"];
/// The image folder.
pub const IMAGE_DIR: &str = "image";
/// The mask folder.
pub const MASK_DIR: &str = "mask";
/// Image extensions listed in `image/`.
const IMAGE_EXTENSIONS: [&str; 6] = ["png", "jpg", "jpeg", "PNG", "JPG", "JPEG"];
/// Skew, relative to `fx`, above which dropping it is warned about.
const SKEW_WARNING: f64 = 1e-3;

/// The camera file of the NeuS dataset folder `dir`: the first of [`CAMERA_FILES`] that exists
/// (the first when none does).
pub(crate) fn camera_file(dir: &Path) -> PathBuf {
    CAMERA_FILES
        .iter()
        .map(|f| dir.join(f))
        .find(|p| names_a_file(p))
        .unwrap_or_else(|| dir.join(CAMERA_FILES[0]))
}

/// The image files of `dir` with one of `extensions`, in name order.
pub(crate) fn list_images(dir: &Path, extensions: &[&str]) -> Result<Vec<PathBuf>, SceneError> {
    let entries = std::fs::read_dir(dir).map_err(|e| SceneError::io(dir, e))?;
    let mut files: Vec<PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.extension()
                .and_then(|e| e.to_str())
                .is_some_and(|e| extensions.contains(&e))
        })
        .collect();
    files.sort();
    Ok(files)
}

/// Reads the `.npz` archive `file`.
pub(crate) fn read_npz(file: &Path) -> Result<Npz, SceneError> {
    let bytes = crate::file_io::read_bounded(file, crate::file_io::SCENE_FILE)?;
    Npz::parse(&bytes).map_err(|problem| SceneError::Npy {
        file: file.to_path_buf(),
        array: None,
        problem,
    })
}

/// Member `name` of `npz` as a 4×4 matrix (a 3×4 one gets the row `0 0 0 1`).
pub(crate) fn matrix(npz: &Npz, file: &Path, name: &str) -> Result<DMat4, SceneError> {
    let npy_error = |problem| SceneError::Npy {
        file: file.to_path_buf(),
        array: Some(name.to_string()),
        problem,
    };
    let array: NpyArray = match npz.array(name) {
        None => {
            return Err(SceneError::parse(
                file,
                Location::Record(format!("array {name:?}")),
                format!(
                    "the archive has no array {name:?} (NeuS/IDR cameras need world_mat_i and scale_mat_i for every image)"
                ),
            ));
        }
        Some(a) => a.map_err(npy_error)?,
    };
    let rows = match array.shape.as_slice() {
        [4, 4] => 4,
        [3, 4] => 3,
        _ => {
            return Err(npy_error(NpyError::Shape {
                found: array.shape,
                expected: "(4, 4) or (3, 4)".into(),
            }));
        }
    };
    let mut m = [[0.0f64; 4]; 4];
    m[3] = [0.0, 0.0, 0.0, 1.0];
    for (r, row) in m.iter_mut().enumerate().take(rows) {
        row.copy_from_slice(&array.data[r * 4..r * 4 + 4]);
    }
    if m.iter().flatten().any(|v| !v.is_finite()) {
        return Err(SceneError::parse(
            file,
            Location::Record(format!("array {name:?}")),
            "the matrix holds a value that is not finite",
        ));
    }
    Ok(DMat4::from_cols_array_2d(&m).transpose())
}

pub(crate) fn load(file: &Path, options: &LoadOptions, warnings: &mut Vec<String>) -> Result<Scene, SceneError> {
    let dir = file.parent().unwrap_or(Path::new("."));
    let npz = read_npz(file)?;
    let image_dir = dir.join(IMAGE_DIR);
    if !image_dir.is_dir() {
        return Err(SceneError::NotDetected {
            path: dir.to_path_buf(),
            looked_for: format!("the image folder {} of this NeuS/IDR dataset", image_dir.display()),
        });
    }
    let images = list_images(&image_dir, &IMAGE_EXTENSIONS)?;
    if images.is_empty() {
        return Err(SceneError::Empty {
            path: image_dir,
            reason: "no .png or .jpg image".into(),
        });
    }
    let mask_dir = dir.join(MASK_DIR);
    let masks = options.masks_dir.is_none() && mask_dir.is_dir();
    let mut sources = Vec::with_capacity(images.len());
    let mut skewed: Option<(String, f64)> = None;
    for (i, image_path) in images.into_iter().enumerate() {
        let name = image_path
            .file_name()
            .and_then(|n| n.to_str())
            .unwrap_or_default()
            .to_string();
        let world = matrix(&npz, file, &format!("world_mat_{i}"))?;
        let scale = matrix(&npz, file, &format!("scale_mat_{i}"))?;
        let p = (world * scale).transpose().to_cols_array_2d();
        let location = Location::Record(format!("world_mat_{i} @ scale_mat_{i} (image {name:?})"));
        let d = decompose_projection(&[p[0], p[1], p[2]]).map_err(|m| SceneError::parse(file, location.clone(), m))?;
        let skew = d.k[0][1] / d.k[0][0];
        if skew.abs() > SKEW_WARNING && skewed.as_ref().is_none_or(|(_, s)| skew.abs() > s.abs()) {
            skewed = Some((format!("world_mat_{i}"), skew));
        }
        let intrinsics = Intrinsics {
            fx: d.k[0][0],
            fy: d.k[1][1],
            cx: d.k[0][2] + 0.5,
            cy: d.k[1][2] + 0.5,
            distortion: Default::default(),
        };
        let rotation = Mat3::from_cols_array_2d(&d.rotation.map(|r| r.map(|v| v as f32))).transpose();
        let translation = Vec3::from_array(d.translation.map(|v| v as f32));
        if !rotation.is_finite() || !translation.is_finite() {
            return Err(SceneError::parse(file, location, "pose overflows single precision"));
        }
        let mask = if masks {
            match mask::find_mask(&mask_dir, &name) {
                Some(m) => Some(m),
                None => {
                    return Err(SceneError::MissingMask {
                        image: image_path,
                        masks_dir: mask_dir,
                    });
                }
            }
        } else {
            None
        };
        sources.push(ViewSource {
            name,
            image_path,
            file: file.to_path_buf(),
            location,
            camera: CameraSpec::Scaled {
                intrinsics,
                reference: ReferenceSize::FromPrincipalPoint,
            },
            rotation,
            translation,
            mask,
        });
    }
    if let Some((array, skew)) = skewed {
        warnings.push(format!(
            "{}: {array}: the camera has a skew of {skew:.2e} × fx, which the pinhole model drops",
            file.display()
        ));
    }
    let views = views::load_all(sources, options, warnings)?;
    let (train, test) = split::split_every(views, options.test_every);
    Ok(Scene {
        name: dir.file_name().and_then(|n| n.to_str()).unwrap_or("scene").to_string(),
        format: SceneFormat::Neus,
        source: file.to_path_buf(),
        background: options.background,
        train,
        test,
        points: None,
        extent: 0.0,
        warnings: Vec::new(),
    })
}
