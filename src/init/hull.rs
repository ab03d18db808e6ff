//! Visual-hull initialisation for scenes whose images carry coverage (alpha) masks.
//!
//! The reference initialises NeRF-synthetic scenes with uniform random points in
//! `[−1.3, 1.3]³` (spec §8): most of them float in empty space, cover every view with
//! semi-transparent layers and must fade and be relocated before they are useful. When the
//! training images come with alpha masks (RGBA renders), the masks say where the object is:
//! carving a voxel grid with them (space carving) leaves the *visual hull*, a superset of the
//! object, and billboards placed on its surface start where the images need them.
//!
//! # Rules
//!
//! - Grid: `resolution³` voxels over the box `[lo, hi]`; a voxel is described by its centre.
//! - Masks: a view's coverage is dilated by [`HullConfig::dilate`] pixels (max filter) so that
//!   thin parts and rounding of the projection cannot carve the object itself. A pixel is
//!   "object" when the dilated coverage is at least [`HullConfig::threshold`].
//! - A voxel is kept when every view with a mask, in front of which it lies (view depth > 0)
//!   and in whose image it projects, sees object at the projected pixel. Views it projects
//!   outside of do not vote (the object may leave the frame).
//! - Surface: kept voxels with at least one of the 6 face neighbours carved (or on the grid
//!   border). Points: the surface voxel centres, each moved by a seeded uniform offset within
//!   the voxel.
//! - Colour: the mean of the image colours at the projections of the point in the views where
//!   its undilated coverage is at least 128 (occlusion is ignored: a rough starting colour for
//!   the SH DC term); grey 0.5 when there is no such view.
//!
//! Cost: `resolution³ × views` projections, parallel over z-slices (deterministic).

use crate::rng::Rng;
use crate::scene::View;
use glam::Vec3;
use rayon::prelude::*;
use thiserror::Error;

/// Parameters of [`visual_hull_points`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HullConfig {
    /// Voxels per side of the grid.
    pub resolution: usize,
    /// Dilation of the masks, pixels (square max filter of side `2·dilate + 1`).
    pub dilate: u32,
    /// Dilated coverage (0-255) at or above which a pixel counts as object.
    pub threshold: u8,
}

impl Default for HullConfig {
    fn default() -> Self {
        Self {
            resolution: 128,
            dilate: 2,
            threshold: 8,
        }
    }
}

/// Errors of [`visual_hull_points`].
#[derive(Debug, Error, PartialEq)]
#[non_exhaustive]
pub enum HullError {
    /// No training view has a coverage mask (the images have no alpha channel, or needed
    /// undistortion).
    #[error("no training view has an alpha mask: the visual hull needs RGBA images (e.g. NeRF-synthetic)")]
    NoMasks,
    /// Carving left no voxel (the masks are empty or inconsistent with the cameras).
    #[error("the visual hull is empty: every voxel of the box was carved away by some view's mask")]
    Empty,
    /// A grid resolution below 2.
    #[error("the hull grid resolution must be at least 2, got {0}")]
    Resolution(usize),
    /// A view's image could not be decoded again for the points' colours (an on-demand image,
    /// [`crate::scene::on_demand`]): the message names the file.
    #[error("{0}")]
    Image(String),
}

/// A view's mask, dilated and thresholded: `true` where the view sees the object.
struct ObjectMask<'a> {
    view: &'a View,
    object: Vec<bool>,
    raw: &'a [u8],
}

pub(crate) fn dilate_mask(coverage: &[u8], width: usize, height: usize, radius: usize) -> Vec<u8> {
    // Separable max filter: rows, then columns.
    let mut rows = vec![0u8; coverage.len()];
    for y in 0..height {
        for x in 0..width {
            let (a, b) = (x.saturating_sub(radius), (x + radius).min(width - 1));
            rows[y * width + x] = coverage[y * width + a..=y * width + b]
                .iter()
                .copied()
                .max()
                .unwrap_or(0);
        }
    }
    let mut out = vec![0u8; coverage.len()];
    for y in 0..height {
        let (a, b) = (y.saturating_sub(radius), (y + radius).min(height - 1));
        for x in 0..width {
            out[y * width + x] = (a..=b).map(|yy| rows[yy * width + x]).max().unwrap_or(0);
        }
    }
    out
}

/// Pixel index of the projection of `p` in `view`, when in front of it and inside its image.
#[inline]
fn pixel_of(view: &View, p: Vec3) -> Option<usize> {
    let cam = &view.camera;
    let (x, y) = cam.project(p)?;
    // Written positively so that NaN fails.
    if !(x >= 0.0 && y >= 0.0 && x < cam.width as f32 && y < cam.height as f32) {
        return None;
    }
    Some(y as usize * cam.width as usize + x as usize)
}

/// The kept voxels of the visual hull of `views` over the box `[lo, hi]`, as a
/// `resolution³` occupancy grid indexed `(z·r + y)·r + x`.
///
/// # Errors
/// [`HullError::NoMasks`] when no view has a coverage mask, [`HullError::Resolution`] for a
/// resolution below 2.
pub fn carve(views: &[View], lo: Vec3, hi: Vec3, config: &HullConfig) -> Result<Vec<bool>, HullError> {
    let r = config.resolution;
    if r < 2 {
        return Err(HullError::Resolution(r));
    }
    let masks = object_masks(views, config)?;
    let step = (hi - lo) / r as f32;
    let mut occupied = vec![false; r * r * r];
    occupied.par_chunks_mut(r * r).enumerate().for_each(|(z, slice)| {
        for y in 0..r {
            for x in 0..r {
                let p = lo + step * Vec3::new(x as f32 + 0.5, y as f32 + 0.5, z as f32 + 0.5);
                slice[y * r + x] = masks.iter().all(|m| pixel_of(m.view, p).is_none_or(|i| m.object[i]));
            }
        }
    });
    Ok(occupied)
}

fn object_masks<'a>(views: &'a [View], config: &HullConfig) -> Result<Vec<ObjectMask<'a>>, HullError> {
    let masks: Vec<ObjectMask<'a>> = views
        .par_iter()
        .filter_map(|view| {
            let raw = view.coverage.as_deref()?;
            let (w, h) = (view.camera.width as usize, view.camera.height as usize);
            if raw.len() != w * h || w == 0 || h == 0 {
                return None;
            }
            let object = dilate_mask(raw, w, h, config.dilate as usize)
                .into_iter()
                .map(|a| a >= config.threshold)
                .collect();
            Some(ObjectMask { view, object, raw })
        })
        .collect();
    if masks.is_empty() {
        return Err(HullError::NoMasks);
    }
    Ok(masks)
}

/// Points on the surface of the visual hull of `views` over the box `[lo, hi]` and their
/// colours (rules in the [module documentation](self)), in grid order. `seed` drives the
/// offsets within the voxels.
///
/// # Errors
/// As [`carve`], and [`HullError::Empty`] when every voxel was carved.
pub fn visual_hull_points(
    views: &[View],
    lo: Vec3,
    hi: Vec3,
    config: &HullConfig,
    seed: u64,
) -> Result<(Vec<Vec3>, Vec<[f32; 3]>), HullError> {
    let occupied = carve(views, lo, hi, config)?;
    let masks = object_masks(views, config)?;
    let r = config.resolution;
    let at = |x: usize, y: usize, z: usize| occupied[(z * r + y) * r + x];
    let step = (hi - lo) / r as f32;
    let mut rng = Rng::new(seed);
    let mut points = Vec::new();
    for z in 0..r {
        for y in 0..r {
            for x in 0..r {
                if !at(x, y, z) {
                    continue;
                }
                let border = x == 0 || y == 0 || z == 0 || x + 1 == r || y + 1 == r || z + 1 == r;
                let surface = border
                    || !at(x - 1, y, z)
                    || !at(x + 1, y, z)
                    || !at(x, y - 1, z)
                    || !at(x, y + 1, z)
                    || !at(x, y, z - 1)
                    || !at(x, y, z + 1);
                if surface {
                    let jitter = Vec3::new(rng.range(0.0, 1.0), rng.range(0.0, 1.0), rng.range(0.0, 1.0));
                    points.push(lo + step * (Vec3::new(x as f32, y as f32, z as f32) + jitter));
                }
            }
        }
    }
    if points.is_empty() {
        return Err(HullError::Empty);
    }
    // View by view (each image fetched once, decoded when it is on demand), each point's sum
    // in view order.
    let mut sums = vec![([0.0f64; 3], 0u32); points.len()];
    for m in &masks {
        let image = m.view.image.get().map_err(|e| HullError::Image(e.to_string()))?;
        let px = image.as_bytes();
        sums.par_iter_mut().zip(&points).for_each(|((sum, n), &p)| {
            if let Some(i) = pixel_of(m.view, p)
                && m.raw[i] >= 128
            {
                for c in 0..3 {
                    sum[c] += f64::from(px[3 * i + c]) / 255.0;
                }
                *n += 1;
            }
        });
    }
    let colours = sums
        .into_iter()
        .map(|(sum, n)| {
            if n == 0 {
                [0.5; 3]
            } else {
                sum.map(|s| (s / f64::from(n)) as f32)
            }
        })
        .collect();
    Ok((points, colours))
}
