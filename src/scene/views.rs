//! Turning a posed image reference into a [`View`]: decode, check the size, undistort,
//! downscale, build the pinhole camera; decode, resample and apply the view's mask
//! ([`super::mask`]).

use super::colmap::Intrinsics;
use super::error::{Location, SceneError};
use super::mask::{self, MaskMode};
use super::nerf_json::IntrinsicFields;
use super::on_demand::{ImageCache, OnDemandImage, Recipe};
use super::reference_size::{ReferenceSize, scale_to_image};
use super::undistort;
use super::{Image, LoadOptions, View, ViewImage, image_io};
use crate::camera::Camera;
use crate::file_io::{FileKind, kind_of, not_regular};
use glam::{Mat3, Vec3};
use rayon::prelude::*;
use std::path::PathBuf;
use std::sync::Arc;

/// How the camera of a view is known.
pub(crate) enum CameraSpec {
    /// Fully given (COLMAP): intrinsics and the size the camera states.
    Known {
        intrinsics: Intrinsics,
        width: u64,
        height: u64,
    },
    /// JSON fields resolved once the image size is known.
    Json {
        frame: Box<IntrinsicFields>,
        scene: Box<IntrinsicFields>,
    },
    /// Intrinsics stated for another image size (NeuS, LLFF), scaled to the image found
    /// ([`scale_to_image`]).
    Scaled {
        intrinsics: Intrinsics,
        reference: ReferenceSize,
    },
}

/// Everything needed to load one view.
pub(crate) struct ViewSource {
    pub name: String,
    pub image_path: PathBuf,
    /// The file holding the record (for messages).
    pub file: PathBuf,
    /// The record (for messages).
    pub location: Location,
    pub camera: CameraSpec,
    /// World-to-camera rotation and translation (OpenCV axes).
    pub rotation: Mat3,
    pub translation: Vec3,
    /// The view's mask file, when the format has one (NeuS `mask/`); `LoadOptions::masks_dir`
    /// replaces it.
    pub mask: Option<PathBuf>,
}

impl ViewSource {
    /// The error for a missing image file.
    pub(crate) fn missing(&self) -> SceneError {
        SceneError::MissingImage {
            file: self.file.clone(),
            location: self.location.clone(),
            image: self.image_path.clone(),
        }
    }
}

/// Loads every view in parallel; the first error in list order is returned. Warnings about
/// damaged images accepted by [`LoadOptions::allow_damaged_images`] are added to `warnings`, in
/// list order. The images are held in memory while they fit in [`LoadOptions::image_memory`];
/// when they do not, every view is turned on demand, sharing one cache of that size
/// ([`super::on_demand`]).
pub(crate) fn load_all(
    sources: Vec<ViewSource>,
    options: &LoadOptions,
    warnings: &mut Vec<String>,
) -> Result<Vec<View>, SceneError> {
    let mut sources = sources;
    if let Some(dir) = &options.masks_dir {
        if !dir.is_dir() {
            return Err(SceneError::NotDetected {
                path: dir.clone(),
                looked_for: "the mask folder (--masks, LoadOptions::masks_dir) is not a folder".into(),
            });
        }
        for s in &mut sources {
            let found = mask::find_mask(dir, &s.name);
            let Some(found) = found else {
                return Err(SceneError::MissingMask {
                    image: s.image_path.clone(),
                    masks_dir: dir.clone(),
                });
            };
            s.mask = Some(found);
        }
    }
    for s in &sources {
        match kind_of(&s.image_path) {
            Ok(FileKind::Regular) => {}
            Ok(FileKind::Missing) => return Err(s.missing()),
            Ok(kind) => return Err(not_regular(&s.image_path, crate::file_io::IMAGE.what, kind).into()),
            Err(e) => return Err(SceneError::io(&s.image_path, e)),
        }
    }
    let cache = Arc::new(ImageCache::new(options.image_memory));
    let mut views: Vec<View> = Vec::with_capacity(sources.len());
    // While the images are held in memory: each view's recipe, to turn it on demand later.
    let mut recipes: Vec<Arc<Recipe>> = Vec::new();
    let (mut held, mut on_demand) = (0u64, false);
    let mut turned: Vec<(PathBuf, &'static str)> = Vec::new();
    // In chunks, so that no more than the budget and one chunk of images is ever held.
    let chunk = 2 * rayon::current_num_threads().max(4);
    let mut sources = sources.into_iter();
    loop {
        let batch: Vec<ViewSource> = sources.by_ref().take(chunk).collect();
        if batch.is_empty() {
            break;
        }
        let results: Vec<(ViewSource, Result<LoadedView, SceneError>)> = batch
            .into_par_iter()
            .map(|s| {
                let loaded = load_view(&s, options);
                (s, loaded)
            })
            .collect();
        for (source, r) in results {
            let (mut view, warning, turn) = r?;
            warnings.extend(warning);
            if let Some(turn) = turn {
                turned.push((view.path.clone(), turn));
            }
            let recipe = Arc::new(Recipe {
                source,
                options: options.clone(),
            });
            if on_demand {
                view.image = turn_on_demand(view.image, recipe, &cache, views.len());
            } else {
                held += view.image.held_bytes();
                recipes.push(recipe);
            }
            views.push(view);
        }
        if !on_demand && held > options.image_memory {
            on_demand = true;
            views = std::mem::take(&mut views)
                .into_iter()
                .zip(recipes.drain(..))
                .enumerate()
                .map(|(key, (view, recipe))| View {
                    image: turn_on_demand(view.image, recipe, &cache, key),
                    ..view
                })
                .collect();
        }
    }
    if let Some((first, turn)) = turned.first() {
        warnings.push(format!(
            "{} of {} images ask through their EXIF orientation to be shown turned or mirrored ({} {turn}{}); \
             it is not applied: structure from motion registers the pixels as stored, so the cameras fit them \
             as stored, and renders show the scene as stored",
            turned.len(),
            views.len(),
            first.display(),
            if turned.len() > 1 { ", ..." } else { "" }
        ));
    }
    Ok(views)
}

/// `image` (just decoded from `recipe`) as an on-demand image of `cache` under `key`.
fn turn_on_demand(image: ViewImage, recipe: Arc<Recipe>, cache: &Arc<ImageCache>, key: usize) -> ViewImage {
    match image {
        ViewImage::InMemory(image) => {
            ViewImage::OnDemand(OnDemandImage::new(recipe, Arc::clone(cache), key, Arc::new(image)))
        }
        on_demand => on_demand,
    }
}

/// A loaded view, the warning naming its damage (if accepted damaged) and its EXIF orientation
/// (if not the normal one, [`image_io::exif_turn`]).
type LoadedView = (View, Option<String>, Option<&'static str>);

/// Decodes and checks the view of `s` (in memory); [`super::on_demand`] calls it again to decode
/// an on-demand image.
pub(crate) fn load_view(s: &ViewSource, options: &LoadOptions) -> Result<LoadedView, SceneError> {
    let background = options.background.rgb();
    let (image, alpha, damage, turn) = image_io::decode_with_alpha(
        &s.image_path,
        &s.file,
        &s.location,
        background,
        options.allow_damaged_images,
    )?;
    let (iw, ih) = (image.width(), image.height());
    let perr = |m: String| SceneError::parse(&s.file, s.location.clone(), m);
    let (intrinsics, cw, ch) = match &s.camera {
        CameraSpec::Known {
            intrinsics,
            width,
            height,
        } => (*intrinsics, *width, *height),
        CameraSpec::Json { frame, scene } => {
            let (k, w, h) = frame.resolve(scene, iw, ih).map_err(perr)?;
            (k, w as u64, h as u64)
        }
        CameraSpec::Scaled { intrinsics, reference } => {
            let k = scale_to_image(intrinsics, *reference, iw, ih)
                .map_err(|m| perr(format!("{}: {m}", s.image_path.display())))?;
            if let Some(problem) = k.implausibility(iw, ih) {
                return Err(perr(format!("{}: {problem}", s.image_path.display())));
            }
            (k, iw as u64, ih as u64)
        }
    };
    if (cw, ch) != (iw as u64, ih as u64) {
        return Err(SceneError::ImageSize {
            image: s.image_path.clone(),
            actual: (iw as u64, ih as u64),
            expected: (cw, ch),
            file: s.file.clone(),
            location: s.location.clone(),
        });
    }
    let plan = undistort::plan(&intrinsics, iw, ih, options.undistort).map_err(perr)?;
    let (nw, nh) = image_io::target_size(plan.width, plan.height, options.downscale, options.max_width);
    if (nw, nh) != (plan.width, plan.height) && nw.min(nh) < super::MIN_DOWNSCALED_SIDE {
        return Err(SceneError::InvalidOption(format!(
            "{}: {}x{} becomes {nw}x{nh} with downscale {}{}, under the {} pixels a side that a downscaled image keeps; \
             choose a smaller downscale{}",
            s.image_path.display(),
            plan.width,
            plan.height,
            options.downscale,
            options
                .max_width
                .map_or(String::new(), |m| format!(" and max width {m}")),
            super::MIN_DOWNSCALED_SIDE,
            if options.max_width.is_some() {
                " or a larger max width"
            } else {
                ""
            },
        )));
    }
    // Coverage is kept for images that need no undistortion (RGBA renders such as NeRF-synthetic).
    let coverage = alpha
        .filter(|_| !undistort::needs_undistortion(&intrinsics.distortion))
        .map(|a| image_io::resize_area_u8(&a, iw as usize, ih as usize, nw as usize, nh as usize));
    let mask = match &s.mask {
        None => None,
        Some(path) => {
            let m = mask::decode_mask(path, &s.image_path, &s.location, iw, ih)?;
            Some(if undistort::needs_undistortion(&intrinsics.distortion) {
                let grey = Image::from_raw(iw, ih, m.iter().flat_map(|&v| [v; 3]).collect());
                let f = undistort::resample(&plan, &grey, [0.0; 3]);
                let small =
                    image_io::resize_area(&f, plan.width as usize, plan.height as usize, nw as usize, nh as usize);
                image_io::quantise(nw, nh, &small)
                    .as_bytes()
                    .iter()
                    .step_by(3)
                    .copied()
                    .collect()
            } else {
                image_io::resize_area_u8(&m, iw as usize, ih as usize, nw as usize, nh as usize)
            })
        }
    };
    let image = if !undistort::needs_undistortion(&intrinsics.distortion) {
        if (nw, nh) == (iw, ih) {
            image
        } else {
            let f = image.to_f32_rgb();
            let small = image_io::resize_area(&f, iw as usize, ih as usize, nw as usize, nh as usize);
            image_io::quantise(nw, nh, &small)
        }
    } else {
        let f = undistort::resample(&plan, &image, background);
        let small = image_io::resize_area(&f, plan.width as usize, plan.height as usize, nw as usize, nh as usize);
        image_io::quantise(nw, nh, &small)
    };
    let image = match (&mask, options.mask_mode) {
        (Some(m), MaskMode::Composite) => {
            let mut rgb = image.into_bytes();
            mask::composite_outside(&mut rgb, m, background);
            Image::from_raw(nw, nh, rgb)
        }
        _ => image,
    };
    let sx = nw as f64 / plan.width as f64;
    let sy = nh as f64 / plan.height as f64;
    let camera = Camera {
        rotation: s.rotation,
        translation: s.translation,
        fx: (plan.fx * sx) as f32,
        fy: (plan.fy * sy) as f32,
        cx: (plan.cx * sx) as f32,
        cy: (plan.cy * sy) as f32,
        width: nw,
        height: nh,
    };
    if ![camera.fx, camera.fy, camera.cx, camera.cy]
        .iter()
        .all(|v| v.is_finite())
    {
        return Err(perr(format!(
            "intrinsics (fx {}, fy {}, cx {}, cy {}) overflow single precision",
            plan.fx, plan.fy, plan.cx, plan.cy
        )));
    }
    let view = View {
        name: s.name.clone(),
        path: s.image_path.clone(),
        camera,
        image: ViewImage::InMemory(image),
        coverage,
        mask,
    };
    Ok((view, damage, turn))
}
