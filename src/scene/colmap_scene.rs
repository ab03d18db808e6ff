//! Building a [`Scene`] from a COLMAP model folder and its image folder.

use super::colmap::{self, model_kind};
use super::error::{Location, SceneError};
use super::views::{self, CameraSpec, ViewSource};
use super::{LoadOptions, PointCloud, Scene, SceneFormat, registration, split, unfold};
use glam::{Mat3, Vec3};
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// Finds the COLMAP model under `path`: `path` itself, `path/sparse`, or the subfolder of
/// `path/sparse` with the most registered images (ties: first in name order).
pub(crate) fn find_model(path: &Path) -> Result<Option<PathBuf>, SceneError> {
    if model_kind(path).is_some() {
        return Ok(Some(path.to_path_buf()));
    }
    let sparse = path.join("sparse");
    if model_kind(&sparse).is_some() {
        return Ok(Some(sparse));
    }
    let Ok(entries) = std::fs::read_dir(&sparse) else {
        return Ok(None);
    };
    let mut dirs: Vec<PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_dir() && model_kind(p).is_some())
        .collect();
    dirs.sort();
    let mut best: Option<(usize, PathBuf)> = None;
    for d in dirs {
        let n = colmap::read_images(&d)?.len();
        if best.as_ref().is_none_or(|(m, _)| n > *m) {
            best = Some((n, d));
        }
    }
    Ok(best.map(|(_, d)| d))
}

/// The image folder for a model folder: `images` beside `sparse` (for `X/sparse/N` and
/// `X/sparse`), else `images` in or beside the model folder.
fn find_images_dir(model_dir: &Path) -> Result<PathBuf, SceneError> {
    let mut candidates = Vec::new();
    let name = |p: &Path| p.file_name().and_then(|n| n.to_str()).map(str::to_owned);
    if let Some(parent) = model_dir.parent() {
        if name(parent).as_deref() == Some("sparse")
            && let Some(root) = parent.parent()
        {
            candidates.push(root.join("images"));
        }
        candidates.push(parent.join("images"));
    }
    candidates.push(model_dir.join("images"));
    for c in &candidates {
        if c.is_dir() {
            return Ok(c.clone());
        }
    }
    Err(SceneError::NotDetected {
        path: model_dir.to_path_buf(),
        looked_for: format!(
            "no image folder for this COLMAP model (looked for {}); set LoadOptions::images_dir",
            candidates
                .iter()
                .map(|c| c.display().to_string())
                .collect::<Vec<_>>()
                .join(", ")
        ),
    })
}

/// The dataset's root folder (for the scene name): the folder holding `sparse/`.
fn root_of(model_dir: &Path) -> PathBuf {
    let is_sparse = |p: &Path| p.file_name().and_then(|n| n.to_str()) == Some("sparse");
    match model_dir.parent() {
        Some(parent) if is_sparse(model_dir) => parent.to_path_buf(),
        Some(parent) if is_sparse(parent) => parent.parent().unwrap_or(parent).to_path_buf(),
        _ => model_dir.to_path_buf(),
    }
}

pub(crate) fn load(model_dir: &Path, options: &LoadOptions, warnings: &mut Vec<String>) -> Result<Scene, SceneError> {
    let model = colmap::read_model(model_dir)?;
    let binary = model_kind(model_dir) == Some(true);
    let images_file = model_dir.join(if binary { "images.bin" } else { "images.txt" });
    if model.images.is_empty() {
        return Err(SceneError::Empty {
            path: images_file,
            reason: "the model has no registered images".into(),
        });
    }
    let images_dir = match &options.images_dir {
        Some(d) => d.clone(),
        None => find_images_dir(model_dir)?,
    };
    // Implausible intrinsics are refused here, before the lens distortion is inverted (which
    // would otherwise blame them on the distortion). The parsers accept them: they read files.
    let cameras_file = model_dir.join(if binary { "cameras.bin" } else { "cameras.txt" });
    for (i, cam) in model.cameras.iter().enumerate() {
        let (w, h) = (
            cam.width.min(u32::MAX as u64) as u32,
            cam.height.min(u32::MAX as u64) as u32,
        );
        if let Some(problem) = cam.intrinsics().implausibility(w, h) {
            let location = Location::Record(format!("camera {i} (camera_id {})", cam.id));
            return Err(SceneError::parse(&cameras_file, location, problem));
        }
    }
    let cameras: HashMap<u32, (usize, &colmap::ColmapCamera)> =
        model.cameras.iter().enumerate().map(|(i, c)| (c.id, (i, c))).collect();
    let mut seen_names: HashMap<&str, usize> = HashMap::new();
    let mut sources = Vec::with_capacity(model.images.len());
    for (i, im) in model.images.iter().enumerate() {
        let location = Location::Record(format!("image {i} (image_id {}, {:?})", im.id, im.name));
        if let Some(j) = seen_names.insert(&im.name, i) {
            return Err(SceneError::parse(
                &images_file,
                location,
                format!("image name {:?} is also used by image {j}", im.name),
            ));
        }
        if Path::new(&im.name).is_absolute() {
            return Err(SceneError::parse(
                &images_file,
                location,
                "image name is an absolute path; names must be relative to the image folder",
            ));
        }
        // `check_references` guarantees the camera exists.
        let Some(&(ci, cam)) = cameras.get(&im.camera_id) else {
            return Err(SceneError::parse(&images_file, location, "camera_id not found"));
        };
        let r = im.rotation();
        let rotation = Mat3::from_cols_array_2d(&r.map(|row| row.map(|v| v as f32))).transpose();
        let translation = Vec3::new(im.tvec[0] as f32, im.tvec[1] as f32, im.tvec[2] as f32);
        if !rotation.is_finite() || !translation.is_finite() {
            return Err(SceneError::parse(
                &images_file,
                location,
                "pose overflows single precision",
            ));
        }
        let location = Location::Record(format!(
            "image {i} (image_id {}, {:?}) with camera {ci} (camera_id {})",
            im.id, im.name, cam.id
        ));
        sources.push(ViewSource {
            name: im.name.clone(),
            image_path: images_dir.join(&im.name),
            file: images_file.clone(),
            location,
            camera: CameraSpec::Known {
                intrinsics: cam.intrinsics(),
                width: cam.width,
                height: cam.height,
            },
            rotation,
            translation,
            mask: None,
        });
    }
    sources.sort_by(|a, b| a.name.cmp(&b.name));
    let mut views = views::load_all(sources, options, warnings)?;
    let unfolding = unfold_views(&mut views, options.unfold, &images_file, warnings);
    // The frame (capture-order index) of each image id, for the points' tracks.
    let frame_of: HashMap<u32, usize> = {
        let index: HashMap<&str, usize> = views.iter().enumerate().map(|(i, v)| (v.name.as_str(), i)).collect();
        model
            .images
            .iter()
            .filter_map(|im| index.get(im.name.as_str()).map(|&i| (im.id, i)))
            .collect()
    };
    let (train, test) = split::split_every(views, options.test_every);
    // SfM points: with an unfolded registration, those seen by one pass turn with it and those
    // seen by several (joining folded halves) are dropped.
    let mut positions = Vec::with_capacity(model.points.len());
    let mut colours = Vec::with_capacity(model.points.len());
    for (i, p) in model.points.iter().enumerate() {
        let mut xyz = glam::DVec3::from_array(p.xyz);
        if let Some((u, _)) = &unfolding {
            let mut passes = p
                .track
                .iter()
                .filter_map(|t| frame_of.get(&t.image_id))
                .map(|&f| u.pass_of(f));
            let Some(pass) = passes.next() else { continue };
            if passes.any(|q| q != pass) {
                continue;
            }
            xyz = u.point(pass, xyz);
        }
        let position = xyz.as_vec3();
        if !position.is_finite() {
            return Err(SceneError::parse(
                &model_dir.join(if binary { "points3D.bin" } else { "points3D.txt" }),
                Location::Record(format!("point {i} (point3D_id {})", p.id)),
                "position overflows single precision",
            ));
        }
        positions.push(position);
        colours.push(p.rgb.map(|c| c as f32 / 255.0));
    }
    if let Some((_, unfolded)) = &unfolding {
        warnings.push(format!(
            "{}: {unfolded}; {} of {} SfM points kept (those seen by one pass). --keep-folded keeps \
             the registration as given (docs/scene.md, \"Folded registrations\")",
            images_file.display(),
            positions.len(),
            model.points.len()
        ));
    }
    let points = PointCloud { positions, colours };
    let root = root_of(model_dir);
    Ok(Scene {
        name: root.file_name().and_then(|n| n.to_str()).unwrap_or("scene").to_string(),
        format: SceneFormat::Colmap,
        source: model_dir.to_path_buf(),
        background: options.background,
        train,
        test,
        points: Some(points),
        extent: 0.0,
        warnings: Vec::new(),
    })
}

/// Turns back the passes of a folded registration of `views` (capture order) when `unfold` is
/// on and [`unfold::plan`] explains the sharp turns as folds, and returns the plan with what it
/// did in words; otherwise warns about the sharp turns, if any
/// ([`registration::folded_registration_warning`]).
fn unfold_views(
    views: &mut [super::View],
    unfold: bool,
    images_file: &Path,
    warnings: &mut Vec<String>,
) -> Option<(unfold::Unfolding, String)> {
    let poses: Vec<unfold::Pose> = views
        .iter()
        .map(|v| unfold::Pose {
            rotation: v.camera.rotation.as_dmat3(),
            centre: v.camera.centre_f64(),
        })
        .collect();
    let plan = unfold.then(|| unfold::plan(&poses));
    let Some(unfold::Plan::Unfold(u)) = plan else {
        let names: Vec<&str> = views.iter().map(|v| v.name.as_str()).collect();
        let cameras: Vec<_> = views.iter().map(|v| v.camera).collect();
        if let Some(w) = registration::folded_registration_warning(&names, &cameras) {
            let why = match plan {
                Some(unfold::Plan::NotFolds(reason)) => format!("not turned back: {reason}"),
                _ => "not turned back: kept as given (--keep-folded)".to_string(),
            };
            warnings.push(format!("{}: {w}; {why}", images_file.display()));
        }
        return None;
    };
    for (i, v) in views.iter_mut().enumerate() {
        let p = u.pose(i, &poses[i]);
        v.camera.rotation = p.rotation.as_mat3();
        v.camera.translation = (-(p.rotation * p.centre)).as_vec3();
    }
    let name = |i: usize| views[i].name.as_str();
    let passes: Vec<String> = u.passes[1..]
        .iter()
        .zip(&u.turns[1..])
        .map(|(p, t)| format!("{}-{} by {:.1} deg", name(p.start), name(p.end - 1), t.to_degrees()))
        .collect();
    let worst_turn = u.boundaries.iter().map(|b| b.residual_turn_deg).fold(0.0, f64::max);
    let worst_steps = u.boundaries.iter().map(|b| b.residual_steps).fold(0.0, f64::max);
    let folds: Vec<String> = u.boundaries.iter().map(|b| format!("{:.0}", b.fold_deg)).collect();
    let report = format!(
        "the registration folds an orbit video onto itself ({} passes; where they meet, \
         consecutive frames are registered turned by {} deg about one axis), so it is turned \
         back: frames {} about the axis ({:.3}, {:.3}, {:.3}) through ({:.3}, {:.3}, {:.3}); each \
         pass then starts within {worst_turn:.1} deg and {worst_steps:.1} frame steps of where the \
         previous one leads",
        u.passes.len(),
        folds.join(", "),
        passes.join(", "),
        u.axis.x,
        u.axis.y,
        u.axis.z,
        u.pivot.x,
        u.pivot.y,
        u.pivot.z,
    );
    Some((u, report))
}
