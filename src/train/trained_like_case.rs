//! A training case on a trained-like object scene ([`crate::billboards::trained_like`]): the
//! scene as the model to train, one view whose target is the render of the same preset with
//! another seed (so the loss and every gradient are far from zero, as early in a run), and a
//! config. What the step benches (`benches/train_step.rs`, `step/trained/…`) and the cost model
//! (`examples/cost_model.rs`) time.

use super::{TrainConfig, TrainView};
use crate::billboards::{TrainedLikeConfig, random_scene_camera, trained_like_scene};
use crate::model::RawBillboards;
use crate::raster::{RenderSettings, render};
use glam::Vec3;

/// The model, its one view (`size × size`) and a config (SH degree 3, white background, seed
/// 0, `iterations` 0 for the caller to set; the world extent is the object's distance from the
/// camera) of [`TrainedLikeConfig::object`] with `billboards` billboards.
pub fn trained_like_case(size: u32, billboards: usize) -> (RawBillboards, Vec<TrainView>, TrainConfig) {
    let config = TrainedLikeConfig::object(billboards, size, size);
    let target = {
        let target_scene = trained_like_scene(&TrainedLikeConfig { seed: 1, ..config });
        let settings = RenderSettings {
            background: Vec3::ONE,
            ..RenderSettings::default()
        };
        render(&target_scene.borrowed(), &random_scene_camera(size, size), &settings).rgb
    };
    let views = vec![TrainView {
        camera: random_scene_camera(size, size),
        rgb: target.iter().map(|v| v.clamp(0.0, 1.0)).collect::<Vec<f32>>().into(),
        loss_mask: None,
    }];
    let train_config = TrainConfig {
        iterations: 0,
        sh_degree: 3,
        background: Vec3::ONE,
        seed: 0,
        extent: crate::billboards::trained_like::OBJECT_DEPTH,
        ..TrainConfig::default()
    };
    let model = RawBillboards::from_activated(&trained_like_scene(&config));
    (model, views, train_config)
}
