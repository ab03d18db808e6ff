//! Scene input: posed photographs from COLMAP (binary and text), NeRF-synthetic,
//! instant-ngp / nerfstudio, NeuS/IDR (`cameras_sphere.npz`, DTU) and LLFF
//! (`poses_bounds.npy`) datasets, undistorted to pinhole cameras, with optional object masks.
//!
//! [`load`] detects the format of a folder (or takes it from [`LoadOptions::format`]), reads the
//! cameras, undistorts and downscales every image once, splits the views into training and test
//! sets and returns a [`Scene`]. Formats, conventions, the undistortion method and the error
//! messages are described in `docs/scene.md`.
//!
//! Conventions of the output:
//! - Every [`View::camera`] is an undistorted pinhole [`Camera`] (world-to-camera pose, OpenCV
//!   axes x right / y down / z forward, intrinsics in pixels of the final image, top-left image
//!   corner at `(0, 0)`), whatever the input format. NeRF/instant-ngp OpenGL camera-to-world
//!   matrices are converted with [`Camera::from_c2w_opengl`].
//! - Images are stored as 8-bit RGB ([`Image`]); RGBA inputs are composited onto
//!   [`LoadOptions::background`] at load time (so the stored 8-bit values already include the
//!   background). [`Image::to_f32_rgb`] gives values `byte / 255` (no sRGB decoding).
//! - World units are those of the input (COLMAP's arbitrary scale, NeRF's metres-ish).
//!
//! ```no_run
//! use bbsplat::scene::{load, Background, LoadOptions};
//! let options = LoadOptions { background: Background::White, downscale: 2, ..Default::default() };
//! let scene = load("data/lego".as_ref(), &options)?;
//! println!("{} train / {} test views, extent {}", scene.train.len(), scene.test.len(), scene.extent);
//! # Ok::<(), bbsplat::scene::SceneError>(())
//! ```

pub mod colmap;
pub mod colmap_binary;
mod colmap_scene;
pub mod colmap_text;
pub mod data_background;
pub mod distortion;
pub mod duplicates;
mod error;
#[cfg(feature = "testing")]
pub mod fuzz;
pub(crate) mod image_io;
mod json_scene;
mod llff;
pub mod mask;
pub mod nerf_json;
mod neus;
pub mod npy;
pub mod on_demand;
pub mod ply;
pub mod projection;
pub mod reference_size;
pub mod registration;
pub mod split;
pub mod undistort;
pub mod unfold;
mod views;

pub use error::{Location, SceneError};
pub use undistort::UndistortMode;

use crate::camera::Camera;
use crate::file_io::{FileKind, names_a_file};
use glam::Vec3;
use std::fmt;
use std::path::{Path, PathBuf};

/// An 8-bit RGB image, rows from top to bottom, pixels interleaved `R G B`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Image {
    width: u32,
    height: u32,
    data: Vec<u8>,
}

impl Image {
    /// An image from interleaved RGB bytes; `None` unless `data.len() == width·height·3` and
    /// both sizes are positive.
    ///
    /// ```
    /// use bbsplat::scene::Image;
    /// let im = Image::new(2, 1, vec![255, 0, 0, 0, 0, 51]).unwrap();
    /// assert_eq!(im.pixel(1, 0), [0, 0, 51]);
    /// assert_eq!(im.pixel_f32(1, 0), [0.0, 0.0, 0.2]);
    /// assert_eq!(im.to_f32_rgb(), vec![1.0, 0.0, 0.0, 0.0, 0.0, 0.2]);
    /// assert!(Image::new(2, 2, vec![0; 3]).is_none());
    /// ```
    pub fn new(width: u32, height: u32, data: Vec<u8>) -> Option<Self> {
        let ok = width > 0 && height > 0 && data.len() as u64 == width as u64 * height as u64 * 3;
        ok.then_some(Image { width, height, data })
    }

    /// Crate-internal constructor for buffers known to have the right length.
    pub(crate) fn from_raw(width: u32, height: u32, data: Vec<u8>) -> Self {
        debug_assert_eq!(data.len(), width as usize * height as usize * 3);
        Image { width, height, data }
    }

    /// Width in pixels.
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Height in pixels.
    pub fn height(&self) -> u32 {
        self.height
    }

    /// The interleaved RGB bytes, row-major from the top-left pixel.
    pub fn as_bytes(&self) -> &[u8] {
        &self.data
    }

    /// The interleaved RGB bytes, taken out of the image.
    pub fn into_bytes(self) -> Vec<u8> {
        self.data
    }

    /// The 8-bit RGB value of pixel `(x, y)` (column, row). Panics when out of range.
    pub fn pixel(&self, x: u32, y: u32) -> [u8; 3] {
        assert!(
            x < self.width && y < self.height,
            "pixel ({x}, {y}) outside {}x{}",
            self.width,
            self.height
        );
        let i = (y as usize * self.width as usize + x as usize) * 3;
        [self.data[i], self.data[i + 1], self.data[i + 2]]
    }

    /// Pixel `(x, y)` as values in `[0, 1]` (`byte / 255`). Panics when out of range.
    pub fn pixel_f32(&self, x: u32, y: u32) -> [f32; 3] {
        self.pixel(x, y).map(|v| v as f32 / 255.0)
    }

    /// The whole image as interleaved RGB values in `[0, 1]` (`byte / 255`), row-major,
    /// length `width·height·3`.
    pub fn to_f32_rgb(&self) -> Vec<f32> {
        self.data.iter().map(|&v| v as f32 / 255.0).collect()
    }
}

/// The image of a [`View`]: decoded and held in memory, or decoded from its file when needed
/// through a bounded cache ([`on_demand`]; [`load`] chooses by [`LoadOptions::image_memory`]).
#[derive(Clone, Debug, PartialEq)]
pub enum ViewImage {
    /// Held in memory.
    InMemory(Image),
    /// Decoded again from its file when needed.
    OnDemand(on_demand::OnDemandImage),
}

/// An image borrowed from a [`ViewImage`] held in memory, or shared with an on-demand cache.
#[derive(Debug)]
pub enum ImageRef<'a> {
    /// Borrowed from the view.
    Borrowed(&'a Image),
    /// Shared with the cache.
    Shared(std::sync::Arc<Image>),
}

impl std::ops::Deref for ImageRef<'_> {
    type Target = Image;
    fn deref(&self) -> &Image {
        match self {
            ImageRef::Borrowed(image) => image,
            ImageRef::Shared(image) => image,
        }
    }
}

impl ViewImage {
    /// Width in pixels.
    pub fn width(&self) -> u32 {
        match self {
            ViewImage::InMemory(image) => image.width(),
            ViewImage::OnDemand(image) => image.width(),
        }
    }

    /// Height in pixels.
    pub fn height(&self) -> u32 {
        match self {
            ViewImage::InMemory(image) => image.height(),
            ViewImage::OnDemand(image) => image.height(),
        }
    }

    /// The image, decoding it when it is not in memory ([`on_demand::OnDemandImage::load`]).
    ///
    /// # Errors
    /// Only for an on-demand image: its file no longer decodes, or decodes to other pixels
    /// ([`SceneError::ImageChanged`]).
    pub fn get(&self) -> Result<ImageRef<'_>, SceneError> {
        match self {
            ViewImage::InMemory(image) => Ok(ImageRef::Borrowed(image)),
            ViewImage::OnDemand(image) => image.load().map(ImageRef::Shared),
        }
    }

    /// The image when it is held in memory.
    pub fn in_memory(&self) -> Option<&Image> {
        match self {
            ViewImage::InMemory(image) => Some(image),
            ViewImage::OnDemand(_) => None,
        }
    }

    /// Bytes of pixels this view holds by itself (an on-demand image's cache is shared and
    /// counted by [`Scene::image_bytes`]).
    pub fn held_bytes(&self) -> u64 {
        match self {
            ViewImage::InMemory(image) => image.as_bytes().len() as u64,
            ViewImage::OnDemand(_) => 0,
        }
    }
}

impl From<Image> for ViewImage {
    fn from(image: Image) -> Self {
        ViewImage::InMemory(image)
    }
}

/// The smallest side, in pixels, that [`LoadOptions::downscale`] and [`LoadOptions::max_width`]
/// may shrink an image to (a smaller image has too few pixels to train on; images stored smaller
/// are loaded as they are).
pub const MIN_DOWNSCALED_SIDE: u32 = 8;

/// One posed photograph.
#[derive(Clone, Debug, PartialEq)]
pub struct View {
    /// Name: the COLMAP image name, or the frame's `file_path` as written in the JSON file.
    pub name: String,
    /// The image file it was loaded from.
    pub path: PathBuf,
    /// The undistorted pinhole camera at the final image resolution.
    pub camera: Camera,
    /// The undistorted, downscaled, background-composited image (`camera.width × camera.height`),
    /// in memory or decoded on demand ([`ViewImage`]).
    pub image: ViewImage,
    /// The image's own alpha channel at the final resolution (`camera.width × camera.height`
    /// values, row-major, 0 = background), when the file had one and needed no undistortion
    /// (e.g. NeRF-synthetic renders). Used by the visual-hull initialisation
    /// ([`crate::init::hull`]); never by the loss.
    pub coverage: Option<Vec<u8>>,
    /// The view's object mask at the final resolution (`camera.width × camera.height` values,
    /// row-major, 255 = keep), when one was loaded: NeuS `mask/`, or
    /// [`LoadOptions::masks_dir`] ([`mask`]). With [`mask::MaskMode::Composite`] (the default)
    /// `image` is already composited onto the background outside it. Masked evaluation uses it
    /// (or else `coverage`).
    pub mask: Option<Vec<u8>>,
}

/// A point cloud (for initialisation), world coordinates.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct PointCloud {
    /// Positions in world units.
    pub positions: Vec<Vec3>,
    /// Colours as RGB in `[0, 1]` (8-bit values / 255).
    pub colours: Vec<[f32; 3]>,
}

/// The dataset formats [`load`] reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SceneFormat {
    /// A COLMAP sparse model (binary or text) with an image folder.
    Colmap,
    /// NeRF-synthetic (Blender): `transforms_train.json` and `transforms_test.json`.
    NerfSynthetic,
    /// instant-ngp / nerfstudio: `transforms.json`.
    Transforms,
    /// NeuS / IDR (DTU, BlendedMVS as NeuS ships them): `cameras_sphere.npz` with `image/` and
    /// `mask/`.
    Neus,
    /// LLFF (the NeRF forward-facing scenes): `poses_bounds.npy` with `images_N/`.
    Llff,
}

impl fmt::Display for SceneFormat {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            SceneFormat::Colmap => "COLMAP",
            SceneFormat::NerfSynthetic => "NeRF-synthetic",
            SceneFormat::Transforms => "instant-ngp/nerfstudio transforms.json",
            SceneFormat::Neus => "NeuS/IDR cameras_sphere.npz",
            SceneFormat::Llff => "LLFF poses_bounds.npy",
        })
    }
}

/// The colour RGBA images are composited onto (and that renders should use behind the scene).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Background {
    /// Black, `[0, 0, 0]` (the default, as in 3DGS/BBSplat without `--white_background`).
    #[default]
    Black,
    /// White, `[1, 1, 1]` (used for published NeRF-synthetic numbers).
    White,
}

impl Background {
    /// The colour as RGB in `[0, 1]`.
    pub fn rgb(self) -> [f32; 3] {
        match self {
            Background::Black => [0.0; 3],
            Background::White => [1.0; 3],
        }
    }

    /// The background of an RGB colour: exactly `[0, 0, 0]` or `[1, 1, 1]`, else `None` (e.g. a
    /// model's [`crate::model_file::ModelMeta::background`]).
    ///
    /// ```
    /// use bbsplat::scene::Background;
    /// assert_eq!(Background::from_rgb([1.0; 3]), Some(Background::White));
    /// assert_eq!(Background::from_rgb([0.5; 3]), None);
    /// ```
    pub fn from_rgb(rgb: [f32; 3]) -> Option<Background> {
        [Background::Black, Background::White]
            .into_iter()
            .find(|b| b.rgb() == rgb)
    }
}

/// Options of [`load`]. `LoadOptions::default()` detects the format, composites on black,
/// keeps the full resolution, holds out every 8th view and crops undistorted images.
#[derive(Clone, Debug, PartialEq)]
pub struct LoadOptions {
    /// Force a format instead of detecting it.
    pub format: Option<SceneFormat>,
    /// Background for RGBA images.
    pub background: Background,
    /// Integer downscale factor (typically 1, 2, 4 or 8; at least 1): the size becomes
    /// `round(size / factor)` (at least 1 pixel) and the intrinsics are scaled by the exact size
    /// ratio. Images are area-averaged.
    pub downscale: u32,
    /// Maximum image width after `downscale`: wider images are area-downscaled to this width
    /// (height rounded to keep the aspect ratio), intrinsics scaled exactly.
    pub max_width: Option<u32>,
    /// Hold out every `test_every`-th view (index 0, n, 2n, ... in name order) as the test set
    /// when the dataset has no test list; 0 puts every view in the training set.
    pub test_every: usize,
    /// How undistorted images are bounded.
    pub undistort: UndistortMode,
    /// Image folder of a COLMAP dataset (default: `images` beside `sparse`).
    pub images_dir: Option<PathBuf>,
    /// Also print warnings (skipped frames, missing point clouds) to stderr; they are always
    /// collected in [`Scene::warnings`].
    pub print_warnings: bool,
    /// Accept damaged images (a JPEG cut short, whose missing part decodes grey) with a warning
    /// instead of refusing them with [`SceneError::ImageDecode`]. Default false.
    pub allow_damaged_images: bool,
    /// Turn back the passes of a COLMAP registration that folded an orbit video onto itself
    /// ([`unfold`]; reported in [`Scene::warnings`]). Default true.
    pub unfold: bool,
    /// A folder of object masks, one per image, matched by file stem ([`mask::find_mask`]);
    /// it replaces a NeuS dataset's own `mask/`. Default none.
    pub masks_dir: Option<PathBuf>,
    /// What loading does with the masks ([`mask::MaskMode`]; default: composite the images onto
    /// the background outside them).
    pub mask_mode: mask::MaskMode,
    /// Bytes of 8-bit images the scene may hold in memory (default
    /// [`on_demand::DEFAULT_IMAGE_MEMORY`], 2 GiB). When the images of all its views fit, they
    /// are held in memory; otherwise every view is decoded on demand from its file through a
    /// cache of this size ([`on_demand`]), which gives the same pixels.
    pub image_memory: u64,
}

impl Default for LoadOptions {
    fn default() -> Self {
        LoadOptions {
            format: None,
            background: Background::Black,
            downscale: 1,
            max_width: None,
            test_every: 8,
            undistort: UndistortMode::Crop,
            images_dir: None,
            print_warnings: true,
            allow_damaged_images: false,
            unfold: true,
            masks_dir: None,
            mask_mode: mask::MaskMode::Composite,
            image_memory: on_demand::DEFAULT_IMAGE_MEMORY,
        }
    }
}

/// A loaded scene.
#[derive(Clone, Debug)]
pub struct Scene {
    /// Name of the dataset folder.
    pub name: String,
    /// The format it was read as.
    pub format: SceneFormat,
    /// The file or model folder the cameras came from.
    pub source: PathBuf,
    /// The background RGBA images were composited onto.
    pub background: Background,
    /// Training views (COLMAP and transforms.json: name order; NeRF-synthetic: file order).
    pub train: Vec<View>,
    /// Test views.
    pub test: Vec<View>,
    /// The point cloud, when the dataset has one (COLMAP `points3D`, nerfstudio `ply_file_path`).
    pub points: Option<PointCloud>,
    /// Scene extent for learning-rate scaling: 1.1 × the largest distance of a training camera
    /// centre from the mean of the training camera centres (world units), as 3DGS. Points are
    /// not used, so outlier points cannot inflate it, and cameras far from all others
    /// ([`split::outlying_cameras`], reported in [`Scene::warnings`]) are left out. 1.1 when all
    /// centres coincide.
    pub extent: f32,
    /// Warnings raised while loading (e.g. frames skipped because their image is missing).
    pub warnings: Vec<String>,
}

impl Scene {
    /// Keeps only the views named in `names`, training and test views alike (each stays in its
    /// split), and recomputes [`Scene::extent`] from the training views kept (outlying cameras
    /// left out, as [`load`] does). Returns the names that are no view of the scene, in order.
    /// How a block of a large scene trains on its own views ([`crate::blocks`]).
    ///
    /// ```
    /// # use bbsplat::demo::{DemoConfig, export_colmap, generate};
    /// # let dir = std::env::temp_dir().join(format!("bbsplat-keep-views-{}", std::process::id()));
    /// # export_colmap(&generate(&DemoConfig { resolution: 8, train_views: 7, test_views: 1, points: 50, seed: 0 }), &dir)?;
    /// let mut scene = bbsplat::load(&dir, &bbsplat::LoadOptions::default())?;
    /// let names = [scene.train[0].name.clone(), scene.test[0].name.clone(), "no_such.png".into()];
    /// let unknown = scene.keep_views(&names.into_iter().collect());
    /// assert_eq!((scene.train.len(), scene.test.len()), (1, 1));
    /// assert_eq!(unknown, ["no_such.png"]);
    /// # std::fs::remove_dir_all(&dir)?;
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn keep_views(&mut self, names: &std::collections::BTreeSet<String>) -> Vec<String> {
        self.train.retain(|v| names.contains(&v.name));
        self.test.retain(|v| names.contains(&v.name));
        self.extent = split::extent_without_outliers(self.train.iter().map(|v| &v.camera)).0;
        let known: std::collections::BTreeSet<&str> =
            self.train.iter().chain(&self.test).map(|v| v.name.as_str()).collect();
        names.iter().filter(|n| !known.contains(n.as_str())).cloned().collect()
    }

    /// The cache the scene's on-demand images share ([`on_demand`]), `None` when its images are
    /// held in memory.
    pub fn image_cache(&self) -> Option<&std::sync::Arc<on_demand::ImageCache>> {
        self.train.iter().chain(&self.test).find_map(|v| match &v.image {
            ViewImage::OnDemand(image) => Some(image.cache()),
            ViewImage::InMemory(_) => None,
        })
    }

    /// The most bytes of 8-bit images the scene holds: the images held in memory, or the
    /// budget of its on-demand cache.
    pub fn image_bytes(&self) -> u64 {
        let held: u64 = self.train.iter().chain(&self.test).map(|v| v.image.held_bytes()).sum();
        held + self.image_cache().map_or(0, |c| c.budget())
    }
}

/// Loads the dataset at `path`: a dataset folder, a COLMAP model folder, or a transforms JSON
/// file. See the module documentation and `docs/scene.md`.
///
/// Detection, in order: a `transforms_train.json` file or folder entry → NeRF-synthetic; a
/// `transforms.json` → instant-ngp/nerfstudio; a COLMAP model (`cameras.bin`/`.txt`) in the
/// folder itself, in `sparse/`, or in `sparse/*/` (with several models, the one with the most
/// registered images) → COLMAP; a `cameras_sphere.npz` (or IDR's `cameras.npz`) → NeuS/IDR; a
/// `poses_bounds.npy` → LLFF. A file path is read as the format its name says
/// (`cameras_sphere.npz`, `cameras.npz` and `poses_bounds.npy` included).
pub fn load(path: &Path, options: &LoadOptions) -> Result<Scene, SceneError> {
    if options.downscale == 0 {
        return Err(SceneError::InvalidOption("downscale must be at least 1".into()));
    }
    if options.max_width == Some(0) {
        return Err(SceneError::InvalidOption("max_width must be at least 1".into()));
    }
    let (format, source) = detect(path, options.format)?;
    let mut warnings = Vec::new();
    let mut scene = match format {
        SceneFormat::Colmap => colmap_scene::load(&source, options, &mut warnings)?,
        SceneFormat::NerfSynthetic => json_scene::load_nerf_synthetic(&source, options, &mut warnings)?,
        SceneFormat::Transforms => json_scene::load_transforms(&source, options, &mut warnings)?,
        SceneFormat::Neus => neus::load(&source, options, &mut warnings)?,
        SceneFormat::Llff => llff::load(&source, options, &mut warnings)?,
    };
    duplicates::leave_out(&mut scene.train, &mut scene.test, &mut warnings)?;
    if scene.train.is_empty() {
        return Err(SceneError::Empty {
            path: source,
            reason: format!(
                "no training view ({} test views); lower test_every or add images",
                scene.test.len()
            ),
        });
    }
    // Poses far from all others are reported and left out of the extent (they would inflate the
    // position learning rate and ruin the run).
    let outliers;
    (scene.extent, outliers) = split::extent_without_outliers(scene.train.iter().map(|v| &v.camera));
    for o in &outliers {
        warnings.push(format!(
            "the camera of view {:?} lies {:.3} units from the median camera centre, {:.0} times the median distance ({:.3}): a misregistered pose? It is left out of the scene extent",
            scene.train[o.index].name,
            o.distance,
            o.distance / o.median_distance,
            o.median_distance
        ));
    }
    if let Some(points) = &scene.points {
        far_points(points, &scene.train, scene.extent, &scene.source)?;
    }
    if options.print_warnings {
        for w in &warnings {
            eprintln!("warning: {w}");
        }
    }
    scene.warnings = warnings;
    Ok(scene)
}

/// How far from the training cameras' mean centre, in scene extents, a point may lie
/// (checked by [`load`]): a sky point of a real capture lies some thousands of extents away.
pub const MAX_POINT_DISTANCE: f32 = 1e6;

/// Refuses a point cloud with a point farther than [`MAX_POINT_DISTANCE`] scene extents from the
/// training cameras (a corrupt or misregistered cloud: the billboards initialised on it would get
/// astronomical scales), naming the file and the point.
fn far_points(points: &PointCloud, train: &[View], extent: f32, source: &Path) -> Result<(), SceneError> {
    let n = train.len().max(1) as f32;
    let mean = train.iter().map(|v| v.camera.centre()).sum::<Vec3>() / n;
    let limit = MAX_POINT_DISTANCE * extent;
    match points
        .positions
        .iter()
        .enumerate()
        .find(|(_, p)| p.distance(mean).is_nan() || p.distance(mean) > limit)
    {
        None => Ok(()),
        Some((i, p)) => Err(SceneError::parse(
            source,
            Location::Record(format!("point cloud point {i}")),
            format!(
                "at {p:?}, {:.1e} scene extents ({extent}) from the cameras, more than {MAX_POINT_DISTANCE:.0e}: a corrupt or misregistered point cloud",
                p.distance(mean) / extent
            ),
        )),
    }
}

/// Detects the format of `path` (or checks the forced one) and returns it with the file or
/// model folder to read. A path that is neither a folder nor a regular file is refused saying
/// what it is (a symlink loop, a link to a missing file, a FIFO, a device), not "does not exist".
pub fn detect(path: &Path, forced: Option<SceneFormat>) -> Result<(SceneFormat, PathBuf), SceneError> {
    match crate::file_io::kind_of(path) {
        Ok(FileKind::Regular | FileKind::Directory) => {}
        Ok(FileKind::Missing) => {
            return Err(SceneError::io(path, std::io::Error::from(std::io::ErrorKind::NotFound)));
        }
        Ok(kind) => return Err(crate::file_io::not_regular(path, "scene", kind).into()),
        Err(e) => return Err(SceneError::io(path, e)),
    }
    if path.is_file() {
        let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("");
        let format = forced.unwrap_or(if name.ends_with("transforms_train.json") {
            SceneFormat::NerfSynthetic
        } else if name.ends_with(".npz") {
            SceneFormat::Neus
        } else if name.ends_with(".npy") {
            SceneFormat::Llff
        } else {
            SceneFormat::Transforms
        });
        if format == SceneFormat::Colmap {
            return Err(SceneError::NotDetected {
                path: path.to_path_buf(),
                looked_for: "COLMAP format forced, but the path is a file: give the dataset or model folder".into(),
            });
        }
        return Ok((format, path.to_path_buf()));
    }
    let synthetic = path.join("transforms_train.json");
    let transforms = path.join("transforms.json");
    match forced {
        Some(SceneFormat::NerfSynthetic) => return Ok((SceneFormat::NerfSynthetic, synthetic)),
        Some(SceneFormat::Transforms) => return Ok((SceneFormat::Transforms, transforms)),
        Some(SceneFormat::Neus) => return Ok((SceneFormat::Neus, neus::camera_file(path))),
        Some(SceneFormat::Llff) => return Ok((SceneFormat::Llff, path.join(llff::POSES_FILE))),
        Some(SceneFormat::Colmap) => {}
        None if names_a_file(&synthetic) => return Ok((SceneFormat::NerfSynthetic, synthetic)),
        None if names_a_file(&transforms) => return Ok((SceneFormat::Transforms, transforms)),
        None => {}
    }
    match colmap_scene::find_model(path)? {
        Some(dir) => Ok((SceneFormat::Colmap, dir)),
        None if forced.is_none() && names_a_file(&neus::camera_file(path)) => {
            Ok((SceneFormat::Neus, neus::camera_file(path)))
        }
        None if forced.is_none() && names_a_file(&path.join(llff::POSES_FILE)) => {
            Ok((SceneFormat::Llff, path.join(llff::POSES_FILE)))
        }
        None => Err(SceneError::NotDetected {
            path: path.to_path_buf(),
            looked_for: "looked for transforms_train.json, transforms.json, a COLMAP model \
                         (cameras.bin or cameras.txt) in the folder, in sparse/ and in sparse/*/, \
                         cameras_sphere.npz or cameras.npz (NeuS/IDR) and poses_bounds.npy (LLFF)"
                .into(),
        }),
    }
}
