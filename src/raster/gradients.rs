//! The gradients of a render's backward pass: what it takes ([`ImageGradients`], the loss's
//! gradients with respect to the images) and what it gives ([`RenderGradients`] per billboard,
//! [`CameraGradient`] for the camera).

use crate::stages::sh::SH_FLOATS;
use crate::stages::splat_transform::CameraGrads;
use glam::{DVec2, DVec3, Vec2, Vec3};

/// Gradients of a scalar loss with respect to every billboard parameter and the background.
///
/// Dense per billboard, laid out like [`ActivatedRef`](super::ActivatedRef). [`render_backward`](super::render_backward) *adds* into it, so
/// several views can be accumulated; rows of billboards that received nothing are untouched.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderGradients {
    /// `∂L/∂position`.
    pub positions: Vec<Vec3>,
    /// `∂L/∂quaternion` (raw, w x y z).
    pub quaternions: Vec<[f32; 4]>,
    /// `∂L/∂log_scales`.
    pub log_scales: Vec<Vec2>,
    /// `∂L/∂SH`, 48 floats per billboard.
    pub sh: Vec<f32>,
    /// `∂L/∂texel`, `[∂r, ∂g, ∂b, ∂alpha]` of the activated texture values, laid out like
    /// [`ActivatedRef::textures`](super::ActivatedRef::textures).
    pub textures: Vec<[f32; 4]>,
    /// `∂L/∂background`.
    pub background: Vec3,
    /// `∂L/∂` the camera of the view (its pose and intrinsics; see [`CameraGradient`]).
    pub camera: CameraGradient,
}

/// Gradients of a loss with respect to a small change of the camera a view was rendered with,
/// summed in f64 over the billboards in index order (so the same for any thread count).
///
/// The parametrisation is [`crate::stages::splat_transform::camera_vjp`]'s:
/// `p_view → (I + [ω]×)·p_view + δ`, i.e. the camera turned by `ω` about its own centre
/// (radians, camera axes) and its view frame shifted by `δ` (camera axes, world units; the
/// centre moves by `−R_cwᵀ·δ`). `translation` includes the SH colours' view directions, which
/// follow the camera centre. [`crate::camera::Camera::adjusted`] applies such a change.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CameraGradient {
    /// `∂L/∂ω`.
    pub rotation: DVec3,
    /// `∂L/∂δ`.
    pub translation: DVec3,
    /// `(∂L/∂fx, ∂L/∂fy)`.
    pub focal: DVec2,
    /// `(∂L/∂cx, ∂L/∂cy)`.
    pub principal: DVec2,
}

impl From<CameraGrads> for CameraGradient {
    fn from(g: CameraGrads) -> Self {
        Self {
            rotation: g.rotation.as_dvec3(),
            translation: g.translation.as_dvec3(),
            focal: g.focal.as_dvec2(),
            principal: g.principal.as_dvec2(),
        }
    }
}

impl std::ops::AddAssign for CameraGradient {
    fn add_assign(&mut self, g: Self) {
        self.rotation += g.rotation;
        self.translation += g.translation;
        self.focal += g.focal;
        self.principal += g.principal;
    }
}

impl RenderGradients {
    /// All-zero gradients for `n` billboards with textures of side `texture_size`.
    pub fn zeros(n: usize, texture_size: usize) -> Self {
        let t = texture_size * texture_size;
        Self {
            positions: vec![Vec3::ZERO; n],
            quaternions: vec![[0.0; 4]; n],
            log_scales: vec![Vec2::ZERO; n],
            sh: vec![0.0; n * SH_FLOATS],
            textures: crate::memory::filled(n * t, [0.0; 4]),
            background: Vec3::ZERO,
            camera: CameraGradient::default(),
        }
    }

    /// Zeroes every gradient of billboard `b` (not the background): after an optimiser has
    /// consumed the rows [`render_backward`](super::render_backward) reported, clearing just those keeps the buffers
    /// ready for the next accumulation without touching the whole set.
    pub fn clear_row(&mut self, b: usize) {
        let t = self.textures.len() / self.positions.len().max(1);
        self.positions[b] = Vec3::ZERO;
        self.quaternions[b] = [0.0; 4];
        self.log_scales[b] = Vec2::ZERO;
        self.sh[b * SH_FLOATS..(b + 1) * SH_FLOATS].fill(0.0);
        self.textures[b * t..(b + 1) * t].fill([0.0; 4]);
    }
}

/// Upstream gradients of the loss with respect to the render's images.
///
/// With [`ImageGradients::normal`] and [`ImageGradients::distortion`] both `None` the backward
/// pass does exactly the work (and gives exactly the bits) it did before they existed.
#[derive(Clone, Copy, Debug, Default)]
pub struct ImageGradients<'a> {
    /// `∂L/∂rgb`, interleaved like [`RenderOutput::rgb`](super::RenderOutput::rgb).
    pub rgb: &'a [f32],
    /// `∂L/∂alpha` per pixel, if the loss uses the opacity map.
    pub alpha: Option<&'a [f32]>,
    /// `∂L/∂depth` per pixel (of the alpha-weighted depth map), if the loss uses it.
    pub depth: Option<&'a [f32]>,
    /// `∂L/∂normal` per pixel, interleaved xyz like [`RenderOutput::normal`](super::RenderOutput::normal) (the alpha-weighted
    /// view-space normal map), if the loss uses it. Reaches the alphas (hence the textures and,
    /// through `(u, v)`, the geometry) and each billboard's rotation through its facing normal
    /// (the flip to face the camera is a constant sign).
    pub normal: Option<&'a [f32]>,
    /// `∂L/∂distortion` per pixel ([`RenderOutput::distortion`](super::RenderOutput::distortion)), if the loss uses it. The
    /// render need not have computed the map: the backward pass rebuilds what it needs.
    pub distortion: Option<&'a [f32]>,
    /// Also compute [`RenderGradients::camera`] (a few hundred instructions per billboard that
    /// received a gradient, about 10 % of a backward pass of many small billboards); left at
    /// zero when false.
    pub camera: bool,
}

impl<'a> ImageGradients<'a> {
    /// The gradient of a loss on the colour image alone (`rgb`, no other map, no camera
    /// gradient), as the photometric loss gives it.
    pub fn colour(rgb: &'a [f32]) -> Self {
        ImageGradients {
            rgb,
            alpha: None,
            depth: None,
            normal: None,
            distortion: None,
            camera: false,
        }
    }

    /// True when a gradient of the normal or distortion map is given (the backward pass then
    /// carries four more channels per entry).
    #[inline]
    pub(super) fn has_aux(&self) -> bool {
        self.normal.is_some() || self.distortion.is_some()
    }
}
