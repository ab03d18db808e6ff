//! Camera alignment: a view's pose and focal length corrected by gradient descent on the training
//! loss, through [`CameraGradient`], with the billboards frozen.
//!
//! Each Adam step is taken on the camera itself: it turns the current camera by `Δω` about its
//! centre, shifts its view frame by `Δδ` and scales its focal lengths by `exp(Δφ)`
//! ([`Camera::adjusted`]), so the gradient the backward pass gives (at `ω = δ = 0` of the
//! current camera) is exactly the gradient of the step's parameters. The moments are seven
//! values (`ω`, `δ`, `φ`), in three one-row [`AdamGroup`]s with their own step sizes.
//!
//! [`fit_camera`] aligns one camera to its image under a frozen model: it tells how much of a
//! view's error a pose or focal error explains (`examples/fit_cameras.rs` runs it on a trained
//! model's test views; `docs/quality.md` has what it found on beer_colmap).

use super::adam::{AdamGroup, AdamParams};
use crate::camera::Camera;
use crate::loss::ssim::SsimScratch;
use crate::loss::{LossError, TrainingLoss};
use crate::raster::backward::{CameraGradient, ImageGradients};
use crate::raster::{
    ActivatedRef, BackwardScratch, RenderBuffers, RenderGradients, RenderSettings, render_backward_with, render_with,
};
use glam::Vec3;

/// Adam step sizes of a camera correction.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CameraStepSizes {
    /// Rotation `ω`, radians per step.
    pub rotation: f32,
    /// View-frame shift `δ`, world units per step.
    pub translation: f32,
    /// Log focal scale `φ` per step (0 keeps the focal lengths).
    pub focal: f32,
}

impl CameraStepSizes {
    /// All three multiplied by `factor`.
    pub fn scaled(self, factor: f32) -> Self {
        Self {
            rotation: self.rotation * factor,
            translation: self.translation * factor,
            focal: self.focal * factor,
        }
    }
}

/// Adam state of one camera: the turn `ω` (3), the shift `δ` (3) and the log focal scale `φ`
/// (1), each a one-row [`AdamGroup`] with its own step size.
struct CameraAdam {
    turn: AdamGroup,
    shift: AdamGroup,
    focal: AdamGroup,
}

impl CameraAdam {
    fn new() -> Self {
        Self {
            turn: AdamGroup::new(1, 3),
            shift: AdamGroup::new(1, 3),
            focal: AdamGroup::new(1, 1),
        }
    }

    /// `camera` after one Adam step on its gradient `g` (taken at `camera`): the step starts
    /// from zero, so the updated parameters are the step itself, applied by [`Camera::adjusted`]
    /// (`∂L/∂φ = fx·∂L/∂fx + fy·∂L/∂fy`, both focal lengths scaling by `exp(φ)`).
    fn step(&mut self, camera: &Camera, g: &CameraGradient, sizes: &CameraStepSizes) -> Camera {
        let hp = AdamParams::default();
        let d_phi = f64::from(camera.fx) * g.focal.x + f64::from(camera.fy) * g.focal.y;
        let (mut turn, mut shift, mut phi) = ([0.0f32; 3], [0.0f32; 3], [0.0f32]);
        let (g_turn, g_shift) = (g.rotation.as_vec3().to_array(), g.translation.as_vec3().to_array());
        self.turn.step_row(0, &mut turn, &g_turn, sizes.rotation, &hp);
        self.shift.step_row(0, &mut shift, &g_shift, sizes.translation, &hp);
        self.focal.step_row(0, &mut phi, &[d_phi as f32], sizes.focal, &hp);
        camera.adjusted(Vec3::from_array(turn), Vec3::from_array(shift), phi[0].exp())
    }
}

/// What [`fit_camera`] did.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CameraFit {
    /// The aligned camera.
    pub camera: Camera,
    /// Training loss at the given camera.
    pub loss_before: f64,
    /// Training loss at the aligned camera.
    pub loss_after: f64,
}

/// Aligns `camera` to `target` (interleaved RGB in `[0, 1]`, the camera's size) under the frozen
/// billboards `set`: `iterations` Adam steps of the camera on the training loss, the step sizes
/// decaying exponentially from `sizes` to `sizes / 100`. Returns the camera with the lowest loss
/// seen (the given one if no step lowered it), so a fit never makes the loss worse.
///
/// ```
/// use bbsplat::billboards::{RandomSceneConfig, random_scene, random_scene_camera};
/// use bbsplat::raster::{RenderSettings, render};
/// use bbsplat::train::camera_fit::{CameraStepSizes, fit_camera};
/// use glam::Vec3;
/// let scene = random_scene(&RandomSceneConfig {
///     billboards: 40, width: 40, height: 32, texture_size: 8, footprint_px: 12.0,
///     alpha_range: (0.6, 1.0), seed: 1,
/// });
/// let truth = random_scene_camera(40, 32);
/// let settings = RenderSettings::default();
/// let photo = render(&scene.borrowed(), &truth, &settings).rgb;
/// // A camera turned by about half a degree and moved a little.
/// let moved = truth.adjusted(Vec3::new(0.005, 0.0, 0.004), Vec3::new(0.02, 0.0, 0.0), 1.0);
/// let sizes = CameraStepSizes { rotation: 1e-3, translation: 2e-3, focal: 0.0 };
/// let fit = fit_camera(&scene.borrowed(), &moved, &photo, &settings, 60, &sizes).unwrap();
/// assert!(fit.loss_after < 0.2 * fit.loss_before);
/// assert!((fit.camera.centre() - truth.centre()).length() < (moved.centre() - truth.centre()).length());
/// ```
///
/// # Errors
/// [`LossError`] when `target` does not match the camera's size.
pub fn fit_camera(
    set: &ActivatedRef<'_>,
    camera: &Camera,
    target: &[f32],
    settings: &RenderSettings,
    iterations: usize,
    sizes: &CameraStepSizes,
) -> Result<CameraFit, LossError> {
    let (w, h) = (camera.width as usize, camera.height as usize);
    let loss_fn = TrainingLoss {
        simd: settings.simd,
        ..TrainingLoss::default()
    };
    let mut adam = CameraAdam::new();
    let mut grads = RenderGradients::zeros(set.len(), set.texture_size);
    let mut buffers = RenderBuffers::default();
    let (mut ssim_scratch, mut backward_scratch) = (SsimScratch::default(), BackwardScratch::default());
    let mut current = *camera;
    let mut best = (f64::INFINITY, *camera);
    let mut loss_before = f64::NAN;
    for k in 0..=iterations {
        let out = render_with(set, &current, settings, std::mem::take(&mut buffers));
        let loss = loss_fn.evaluate_in(&out.rgb, target, (w, h, 3), &mut ssim_scratch)?;
        if k == 0 {
            loss_before = loss.loss;
        }
        if loss.loss < best.0 {
            best = (loss.loss, current);
        }
        if k == iterations {
            break;
        }
        let ig = ImageGradients {
            rgb: &loss.d_render,
            camera: true,
            ..ImageGradients::default()
        };
        let touched = render_backward_with(set, &out, &ig, &mut grads, &mut backward_scratch);
        for &b in &touched {
            grads.clear_row(b as usize);
        }
        let gradient = std::mem::take(&mut grads.camera);
        grads.background = Vec3::ZERO;
        buffers = out.into_buffers();
        let decay = 0.01f32.powf(k as f32 / iterations.max(1) as f32);
        current = adam.step(&current, &gradient, &sizes.scaled(decay));
    }
    Ok(CameraFit {
        camera: best.1,
        loss_before,
        loss_after: best.0,
    })
}
