//! The street layout: copies of one scene side by side, each with the views that look across the
//! row of copies, so that a view sees its own copy only. A scene of `copies × n` billboards whose
//! every view keeps about what a view of one copy keeps: how lazy Adam's cost ([`super::lazy_adam`])
//! is measured (`benches/train_step.rs`, `street/…`) and tested (`tests/suite/train_lazy_adam.rs`).

use super::TrainView;
use crate::model::RawBillboards;
use crate::raster::preprocess::kept_rows_into;
use glam::Vec3;

/// `copies` copies of `model` `spacing` apart along +x, and of each view of `views` whose camera
/// centre is within `across` of the x = 0 plane (those that look across the street), moved with
/// its copy (same image). Copy `c` is rows `c·n..(c+1)·n`.
pub fn street(
    model: &RawBillboards,
    views: &[TrainView],
    copies: usize,
    spacing: f32,
    across: f32,
) -> (RawBillboards, Vec<TrainView>) {
    let mut all = model.clone();
    let mut street_views = Vec::new();
    for c in 0..copies {
        let d = Vec3::new(spacing * c as f32, 0.0, 0.0);
        if c > 0 {
            let mut copy = model.clone();
            copy.positions.iter_mut().for_each(|p| *p += d);
            super::grow::append_rows(&mut all, &copy);
        }
        for v in views.iter().filter(|v| v.camera.centre().x.abs() < across) {
            let mut camera = v.camera;
            // World-to-camera `R(x − d) + t`: the camera moved by `d`.
            camera.translation -= camera.rotation * d;
            street_views.push(TrainView {
                camera,
                rgb: v.rgb.clone(),
                loss_mask: None,
            });
        }
    }
    (all, street_views)
}

/// The share of `model`'s billboards a view of `views` keeps ([`kept_rows_into`]), averaged over
/// the views.
pub fn kept_share(model: &RawBillboards, views: &[TrainView]) -> f64 {
    let set = model.activate();
    let mut kept = Vec::new();
    let total: usize = views
        .iter()
        .map(|v| {
            kept_rows_into(&set.borrowed(), &v.camera, &mut kept);
            kept.iter().filter(|&&k| k).count()
        })
        .sum();
    total as f64 / (views.len() * model.len()).max(1) as f64
}
