//! The two 2DGS geometry regularisers as training options (spec §5.2-§5.3): normal consistency
//! ([`crate::loss::normal_consistency`]) and depth distortion ([`crate::loss::distortion`],
//! map: [`crate::stages::depth_distortion`]). Both are off by default (weights 0, as in the
//! reference); a step with both off renders and back-propagates exactly as without them.
//!
//! Each starts at a fraction of the run ([`GeometryRegularisers::normal_from`],
//! [`GeometryRegularisers::distortion_from`]): the reference starts them after iterations 7000
//! and 3000 of its 32 000; a run planned by a time budget uses the fraction of its planned steps
//! (re-planned as the budget is), like every other milestone.
//!
//! ```
//! use bbsplat::train::geometry::GeometryRegularisers;
//! let off = GeometryRegularisers::default();
//! assert!(!off.normal_active(20_000, 32_000) && !off.distortion_active(20_000, 32_000));
//! let on = GeometryRegularisers { lambda_normal: 0.05, lambda_distortion: 100.0, ..off };
//! assert!(!on.normal_active(6_999, 32_000) && on.normal_active(7_000, 32_000));
//! assert!(!on.distortion_active(2_999, 32_000) && on.distortion_active(3_000, 32_000));
//! ```

use crate::camera::Camera;
use crate::loss::distortion::distortion_loss;
use crate::loss::normal_consistency::normal_consistency;
use crate::raster::RenderOutput;
use crate::raster::backward::ImageGradients;

/// The reference's start of the normal-consistency term: iteration 7000 of 32 000.
pub const NORMAL_FROM: f32 = 7000.0 / 32_000.0;
/// The reference's start of the depth-distortion term: iteration 3000 of 32 000.
pub const DISTORTION_FROM: f32 = 3000.0 / 32_000.0;

/// Weights and start fractions of the geometry regularisers.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GeometryRegularisers {
    /// Weight of the normal-consistency loss (reference `lambda_normal`: default 0, DTU 0.05).
    pub lambda_normal: f32,
    /// Weight of the depth-distortion loss (reference `lambda_dist`: default 0, DTU 100-1000).
    pub lambda_distortion: f32,
    /// Fraction of the run (0-1) after which normal consistency is on ([`NORMAL_FROM`]).
    pub normal_from: f32,
    /// Fraction of the run (0-1) after which depth distortion is on ([`DISTORTION_FROM`]).
    pub distortion_from: f32,
}

impl Default for GeometryRegularisers {
    /// Both off (weights 0), the reference's start fractions.
    fn default() -> Self {
        Self {
            lambda_normal: 0.0,
            lambda_distortion: 0.0,
            normal_from: NORMAL_FROM,
            distortion_from: DISTORTION_FROM,
        }
    }
}

/// True when step `step` (0-based) of a run of `iterations` is at or past `from · iterations`.
fn started(step: usize, iterations: usize, from: f32) -> bool {
    step as f64 >= f64::from(from) * iterations as f64
}

impl GeometryRegularisers {
    /// Normal consistency applies at step `step` (0-based) of a run of `iterations` steps.
    pub fn normal_active(&self, step: usize, iterations: usize) -> bool {
        self.lambda_normal != 0.0 && started(step, iterations, self.normal_from)
    }

    /// Depth distortion applies at step `step` (0-based) of a run of `iterations` steps.
    pub fn distortion_active(&self, step: usize, iterations: usize) -> bool {
        self.lambda_distortion != 0.0 && started(step, iterations, self.distortion_from)
    }

    /// What is out of range, or `None`: weights finite and ≥ 0, fractions in `[0, 1]`.
    pub fn problem(&self) -> Option<String> {
        for (name, w) in [
            ("lambda_normal", self.lambda_normal),
            ("lambda_distortion", self.lambda_distortion),
        ] {
            if !(w.is_finite() && w >= 0.0) {
                return Some(format!("{name} {w} is not a finite number ≥ 0"));
            }
        }
        for (name, f) in [
            ("normal_from", self.normal_from),
            ("distortion_from", self.distortion_from),
        ] {
            if !(0.0..=1.0).contains(&f) {
                return Some(format!("{name} {f} is not a fraction of the run in [0, 1]"));
            }
        }
        None
    }
}

/// The weighted geometry losses of one render and their gradients with respect to its maps.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct GeometryLoss {
    /// `lambda_normal · normal consistency` (0 when off).
    pub normal: f64,
    /// `lambda_distortion · mean distortion` (0 when off).
    pub distortion: f64,
    d_depth: Option<Vec<f32>>,
    d_alpha: Option<Vec<f32>>,
    d_normal: Option<Vec<f32>>,
    d_distortion: Option<Vec<f32>>,
}

impl GeometryLoss {
    /// The losses of `out` (rendered by `camera`) with the given weights (`None`: that term is
    /// off). The render must hold the distortion map when `lambda_distortion` is given
    /// ([`crate::raster::RenderSettings::distortion`]).
    ///
    /// # Panics
    /// When a map does not match the camera (the render was not made by `camera`) or the
    /// distortion map is missing.
    pub fn evaluate(
        out: &RenderOutput,
        camera: &Camera,
        lambda_normal: Option<f32>,
        lambda_distortion: Option<f32>,
    ) -> Self {
        let mut loss = GeometryLoss::default();
        if let Some(lambda) = lambda_normal {
            let nc = normal_consistency(camera, &out.depth, &out.alpha, &out.normal, f64::from(lambda))
                .expect("the render's maps match its camera");
            loss.normal = f64::from(lambda) * nc.value;
            loss.d_depth = Some(nc.d_depth);
            loss.d_alpha = Some(nc.d_alpha);
            loss.d_normal = Some(nc.d_normal);
        }
        if let Some(lambda) = lambda_distortion {
            assert_eq!(
                out.distortion.len(),
                camera.pixel_count(),
                "the render holds its distortion map"
            );
            let (value, grad) =
                distortion_loss(&out.distortion, f64::from(lambda)).expect("the render's maps match its camera");
            loss.distortion = f64::from(lambda) * value;
            loss.d_distortion = Some(grad);
        }
        loss
    }

    /// The upstream gradients of the render's maps: `rgb` plus this loss's gradients (none
    /// when both terms are off, so that the backward pass is the plain one).
    pub fn image_gradients<'a>(&'a self, rgb: &'a [f32]) -> ImageGradients<'a> {
        ImageGradients {
            rgb,
            alpha: self.d_alpha.as_deref(),
            depth: self.d_depth.as_deref(),
            normal: self.d_normal.as_deref(),
            distortion: self.d_distortion.as_deref(),
            camera: false,
        }
    }
}
