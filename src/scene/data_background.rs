//! The background a dataset implies when the user names none.
//!
//! Rule (the benchmark convention): a NeRF-synthetic dataset whose images carry an alpha channel
//! is composited on **white**, as published NeRF-synthetic figures are; every other dataset on
//! **black** (the reference's default without `--white_background`). The choice is made from the
//! data: the scene is loaded once with white when its format is NeRF-synthetic, and if no view
//! turned out to have an alpha channel the background is set back to black (images without
//! alpha do not depend on the background, so nothing needs reloading).
//!
//! The chosen background is what training composites behind the billboards and what
//! [`crate::model_file::ModelMeta::background`] records, so `render` and `eval` reuse it.

use super::{Background, LoadOptions, Scene, SceneError, SceneFormat, detect, load};
use std::path::Path;

/// A background and why it was chosen.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct BackgroundChoice {
    /// The background.
    pub background: Background,
    /// The rule that chose it, for logs and the run summary.
    pub reason: String,
}

/// The background to try first for `format`: white for NeRF-synthetic, black otherwise.
pub fn tentative_background(format: SceneFormat) -> Background {
    match format {
        SceneFormat::NerfSynthetic => Background::White,
        SceneFormat::Colmap | SceneFormat::Transforms | SceneFormat::Neus | SceneFormat::Llff => Background::Black,
    }
}

/// The background of a scene loaded with [`tentative_background`] (module rule): white only when
/// it is NeRF-synthetic and at least one view has an alpha channel.
pub fn settle_background(scene: &Scene) -> BackgroundChoice {
    let has_alpha = scene.train.iter().chain(&scene.test).any(|v| v.coverage.is_some());
    match (scene.format, has_alpha) {
        (SceneFormat::NerfSynthetic, true) => BackgroundChoice {
            background: Background::White,
            reason: "white: NeRF-synthetic images with alpha, composited on white as the benchmark does".into(),
        },
        (SceneFormat::NerfSynthetic, false) => BackgroundChoice {
            background: Background::Black,
            reason: "black: NeRF-synthetic images without alpha (the reference's default)".into(),
        },
        (format, _) => BackgroundChoice {
            background: Background::Black,
            reason: format!("black: {format} dataset (the reference's default)"),
        },
    }
}

/// Loads `path` with the background of the data (module rule), whatever
/// [`LoadOptions::background`] says; returns the scene (its [`Scene::background`] set to the
/// choice) and the choice.
///
/// # Errors
/// As [`load`].
pub fn load_with_data_background(path: &Path, options: &LoadOptions) -> Result<(Scene, BackgroundChoice), SceneError> {
    let (format, _) = detect(path, options.format)?;
    let options = LoadOptions {
        background: tentative_background(format),
        ..options.clone()
    };
    let mut scene = load(path, &options)?;
    let choice = settle_background(&scene);
    scene.background = choice.background;
    Ok((scene, choice))
}
