//! The 2DGS normal-consistency loss (spec §5.2) and its gradient with respect to the depth,
//! opacity and normal maps of a render.
//!
//! With the rasterizer's maps ([`crate::raster::RenderOutput`]) `D = Σ α·T·z` (depth), `A =
//! Σ α·T` (alpha) and `N = Σ α·T·n` (the alpha-weighted normal, facing the camera, **view
//! space**):
//! 1. expected depth `e = D / A`, set to 0 where the quotient is not finite (`A = 0`: the
//!    reference's `nan_to_num`; no gradient there) — [`expected_depth`];
//! 2. back-projected surface points `P = e · r` with `r` the pixel's view ray of z = 1 through
//!    the pixel centre ([`crate::stages::ray_plane::pixel_ray`]; the reference uses the
//!    integer pixel corner, a half-pixel shift that moves the normals by a fraction of a
//!    degree), so `P` is the view-space point at view depth `e`;
//! 3. surface normals by central differences on interior pixels only (1 ≤ column ≤ W − 2,
//!    1 ≤ row ≤ H − 2): `a = P(row + 1) − P(row − 1)`, `b = P(column + 1) − P(column − 1)`,
//!    `n_s = (a × b) / max(|a × b|, 1e-12)` (facing the camera for a visible surface, as the
//!    rendered normals); 0 on the border rows and columns — [`surface_normals`];
//! 4. `L = mean over all pixels of (1 − N · (n_s · A_detached))`: border pixels contribute 1.
//!
//! Frames: the reference rotates both normals to world space; a dot product of two vectors is
//! the same in any frame, and the central differences of back-projected points commute with the
//! rigid camera transform, so view space gives the same loss. **Detached**: only the alpha that
//! multiplies `n_s` (step 4); the alpha in `e = D/A` is differentiated, as in the reference.
//!
//! Everything is computed in f64 from the f32 maps (the gradients are rounded once to f32), in
//! a fixed order (deterministic for any thread count).
//!
//! ```
//! use bbsplat::camera::Camera;
//! use bbsplat::loss::normal_consistency::normal_consistency;
//! // A fronto-parallel plane at depth 2, fully opaque, rendered with the normal (0, 0, -1):
//! // the surface normals agree with it, so only the border pixels cost 1 each.
//! let cam = Camera::identity(8, 6);
//! let n = 8 * 6;
//! let depth = vec![2.0f32; n];
//! let alpha = vec![1.0f32; n];
//! let normal: Vec<f32> = (0..n).flat_map(|_| [0.0, 0.0, -1.0]).collect();
//! let out = normal_consistency(&cam, &depth, &alpha, &normal, 1.0).unwrap();
//! let border = (n - 6 * 4) as f64;
//! assert!((out.value - border / n as f64).abs() < 1e-12);
//! ```

use super::{LossError, chunked_sum};
use crate::camera::Camera;
use crate::stages::ray_plane::pixel_ray;
use glam::DVec3;
use rayon::prelude::*;

/// The `eps` of the normalisation `x / max(|x|, eps)` (PyTorch's `F.normalize` default).
pub const NORMALISE_EPS: f64 = 1e-12;

/// The loss value and its gradients.
#[derive(Clone, Debug, PartialEq)]
pub struct NormalConsistency {
    /// `mean(1 − N·n_s·A)` (not multiplied by the upstream gradient).
    pub value: f64,
    /// `d_loss · ∂L/∂D`, one per pixel.
    pub d_depth: Vec<f32>,
    /// `d_loss · ∂L/∂A`, one per pixel (through `e = D/A` only).
    pub d_alpha: Vec<f32>,
    /// `d_loss · ∂L/∂N`, interleaved xyz.
    pub d_normal: Vec<f32>,
}

/// The expected depth `D/A` per pixel in f64, 0 where the quotient is not finite.
pub fn expected_depth(depth: &[f32], alpha: &[f32]) -> Vec<f64> {
    depth
        .iter()
        .zip(alpha)
        .map(|(&d, &a)| {
            let e = f64::from(d) / f64::from(a);
            if e.is_finite() { e } else { 0.0 }
        })
        .collect()
}

/// The view ray (z = 1) through the centre of every pixel, row-major.
fn rays(camera: &Camera) -> Vec<DVec3> {
    let (w, h) = (camera.width, camera.height);
    (0..h)
        .flat_map(|j| (0..w).map(move |i| (i, j)))
        .map(|(i, j)| pixel_ray(camera, i as f32 + 0.5, j as f32 + 0.5).as_dvec3())
        .collect()
}

/// The central differences of interior pixel `(i, j)`: `a` along the rows (down), `b` along
/// the columns (right).
#[inline]
fn differences(points: &[DVec3], w: usize, i: usize, j: usize) -> (DVec3, DVec3) {
    let p = j * w + i;
    (points[p + w] - points[p - w], points[p + 1] - points[p - 1])
}

/// True when pixel `(i, j)` of a `w × h` image has all four neighbours.
#[inline]
fn interior(i: usize, j: usize, w: usize, h: usize) -> bool {
    i >= 1 && j >= 1 && i + 1 < w && j + 1 < h
}

/// Surface normals of the expected-depth map `expected` (one f64 per pixel of `camera`'s
/// image, row-major): step 3 of the module docs, 0 on the border.
///
/// # Panics
/// When `expected` does not hold one value per pixel (a caller's programming error;
/// [`normal_consistency`] checks its inputs).
pub fn surface_normals(camera: &Camera, expected: &[f64]) -> Vec<DVec3> {
    let (w, h) = (camera.width as usize, camera.height as usize);
    assert_eq!(expected.len(), w * h, "one expected depth per pixel");
    let points: Vec<DVec3> = rays(camera).iter().zip(expected).map(|(r, &e)| e * *r).collect();
    let mut normals = vec![DVec3::ZERO; w * h];
    normals.par_chunks_mut(w).enumerate().for_each(|(j, row)| {
        for (i, n) in row.iter_mut().enumerate() {
            if interior(i, j, w, h) {
                let (a, b) = differences(&points, w, i, j);
                let c = a.cross(b);
                *n = c / c.length().max(NORMALISE_EPS);
            }
        }
    });
    normals
}

/// Vector-Jacobian product of [`surface_normals`]: `∂L/∂expected` for the upstream gradient
/// `d_normals` (one vector per pixel; border entries are ignored).
///
/// # Panics
/// As [`surface_normals`], and when `d_normals` does not hold one vector per pixel.
pub fn surface_normals_vjp(camera: &Camera, expected: &[f64], d_normals: &[DVec3]) -> Vec<f64> {
    let (w, h) = (camera.width as usize, camera.height as usize);
    assert_eq!(expected.len(), w * h, "one expected depth per pixel");
    assert_eq!(d_normals.len(), w * h, "one normal gradient per pixel");
    let rays = rays(camera);
    let points: Vec<DVec3> = rays.iter().zip(expected).map(|(r, &e)| e * *r).collect();
    // Per interior pixel: the gradients of its two differences (zero on the border).
    let mut d_diff = vec![(DVec3::ZERO, DVec3::ZERO); w * h];
    d_diff.par_chunks_mut(w).enumerate().for_each(|(j, row)| {
        for (i, d) in row.iter_mut().enumerate() {
            if !interior(i, j, w, h) {
                continue;
            }
            let (a, b) = differences(&points, w, i, j);
            let c = a.cross(b);
            let len = c.length();
            let dn = d_normals[j * w + i];
            // n = c / max(|c|, eps): ∂n/∂c = (I − n nᵀ)/|c| above eps, I/eps below.
            let dc = if len > NORMALISE_EPS {
                let n = c / len;
                (dn - n * n.dot(dn)) / len
            } else {
                dn / NORMALISE_EPS
            };
            // c = a × b: ∂L/∂a = b × ∂L/∂c, ∂L/∂b = ∂L/∂c × a.
            *d = (b.cross(dc), dc.cross(a));
        }
    });
    // Each point enters the differences of its four neighbours: gathered per pixel.
    let mut d_expected = vec![0.0; w * h];
    d_expected.par_chunks_mut(w).enumerate().for_each(|(j, row)| {
        for (i, d) in row.iter_mut().enumerate() {
            let p = j * w + i;
            let mut dp = DVec3::ZERO;
            if j >= 1 {
                dp += d_diff[p - w].0;
            }
            if j + 1 < h {
                dp -= d_diff[p + w].0;
            }
            if i >= 1 {
                dp += d_diff[p - 1].1;
            }
            if i + 1 < w {
                dp -= d_diff[p + 1].1;
            }
            *d = dp.dot(rays[p]);
        }
    });
    d_expected
}

/// The normal-consistency loss of the maps `depth` (`D`), `alpha` (`A`) and `normal` (`N`,
/// interleaved xyz) of a render by `camera`, and its gradients times `d_loss` (the loss weight;
/// module docs). The alpha that weights the surface normals is `alpha` too, detached.
///
/// # Errors
///
/// [`LossError::Empty`] for an image without pixels, [`LossError::BadLength`] when a map does
/// not match the camera's image size.
pub fn normal_consistency(
    camera: &Camera,
    depth: &[f32],
    alpha: &[f32],
    normal: &[f32],
    d_loss: f64,
) -> Result<NormalConsistency, LossError> {
    normal_consistency_weighted(camera, depth, alpha, alpha, normal, d_loss)
}

/// [`normal_consistency`] with the weight of the surface normals given apart: `L = mean(1 −
/// N · n_s(D/A) · surface_weight)`, with no gradient for `surface_weight` (the detached alpha;
/// separate so that the loss is a plain function of `D`, `A` and `N` for finite differences).
///
/// # Errors
///
/// As [`normal_consistency`] (`surface_weight` must have one value per pixel too).
pub fn normal_consistency_weighted(
    camera: &Camera,
    depth: &[f32],
    alpha: &[f32],
    surface_weight: &[f32],
    normal: &[f32],
    d_loss: f64,
) -> Result<NormalConsistency, LossError> {
    let n = camera.pixel_count();
    if n == 0 {
        return Err(LossError::Empty {
            width: camera.width as usize,
            height: camera.height as usize,
            channels: 1,
        });
    }
    for (which, map, expected) in [
        ("depth", depth, n),
        ("alpha", alpha, n),
        ("surface_weight", surface_weight, n),
        ("normal", normal, 3 * n),
    ] {
        if map.len() != expected {
            return Err(LossError::BadLength {
                which,
                expected,
                got: map.len(),
            });
        }
    }
    let expected = expected_depth(depth, alpha);
    let surface = surface_normals(camera, &expected);
    let rendered = |p: usize| DVec3::new(normal[3 * p].into(), normal[3 * p + 1].into(), normal[3 * p + 2].into());
    let weight = |p: usize| f64::from(surface_weight[p]);
    let value = chunked_sum(n, |p| 1.0 - rendered(p).dot(surface[p] * weight(p))) / n as f64;
    let scale = d_loss / n as f64;
    let d_normal: Vec<f32> = (0..n)
        .flat_map(|p| (-scale * weight(p) * surface[p]).as_vec3().to_array())
        .collect();
    let d_surface: Vec<DVec3> = (0..n).map(|p| -scale * weight(p) * rendered(p)).collect();
    let d_expected = surface_normals_vjp(camera, &expected, &d_surface);
    // e = D/A where finite: ∂e/∂D = 1/A, ∂e/∂A = −D/A².
    let (d_depth, d_alpha) = (0..n)
        .map(|p| {
            let (d, a) = (f64::from(depth[p]), f64::from(alpha[p]));
            if (d / a).is_finite() {
                let g = d_expected[p];
                ((g / a) as f32, (-g * d / (a * a)) as f32)
            } else {
                (0.0, 0.0)
            }
        })
        .unzip();
    Ok(NormalConsistency {
        value,
        d_depth,
        d_alpha,
        d_normal,
    })
}
