//! COLMAP sparse models: in-memory types shared by the binary and text readers and writers.
//!
//! Conventions (COLMAP's, kept as they are in the files):
//! - An image's pose is **world-to-camera**, `X_cam = R(q)·X_world + t`, with the quaternion
//!   `q = (w, x, y, z)` (not necessarily unit in the file; normalised when a
//!   [`crate::camera::Camera`] is built) and OpenCV camera axes (x right, y down, z forward).
//!   The camera centre is `-Rᵀt`.
//! - Intrinsics are in pixels of the image as stored, with the top-left corner of the top-left
//!   pixel at `(0, 0)` (so that pixel's centre is `(0.5, 0.5)`), like [`crate::camera::Camera`].
//! - Record ids (`camera_id`, `image_id`, `point3D_id`) are unordered and need not be
//!   contiguous. Records are kept in file order, so that writing a model back gives the same file
//!   contents (up to the text comments).
//!
//! Validation done by the readers: image sizes are positive and fit in `u32`, intrinsics, poses
//! and 3D point positions are finite, focal lengths are positive, quaternions are not zero, image
//! names are non-empty UTF-8 without NUL or line breaks, ids are unique. Keypoint coordinates and
//! point errors are stored as read, without checks.

use super::distortion::Distortion;
use super::error::{Location, SceneError};
use crate::file_io::names_a_file;
use std::collections::HashSet;
use std::path::Path;

/// The COLMAP camera models this crate reads. Other models (fisheyes, FULL_OPENCV, FOV, ...)
/// are refused with [`SceneError::UnsupportedCameraModel`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum CameraModel {
    /// Id 0, params `[f, cx, cy]`.
    SimplePinhole,
    /// Id 1, params `[fx, fy, cx, cy]`.
    Pinhole,
    /// Id 2, params `[f, cx, cy, k]`.
    SimpleRadial,
    /// Id 3, params `[f, cx, cy, k1, k2]`.
    Radial,
    /// Id 4, params `[fx, fy, cx, cy, k1, k2, p1, p2]`.
    Opencv,
}

/// COLMAP's model ids and names (including the ones this crate refuses), with their number of
/// parameters, as in COLMAP's `models.h`.
const ALL_MODELS: [(i32, &str, usize); 11] = [
    (0, "SIMPLE_PINHOLE", 3),
    (1, "PINHOLE", 4),
    (2, "SIMPLE_RADIAL", 4),
    (3, "RADIAL", 5),
    (4, "OPENCV", 8),
    (5, "OPENCV_FISHEYE", 8),
    (6, "FULL_OPENCV", 12),
    (7, "FOV", 5),
    (8, "SIMPLE_RADIAL_FISHEYE", 4),
    (9, "RADIAL_FISHEYE", 5),
    (10, "THIN_PRISM_FISHEYE", 12),
];

impl CameraModel {
    /// All supported models, in id order.
    pub const ALL: [CameraModel; 5] = [
        CameraModel::SimplePinhole,
        CameraModel::Pinhole,
        CameraModel::SimpleRadial,
        CameraModel::Radial,
        CameraModel::Opencv,
    ];

    /// COLMAP's numeric model id.
    pub fn id(self) -> i32 {
        match self {
            CameraModel::SimplePinhole => 0,
            CameraModel::Pinhole => 1,
            CameraModel::SimpleRadial => 2,
            CameraModel::Radial => 3,
            CameraModel::Opencv => 4,
        }
    }

    /// COLMAP's model name, e.g. `"SIMPLE_RADIAL"`.
    pub fn name(self) -> &'static str {
        ALL_MODELS[self.id() as usize].1
    }

    /// Number of parameters COLMAP stores for the model.
    pub fn num_params(self) -> usize {
        ALL_MODELS[self.id() as usize].2
    }

    /// The supported model with this id; otherwise a description of the refused model for
    /// the error message (`"OPENCV_FISHEYE (model id 5)"` or `"unknown model id 42"`).
    pub fn from_id(id: i32) -> Result<Self, String> {
        if let Some(m) = Self::ALL.iter().find(|m| m.id() == id) {
            return Ok(*m);
        }
        match ALL_MODELS.iter().find(|(i, _, _)| *i == id) {
            Some((_, name, _)) => Err(format!("{name} (model id {id})")),
            None => Err(format!("unknown model id {id}")),
        }
    }

    /// The supported model with this name; otherwise a description of the refused model.
    pub fn from_name(name: &str) -> Result<Self, String> {
        if let Some(m) = Self::ALL.iter().find(|m| m.name() == name) {
            return Ok(*m);
        }
        match ALL_MODELS.iter().find(|(_, n, _)| *n == name) {
            Some((id, _, _)) => Err(format!("{name} (model id {id})")),
            None => Err(format!("unknown model name {name:?}")),
        }
    }
}

/// One camera of `cameras.bin` / `cameras.txt`.
#[derive(Clone, Debug, PartialEq)]
pub struct ColmapCamera {
    /// `camera_id` (unsigned 32-bit in COLMAP).
    pub id: u32,
    /// The camera model.
    pub model: CameraModel,
    /// Image width in pixels.
    pub width: u64,
    /// Image height in pixels.
    pub height: u64,
    /// Model parameters in COLMAP's order (see [`CameraModel`]); length
    /// [`CameraModel::num_params`].
    pub params: Vec<f64>,
}

/// Pinhole intrinsics in pixels plus an OpenCV radial-tangential distortion, all in f64.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Intrinsics {
    /// Focal length along x, pixels.
    pub fx: f64,
    /// Focal length along y, pixels.
    pub fy: f64,
    /// Principal point x, pixels from the left image edge.
    pub cx: f64,
    /// Principal point y, pixels from the top image edge.
    pub cy: f64,
    /// Lens distortion on normalised image coordinates (zero for pinhole models).
    pub distortion: Distortion,
}

/// Narrowest field of view a camera may have, degrees (a telephoto lens of 1° has a focal
/// length of 57 image widths).
pub const MIN_FOV_DEG: f64 = 1.0;
/// Widest field of view a pinhole camera may have, degrees (180° is a focal length of 0).
pub const MAX_FOV_DEG: f64 = 179.0;

impl Intrinsics {
    /// What makes these intrinsics implausible for an image of `width × height`, or `None`: a
    /// field of view (`2·atan(size / 2f)`) along either axis outside [`MIN_FOV_DEG`] to
    /// [`MAX_FOV_DEG`], or a principal point outside the image. Such values come from a unit
    /// mix-up or a broken export, and training on them would silently give garbage.
    pub fn implausibility(&self, width: u32, height: u32) -> Option<String> {
        let fov = |size: u32, f: f64| 2.0 * (0.5 * size as f64 / f).atan().to_degrees();
        for (axis, name, size, f) in [("x", "fx", width, self.fx), ("y", "fy", height, self.fy)] {
            let deg = fov(size, f);
            if !(MIN_FOV_DEG..=MAX_FOV_DEG).contains(&deg) {
                return Some(format!(
                    "the field of view along {axis} is {deg:.3} deg ({name} = {f} px for {size} px),                      outside {MIN_FOV_DEG}-{MAX_FOV_DEG} deg: the focal length is implausible (a unit mix-up?)"
                ));
            }
        }
        let inside = |c: f64, size: u32| (0.0..=size as f64).contains(&c);
        if !inside(self.cx, width) || !inside(self.cy, height) {
            return Some(format!(
                "the principal point ({}, {}) lies outside the {width}x{height} image",
                self.cx, self.cy
            ));
        }
        None
    }
}

impl ColmapCamera {
    /// The camera's intrinsics, with every distortion model mapped to OpenCV's
    /// `k1 k2 p1 p2` (missing terms zero).
    ///
    /// ```
    /// use bbsplat::scene::colmap::{CameraModel, ColmapCamera};
    /// let cam = ColmapCamera { id: 1, model: CameraModel::SimpleRadial, width: 640, height: 480,
    ///     params: vec![500.0, 320.0, 240.0, 0.05] };
    /// let k = cam.intrinsics();
    /// assert_eq!((k.fx, k.fy, k.cx, k.cy, k.distortion.k1), (500.0, 500.0, 320.0, 240.0, 0.05));
    /// ```
    pub fn intrinsics(&self) -> Intrinsics {
        let p = |i: usize| self.params.get(i).copied().unwrap_or(0.0);
        let (fx, fy, cx, cy, k1, k2, p1, p2) = match self.model {
            CameraModel::SimplePinhole => (p(0), p(0), p(1), p(2), 0.0, 0.0, 0.0, 0.0),
            CameraModel::Pinhole => (p(0), p(1), p(2), p(3), 0.0, 0.0, 0.0, 0.0),
            CameraModel::SimpleRadial => (p(0), p(0), p(1), p(2), p(3), 0.0, 0.0, 0.0),
            CameraModel::Radial => (p(0), p(0), p(1), p(2), p(3), p(4), 0.0, 0.0),
            CameraModel::Opencv => (p(0), p(1), p(2), p(3), p(4), p(5), p(6), p(7)),
        };
        Intrinsics {
            fx,
            fy,
            cx,
            cy,
            distortion: Distortion {
                k1,
                k2,
                k3: 0.0,
                p1,
                p2,
            },
        }
    }

    /// Checks sizes and parameters; `Err` holds what is wrong (the caller adds file/record).
    pub(crate) fn check(&self) -> Result<(), String> {
        if self.width == 0 || self.height == 0 {
            return Err(format!("image size {}x{} is not positive", self.width, self.height));
        }
        if self.width > u32::MAX as u64 || self.height > u32::MAX as u64 {
            return Err(format!("image size {}x{} is too large", self.width, self.height));
        }
        if self.params.len() != self.model.num_params() {
            return Err(format!(
                "model {} needs {} parameters, found {}",
                self.model.name(),
                self.model.num_params(),
                self.params.len()
            ));
        }
        if let Some(i) = self.params.iter().position(|v| !v.is_finite()) {
            return Err(format!(
                "parameter {i} of model {} is not finite ({})",
                self.model.name(),
                self.params[i]
            ));
        }
        let k = self.intrinsics();
        if k.fx <= 0.0 || k.fy <= 0.0 {
            return Err(format!("focal length ({}, {}) is not positive", k.fx, k.fy));
        }
        Ok(())
    }
}

/// One 2D keypoint of an image.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Point2D {
    /// Pixel coordinates (x right, y down; top-left image corner at (0, 0)).
    pub xy: [f64; 2],
    /// Id of the 3D point it observes, `-1` when none (COLMAP stores `u64::MAX` in binary).
    pub point3d_id: i64,
}

/// One registered image of `images.bin` / `images.txt`.
#[derive(Clone, Debug, PartialEq)]
pub struct ColmapImage {
    /// `image_id`.
    pub id: u32,
    /// World-to-camera rotation as a quaternion `(w, x, y, z)`.
    pub qvec: [f64; 4],
    /// World-to-camera translation.
    pub tvec: [f64; 3],
    /// The camera it was taken with.
    pub camera_id: u32,
    /// File name relative to the image folder (may contain `/`).
    pub name: String,
    /// Keypoints (may be empty).
    pub points2d: Vec<Point2D>,
}

impl ColmapImage {
    /// Checks the pose and the name; `Err` holds what is wrong.
    pub(crate) fn check(&self) -> Result<(), String> {
        if self.qvec.iter().chain(&self.tvec).any(|v| !v.is_finite()) {
            return Err(format!(
                "pose is not finite (qvec {:?}, tvec {:?})",
                self.qvec, self.tvec
            ));
        }
        let n2: f64 = self.qvec.iter().map(|v| v * v).sum();
        if n2.is_nan() || n2 <= 1e-12 || n2.is_infinite() {
            return Err(format!("quaternion {:?} cannot be normalised", self.qvec));
        }
        check_name(&self.name)
    }

    /// Rotation matrix (rows) of the normalised quaternion.
    pub fn rotation(&self) -> [[f64; 3]; 3] {
        let n = self.qvec.iter().map(|v| v * v).sum::<f64>().sqrt();
        let [w, x, y, z] = self.qvec.map(|v| v / n);
        [
            [
                1.0 - 2.0 * (y * y + z * z),
                2.0 * (x * y - w * z),
                2.0 * (x * z + w * y),
            ],
            [
                2.0 * (x * y + w * z),
                1.0 - 2.0 * (x * x + z * z),
                2.0 * (y * z - w * x),
            ],
            [
                2.0 * (x * z - w * y),
                2.0 * (y * z + w * x),
                1.0 - 2.0 * (x * x + y * y),
            ],
        ]
    }
}

/// Checks an image name: non-empty, no NUL, no line break, no leading/trailing whitespace.
pub(crate) fn check_name(name: &str) -> Result<(), String> {
    if name.is_empty() {
        return Err("image name is empty".into());
    }
    if name.contains(['\0', '\n', '\r']) {
        return Err(format!("image name {name:?} contains a NUL or line-break character"));
    }
    if name.trim() != name {
        return Err(format!("image name {name:?} has leading or trailing whitespace"));
    }
    Ok(())
}

/// One element of a 3D point's track: which keypoint of which image observes it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TrackElement {
    /// `image_id` of the observing image.
    pub image_id: u32,
    /// Index of the keypoint in that image's `points2d` list.
    pub point2d_idx: u32,
}

/// One point of `points3D.bin` / `points3D.txt`.
#[derive(Clone, Debug, PartialEq)]
pub struct ColmapPoint3D {
    /// `point3D_id`.
    pub id: u64,
    /// Position in world coordinates.
    pub xyz: [f64; 3],
    /// Colour, 8-bit sRGB.
    pub rgb: [u8; 3],
    /// Mean reprojection error in pixels (as stored; not checked).
    pub error: f64,
    /// Observations.
    pub track: Vec<TrackElement>,
}

/// A whole sparse model, records in file order.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct ColmapModel {
    /// Cameras.
    pub cameras: Vec<ColmapCamera>,
    /// Registered images.
    pub images: Vec<ColmapImage>,
    /// 3D points.
    pub points: Vec<ColmapPoint3D>,
}

/// Reports the first repeated id, for the duplicate check of the readers.
pub(crate) struct IdSet<T>(HashSet<T>);

impl<T: std::hash::Hash + Eq + Copy + std::fmt::Display> IdSet<T> {
    pub(crate) fn new() -> Self {
        IdSet(HashSet::new())
    }

    /// `Err` with a message when `id` was seen before.
    pub(crate) fn insert(&mut self, what: &str, id: T) -> Result<(), String> {
        if self.0.insert(id) {
            Ok(())
        } else {
            Err(format!("{what} {id} appears twice"))
        }
    }
}

/// Cross-checks a model: every image's camera exists. `images_file` is named in the error.
pub fn check_references(model: &ColmapModel, images_file: &Path) -> Result<(), SceneError> {
    let ids: HashSet<u32> = model.cameras.iter().map(|c| c.id).collect();
    for (i, im) in model.images.iter().enumerate() {
        if !ids.contains(&im.camera_id) {
            return Err(SceneError::parse(
                images_file,
                Location::Record(format!("image {i} (image_id {}, {:?})", im.id, im.name)),
                format!("camera_id {} is not in the cameras file", im.camera_id),
            ));
        }
    }
    Ok(())
}

/// Which files a model folder holds: `Some(true)` for binary (`cameras.bin`), `Some(false)`
/// for text (`cameras.txt`), `None` for neither. Binary wins when both exist. A `cameras` entry
/// that is not a folder counts even when it is no regular file (a device, a FIFO, a symlink
/// loop): reading it then says what it is, instead of "no dataset found".
pub fn model_kind(dir: &Path) -> Option<bool> {
    if names_a_file(&dir.join("cameras.bin")) {
        Some(true)
    } else if names_a_file(&dir.join("cameras.txt")) {
        Some(false)
    } else {
        None
    }
}

/// A COLMAP file, read whole ([`crate::file_io::SCENE_FILE`] at most; regular files only).
fn read_file(path: &Path) -> Result<Vec<u8>, SceneError> {
    Ok(crate::file_io::read_bounded(path, crate::file_io::SCENE_FILE)?)
}

/// Reads only the images of the model in `dir` (binary or text).
pub fn read_images(dir: &Path) -> Result<Vec<ColmapImage>, SceneError> {
    match model_kind(dir) {
        Some(true) => {
            let p = dir.join("images.bin");
            super::colmap_binary::parse_images(&read_file(&p)?, &p)
        }
        _ => {
            let p = dir.join("images.txt");
            let bytes = read_file(&p)?;
            super::colmap_text::parse_images(super::colmap_text::decode_utf8(&bytes, &p)?, &p)
        }
    }
}

/// Reads the sparse model in `dir`: `cameras`, `images` and `points3D`, all `.bin` when
/// `cameras.bin` exists, otherwise all `.txt`, and checks that every image's camera exists.
///
/// ```no_run
/// let model = bbsplat::scene::colmap::read_model("data/sparse/0".as_ref())?;
/// println!("{} cameras, {} images, {} points", model.cameras.len(), model.images.len(), model.points.len());
/// # Ok::<(), bbsplat::scene::SceneError>(())
/// ```
pub fn read_model(dir: &Path) -> Result<ColmapModel, SceneError> {
    use super::{colmap_binary as bin, colmap_text as txt};
    let model = match model_kind(dir) {
        Some(true) => {
            let (c, i, p) = (
                dir.join("cameras.bin"),
                dir.join("images.bin"),
                dir.join("points3D.bin"),
            );
            ColmapModel {
                cameras: bin::parse_cameras(&read_file(&c)?, &c)?,
                images: bin::parse_images(&read_file(&i)?, &i)?,
                points: bin::parse_points(&read_file(&p)?, &p)?,
            }
        }
        Some(false) => {
            let (c, i, p) = (
                dir.join("cameras.txt"),
                dir.join("images.txt"),
                dir.join("points3D.txt"),
            );
            let (cb, ib, pb) = (read_file(&c)?, read_file(&i)?, read_file(&p)?);
            ColmapModel {
                cameras: txt::parse_cameras(txt::decode_utf8(&cb, &c)?, &c)?,
                images: txt::parse_images(txt::decode_utf8(&ib, &i)?, &i)?,
                points: txt::parse_points(txt::decode_utf8(&pb, &p)?, &p)?,
            }
        }
        None => {
            return Err(SceneError::NotDetected {
                path: dir.to_path_buf(),
                looked_for: "no cameras.bin or cameras.txt in this folder".into(),
            });
        }
    };
    let images_file = dir.join(if model_kind(dir) == Some(true) {
        "images.bin"
    } else {
        "images.txt"
    });
    check_references(&model, &images_file)?;
    Ok(model)
}
