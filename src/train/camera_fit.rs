//! Camera alignment: a view's pose and focal length corrected by gradient descent on the training
//! loss, through [`CameraGradient`], with the billboards frozen.
//!
//! Each Adam step is taken on the camera itself: it turns the current camera by `Δω` about its
//! centre, shifts its view frame by `Δδ` and scales its focal lengths by `exp(Δφ)`
//! ([`Camera::adjusted`]), so the gradient the backward pass gives (at `ω = δ = 0` of the
//! current camera) is exactly the gradient of the step's parameters. The moments are seven
//! values per camera (`ω`, `δ`, `φ`), a row of an [`AdamGroup`] with the row's own update count.
//!
//! [`fit_camera`] aligns one camera to its image under a frozen model: it tells how much of a
//! view's error a pose or focal error explains (`examples/fit_cameras.rs` runs it on a trained
//! model's test views; `docs/quality.md` has what it found on beer_colmap).

use super::adam::{AdamGroup, AdamParams, update_row};
use crate::camera::Camera;
use crate::loss::{LossError, TrainingLoss};
use crate::raster::backward::{CameraGradient, ImageGradients};
use crate::raster::{ActivatedRef, RenderBuffers, RenderGradients, RenderSettings, render_backward, render_with};
use glam::Vec3;

/// Values per camera row of the optimiser: `ω` (3), `δ` (3), `φ` (1).
pub const CAMERA_ROW: usize = 7;

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

/// The gradient of a camera row, `[ω, δ, φ]`: `∂L/∂φ = fx·∂L/∂fx + fy·∂L/∂fy` (both focal
/// lengths scale by `exp(φ)`).
pub fn row_gradient(camera: &Camera, g: &CameraGradient) -> [f32; CAMERA_ROW] {
    let d_phi = f64::from(camera.fx) * g.focal.x + f64::from(camera.fy) * g.focal.y;
    [
        g.rotation.x as f32,
        g.rotation.y as f32,
        g.rotation.z as f32,
        g.translation.x as f32,
        g.translation.y as f32,
        g.translation.z as f32,
        d_phi as f32,
    ]
}

/// One Adam step of camera `row` of `adam` (row length [`CAMERA_ROW`]) from its gradient at
/// `camera`: the step `[ω, δ, φ]` to apply ([`Camera::adjusted`] with `exp(φ)`). The row's own
/// update count drives the bias correction.
pub fn adam_delta(
    camera: &Camera,
    gradient: &CameraGradient,
    adam: &mut AdamGroup,
    row: usize,
    sizes: &CameraStepSizes,
) -> [f32; CAMERA_ROW] {
    assert_eq!(adam.row_len, CAMERA_ROW, "a camera row holds ω, δ and φ");
    let grads = row_gradient(camera, gradient);
    adam.steps[row] = adam.steps[row].saturating_add(1);
    let t = u64::from(adam.steps[row]);
    let hp = AdamParams::default();
    let base = row * CAMERA_ROW;
    // Each part has its own step size; the update starts from zero, so it is the step itself.
    let mut delta = [0.0f32; CAMERA_ROW];
    for (range, lr) in [(0..3, sizes.rotation), (3..6, sizes.translation), (6..7, sizes.focal)] {
        let span = base + range.start..base + range.end;
        update_row(
            &mut adam.m[span.clone()],
            &mut adam.v[span],
            &mut delta[range.clone()],
            &grads[range],
            lr,
            &hp,
            t,
        );
    }
    delta
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
    let loss_fn = TrainingLoss::default();
    let mut adam = AdamGroup::new(1, CAMERA_ROW);
    let mut grads = RenderGradients::zeros(set.len(), set.texture_size);
    let mut buffers = RenderBuffers::default();
    let mut current = *camera;
    let mut best = (f64::INFINITY, *camera);
    let mut loss_before = f64::NAN;
    for k in 0..=iterations {
        let out = render_with(set, &current, settings, std::mem::take(&mut buffers));
        let loss = loss_fn.evaluate(&out.rgb, target, w, h, 3)?;
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
        let touched = render_backward(set, &out, &ig, &mut grads);
        for &b in &touched {
            grads.clear_row(b as usize);
        }
        let gradient = std::mem::take(&mut grads.camera);
        grads.background = Vec3::ZERO;
        buffers = out.into_buffers();
        let decay = 0.01f32.powf(k as f32 / iterations.max(1) as f32);
        let [wx, wy, wz, dx, dy, dz, phi] = adam_delta(&current, &gradient, &mut adam, 0, &sizes.scaled(decay));
        current = current.adjusted(Vec3::new(wx, wy, wz), Vec3::new(dx, dy, dz), phi.exp());
    }
    Ok(CameraFit {
        camera: best.1,
        loss_before,
        loss_after: best.0,
    })
}
