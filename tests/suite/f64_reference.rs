//! An independent float64 reference renderer and the crate's rasterizer checked against it:
//! forward images on random scenes and named hard cases, analytic gradients under the training
//! settings against central differences of the f64 renderer (away from every discontinuity, with
//! the margin asserted), the one-sided derivative the backward returns at each discontinuity,
//! and the float32 threshold effects measured. See `docs/numerics-raster.md`, section
//! "Independent float64 reference".

mod discontinuities;
mod float32_effects;
mod forward;
mod gradients;
pub mod renderer;
mod scenes;

use bbsplat::billboards::ActivatedBillboards;
use bbsplat::camera::Camera;
use bbsplat::raster::{RenderOutput, RenderSettings, render};
use renderer::{Cam64, Image64, Scene64, Thresholds, render64};

/// Relative L2 error `‖got − want‖ / ‖want‖` (f64).
fn rel_l2(got: &[f32], want: &[f64]) -> f64 {
    assert_eq!(got.len(), want.len());
    let num: f64 = got.iter().zip(want).map(|(&g, &w)| (g as f64 - w).powi(2)).sum();
    let den: f64 = want.iter().map(|w| w * w).sum();
    assert!(den > 0.0, "the reference image is empty: the case tests nothing");
    (num / den).sqrt()
}

/// Per-image relative L2 errors of the crate's render against the f64 reference: rgb, alpha,
/// depth.
#[derive(Clone, Copy, Debug)]
struct ImageErrors {
    rgb: f64,
    alpha: f64,
    depth: f64,
}

impl ImageErrors {
    fn max(&self) -> f64 {
        self.rgb.max(self.alpha).max(self.depth)
    }
}

fn image_errors(got: &RenderOutput, want: &Image64) -> ImageErrors {
    ImageErrors {
        rgb: rel_l2(&got.rgb, &want.rgb),
        alpha: rel_l2(&got.alpha, &want.alpha),
        depth: rel_l2(&got.depth, &want.depth),
    }
}

/// The crate's render and the f64 reference (crate thresholds) of the same inputs.
fn both(b: &ActivatedBillboards, cam: &Camera, settings: &RenderSettings) -> (RenderOutput, Image64) {
    let out = render(&b.borrowed(), cam, settings);
    let th = Thresholds::crate_values(&settings.composite);
    let (img, _) = render64(&Scene64::of(b, settings), &Cam64::of(cam), &th, false);
    (out, img)
}
