//! Building a [`Scene`] from NeRF-synthetic or instant-ngp/nerfstudio transforms files.

use super::error::{Location, SceneError};
use super::nerf_json::{TransformsFile, parse_transforms};
use super::views::{self, CameraSpec, ViewSource};
use super::{LoadOptions, Scene, SceneFormat, View, ply, split};
use crate::camera::Camera;
use crate::file_io::names_a_file;
use glam::Mat3;
use std::path::{Path, PathBuf};

/// Extensions tried, in order, when a `file_path` does not name an existing file.
const EXTENSIONS: [&str; 5] = ["png", "jpg", "jpeg", "PNG", "JPG"];

/// Resolves a frame's image path relative to `dir`: the path itself when it names a file
/// ([`crate::file_io::names_a_file`]: a device or a FIFO too, refused with what it is when read),
/// otherwise with each of [`EXTENSIONS`] appended. `Err` holds the path reported as missing
/// (with `.png` appended when the path had no extension).
fn resolve_image(dir: &Path, file_path: &str) -> Result<PathBuf, PathBuf> {
    let base = dir.join(file_path);
    if names_a_file(&base) {
        return Ok(base);
    }
    for ext in EXTENSIONS {
        let mut s = base.clone().into_os_string();
        s.push(".");
        s.push(ext);
        let p = PathBuf::from(s);
        if names_a_file(&p) {
            return Ok(p);
        }
    }
    if base.extension().is_none() {
        let mut s = base.into_os_string();
        s.push(".png");
        Err(PathBuf::from(s))
    } else {
        Err(base)
    }
}

fn read_transforms(file: &Path) -> Result<TransformsFile, SceneError> {
    let bytes = crate::file_io::read_bounded(file, crate::file_io::JSON_FILE)?;
    let text = super::colmap_text::decode_utf8(&bytes, file)?;
    parse_transforms(text, file)
}

/// View sources of a transforms file's frames. Missing images are errors when `skip_missing`
/// is false, otherwise the frame is skipped with a warning.
fn sources_of(
    file: &Path,
    t: &TransformsFile,
    skip_missing: bool,
    warnings: &mut Vec<String>,
) -> Result<Vec<ViewSource>, SceneError> {
    let dir = file.parent().unwrap_or(Path::new("."));
    let mut out = Vec::with_capacity(t.frames.len());
    for (i, f) in t.frames.iter().enumerate() {
        let location = Location::Record(format!("frames[{i}] ({:?})", f.file_path));
        let rows = f.transform_matrix.map(|r| r.map(|v| v as f32));
        let cam = Camera::from_c2w_opengl(rows, 1.0, 1.0, 0.0, 0.0, 1, 1);
        let (rotation, translation): (Mat3, _) = (cam.rotation, cam.translation);
        if !rotation.is_finite() || !translation.is_finite() {
            return Err(SceneError::parse(
                file,
                location,
                "pose is not finite in single precision",
            ));
        }
        let image_path = match resolve_image(dir, &f.file_path) {
            Ok(p) => p,
            Err(missing) if skip_missing => {
                warnings.push(format!(
                    "{}: {location}: image file {} does not exist; frame skipped",
                    file.display(),
                    missing.display()
                ));
                continue;
            }
            Err(missing) => {
                return Err(SceneError::MissingImage {
                    file: file.to_path_buf(),
                    location,
                    image: missing,
                });
            }
        };
        let name = f.file_path.strip_prefix("./").unwrap_or(&f.file_path).to_string();
        out.push(ViewSource {
            name,
            image_path,
            file: file.to_path_buf(),
            location,
            camera: CameraSpec::Json {
                frame: Box::new(f.intrinsics.clone()),
                scene: Box::new(t.intrinsics.clone()),
            },
            rotation,
            translation,
            mask: None,
        });
    }
    Ok(out)
}

fn scene_name(file: &Path) -> String {
    file.parent()
        .and_then(|d| std::fs::canonicalize(d).ok())
        .and_then(|d| d.file_name().and_then(|n| n.to_str()).map(str::to_owned))
        .unwrap_or_else(|| "scene".into())
}

fn sort_by_name(mut views: Vec<View>) -> Vec<View> {
    views.sort_by(|a, b| a.name.cmp(&b.name));
    views
}

/// NeRF-synthetic: `transforms_train.json` is the training set (file order) and the sibling
/// `transforms_test.json`, when present, the test set; without it the every-n-th rule applies.
pub(crate) fn load_nerf_synthetic(
    train_file: &Path,
    options: &LoadOptions,
    warnings: &mut Vec<String>,
) -> Result<Scene, SceneError> {
    let train_json = read_transforms(train_file)?;
    if train_json.frames.is_empty() {
        return Err(SceneError::Empty {
            path: train_file.to_path_buf(),
            reason: "\"frames\" is empty".into(),
        });
    }
    let test_name = train_file
        .file_name()
        .and_then(|n| n.to_str())
        .map(|n| n.replace("transforms_train", "transforms_test"))
        .unwrap_or_else(|| "transforms_test.json".into());
    let test_file = train_file.with_file_name(test_name);
    let train_sources = sources_of(train_file, &train_json, false, warnings)?;
    let (train, test) = if names_a_file(&test_file) {
        let test_json = read_transforms(&test_file)?;
        let test_sources = sources_of(&test_file, &test_json, false, warnings)?;
        // One load for both, so that they share one image budget.
        let train_count = train_sources.len();
        let mut train = views::load_all(
            train_sources.into_iter().chain(test_sources).collect(),
            options,
            warnings,
        )?;
        let test = train.split_off(train_count);
        (train, test)
    } else {
        let views = sort_by_name(views::load_all(train_sources, options, warnings)?);
        split::split_every(views, options.test_every)
    };
    Ok(Scene {
        name: scene_name(train_file),
        format: SceneFormat::NerfSynthetic,
        source: train_file.to_path_buf(),
        background: options.background,
        train,
        test,
        points: None,
        extent: 0.0,
        warnings: Vec::new(),
    })
}

/// The warning when the scene's one focal length in pixels (`fl_x`/`fl_y`, no `w`/`h`), used by
/// frames without their own, meets images of different sizes: the same focal gives them
/// different fields of view, which is wrong when they were resized copies of one camera's
/// photos.
fn one_focal_for_mixed_sizes(file: &Path, t: &TransformsFile, views: &[View]) -> Option<String> {
    let scene = &t.intrinsics;
    let shared = (scene.fl_x.is_some() || scene.fl_y.is_some()) && scene.w.is_none() && scene.h.is_none();
    let own_focal = t
        .frames
        .iter()
        .any(|f| f.intrinsics.fl_x.is_some() || f.intrinsics.fl_y.is_some());
    if !shared || own_focal {
        return None;
    }
    let first = views.first()?;
    let size = |v: &View| (v.camera.width, v.camera.height);
    let other = views.iter().find(|v| size(v) != size(first))?;
    Some(format!(
        "{}: one focal length (fl_x/fl_y) for images of different sizes ({:?} is {}x{}, {:?} {}x{}) gives them \
         different fields of view: if the images were resized, give the frames their own fl_x, w and h",
        file.display(),
        first.name,
        first.camera.width,
        first.camera.height,
        other.name,
        other.camera.width,
        other.camera.height
    ))
}

/// instant-ngp / nerfstudio `transforms.json`: frames whose image is missing are skipped with a
/// warning; views are sorted by name and every n-th is held out; `ply_file_path` is read when
/// it exists (a warning when it does not).
pub(crate) fn load_transforms(
    file: &Path,
    options: &LoadOptions,
    warnings: &mut Vec<String>,
) -> Result<Scene, SceneError> {
    let t = read_transforms(file)?;
    let sources = sources_of(file, &t, true, warnings)?;
    if sources.is_empty() {
        return Err(SceneError::Empty {
            path: file.to_path_buf(),
            reason: if t.frames.is_empty() {
                "\"frames\" is empty".into()
            } else {
                format!("none of the {} frames has an existing image file", t.frames.len())
            },
        });
    }
    let points = match &t.ply_file_path {
        None => None,
        Some(p) => {
            let path = file.parent().unwrap_or(Path::new(".")).join(p);
            if names_a_file(&path) {
                let bytes = crate::file_io::read_bounded(&path, crate::file_io::SCENE_FILE)?;
                Some(ply::parse_point_cloud(&bytes, &path)?)
            } else {
                warnings.push(format!(
                    "{}: ply_file_path: point cloud {} does not exist; loading without points",
                    file.display(),
                    path.display()
                ));
                None
            }
        }
    };
    let views = sort_by_name(views::load_all(sources, options, warnings)?);
    warnings.extend(one_focal_for_mixed_sizes(file, &t, &views));
    let (train, test) = split::split_every(views, options.test_every);
    Ok(Scene {
        name: scene_name(file),
        format: SceneFormat::Transforms,
        source: file.to_path_buf(),
        background: options.background,
        train,
        test,
        points,
        extent: 0.0,
        warnings: Vec::new(),
    })
}
