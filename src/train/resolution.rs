//! Coarse-to-fine training: the first part of a run on downscaled images.
//!
//! A step's cost is set by the pixels it renders (forward, loss, backward), so a step on images
//! downscaled by 2 costs about a quarter. Early in a run the model is far from the images and the
//! coarse images carry most of what it has to learn (positions, sizes, base colours); the fine
//! detail (textures) is learned after the switch. This is not part of the reference, which
//! trains at one resolution throughout; it is off by default ([`ResolutionSchedule::OFF`]).
//!
//! The phase depends on the step index only, so a resumed run switches at the same step, and
//! the result does not depend on the thread count. The views of both phases are the same list in
//! the same order (the trainer's shuffled stack indexes them).

use super::{TrainView, ViewPixels};
use crate::scene::SceneError;
use crate::scene::image_io::{resize_area, resize_area_u8};

/// Which resolution step `s` of a run trains at.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ResolutionSchedule {
    /// Downscale factor of the coarse phase (1: no coarse phase).
    pub factor: u32,
    /// Fraction of the run spent in the coarse phase, in `[0, 1]`.
    pub until: f64,
}

impl ResolutionSchedule {
    /// One resolution throughout.
    pub const OFF: ResolutionSchedule = ResolutionSchedule { factor: 1, until: 0.0 };

    /// True when step `step` (0-based) of a run of `iterations` steps trains on the coarse
    /// images: `factor > 1` and `step < ⌈until · iterations⌉`.
    ///
    /// ```
    /// use bbsplat::train::resolution::ResolutionSchedule;
    /// let s = ResolutionSchedule { factor: 2, until: 0.25 };
    /// assert!(s.is_coarse(0, 1000) && s.is_coarse(249, 1000) && !s.is_coarse(250, 1000));
    /// assert!(!ResolutionSchedule::OFF.is_coarse(0, 1000));
    /// ```
    pub fn is_coarse(&self, step: usize, iterations: usize) -> bool {
        self.factor > 1 && (step as f64) < (self.until.clamp(0.0, 1.0) * iterations as f64).ceil()
    }
}

/// `view` downscaled by `factor`: the image area-averaged to `round(size / factor)` pixels per
/// side (at least 1), the camera scaled by the exact size ratio ([`crate::camera::Camera::scaled`]),
/// so the image edges stay where they were. An on-demand view ([`ViewPixels::OnDemand`]) stays
/// on demand, downscaled when it is decoded.
///
/// # Errors
/// Only for an on-demand view downscaled already (it is decoded now, and its file no longer
/// gives its pixels).
///
/// ```
/// use bbsplat::camera::Camera;
/// use bbsplat::train::TrainView;
/// use bbsplat::train::resolution::downscale_view;
/// use glam::Vec3;
/// let camera = Camera::look_at(Vec3::new(0.0, 0.0, -3.0), Vec3::ZERO, Vec3::Y, 40.0, 40.0, 4, 2);
/// let rgb: Vec<f32> = (0..4 * 2 * 3).map(|k| (k / 3) as f32).collect();
/// let small = downscale_view(&TrainView { camera, rgb: rgb.into(), loss_mask: None }, 2).unwrap();
/// assert_eq!((small.camera.width, small.camera.height, small.camera.fx), (2, 1, 20.0));
/// // Each output pixel is the mean of a 2×2 block: pixels (0, 1, 4, 5) → 2.5.
/// assert_eq!(&small.rgb.to_f32().unwrap()[..3], &[2.5, 2.5, 2.5]);
/// ```
pub fn downscale_view(view: &TrainView, factor: u32) -> Result<TrainView, SceneError> {
    if factor <= 1 {
        return Ok(view.clone());
    }
    let camera = view.camera.scaled(1.0 / factor as f32);
    if let ViewPixels::OnDemand(p) = &view.rgb
        && p.size() == (p.image().width(), p.image().height())
    {
        return Ok(TrainView {
            camera,
            rgb: ViewPixels::OnDemand(p.downscaled(camera.width, camera.height)),
            loss_mask: downscale_mask(view, &camera),
        });
    }
    let (w, h) = (view.camera.width as usize, view.camera.height as usize);
    let rgb = resize_area(&view.rgb.to_f32()?, w, h, camera.width as usize, camera.height as usize);
    Ok(TrainView {
        camera,
        rgb: rgb.into(),
        loss_mask: downscale_mask(view, &camera),
    })
}

/// The view's loss mask averaged over the same blocks as its pixels (`camera`: the downscaled
/// camera), rounded to 8 bits.
fn downscale_mask(view: &TrainView, camera: &crate::camera::Camera) -> Option<Vec<u8>> {
    let mask = view.loss_mask.as_ref()?;
    let (w, h) = (view.camera.width as usize, view.camera.height as usize);
    Some(resize_area_u8(
        mask,
        w,
        h,
        camera.width as usize,
        camera.height as usize,
    ))
}
