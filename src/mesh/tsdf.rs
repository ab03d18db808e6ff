//! TSDF fusion: rendered depth maps of the training views fused into a truncated signed
//! distance volume with colour (the reference's Open3D `ScalableTSDFVolume.integrate`, dense).
//!
//! Per view and per voxel (centre `p`, view-space `v`): the voxel projects to pixel
//! `(⌊fx·v.x/v.z + cx⌋, ⌊fy·v.y/v.z + cy⌋)` (the crate's pixel convention: pixel `i` covers
//! `[i, i + 1)`). With that pixel's depth `d` (view depth; 0 where the pixel fuses nothing) the
//! signed distance is measured along the ray, as Open3D: `sdf = (d − v.z) · ‖(v.x/v.z, v.y/v.z,
//! 1)‖`. The voxel is updated only when `0 < d ≤ depth_trunc` and `sdf > −sdf_trunc`, with
//! `tsdf = min(1, sdf / sdf_trunc)` folded into a running mean of weight 1 per view (colour
//! likewise, the pixel's rendered RGB). Voxels in front of the surface get `+1` (carved free
//! space), voxels far behind it are left alone, and pixels that fuse nothing leave every voxel
//! on their ray untouched ([`super::params`] says which pixels those are).
//!
//! Determinism: views are fused one after another in the given order; within a view voxels are
//! updated in parallel, each by one task, from its own values only.

use super::MeshError;
use super::params::{DepthKind, MeshParams};
use crate::camera::Camera;
use crate::raster::{ActivatedRef, RenderBuffers, RenderOutput, RenderSettings, render_with};
use glam::Vec3;
use rayon::prelude::*;

/// A depth map to fuse and the colours that go with it.
#[derive(Clone, Debug, PartialEq)]
pub struct DepthMap {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// View depth per pixel, row-major; `0` where the pixel fuses nothing.
    pub depth: Vec<f32>,
    /// Interleaved RGB per pixel (linear, `[0, 1]`, clamped).
    pub rgb: Vec<f32>,
}

impl DepthMap {
    /// The depth map of a render: expected depth `depth / alpha` or the median depth, set to 0
    /// where the rendered alpha is 0 or below `min_alpha`, where the result is not finite and
    /// positive, or where `coverage` (the image's own alpha, 8-bit) is below 128 (0.5).
    pub fn from_render(out: &RenderOutput, kind: DepthKind, min_alpha: f32, coverage: Option<&[u8]>) -> Self {
        let n = (out.width * out.height) as usize;
        let depth = (0..n)
            .map(|i| {
                let alpha = out.alpha[i];
                let d = match kind {
                    DepthKind::Expected => out.depth[i] / alpha,
                    DepthKind::Median => out.median_depth[i],
                };
                let masked = coverage.is_some_and(|c| c[i] < 128);
                if alpha > 0.0 && alpha >= min_alpha && !masked && d.is_finite() && d > 0.0 {
                    d
                } else {
                    0.0
                }
            })
            .collect();
        Self {
            width: out.width,
            height: out.height,
            depth,
            rgb: out.rgb.iter().map(|c| c.clamp(0.0, 1.0)).collect(),
        }
    }
}

/// A dense TSDF volume with colour: samples at `origin + voxel_size·(x, y, z)`, x fastest.
#[derive(Clone, Debug, PartialEq)]
pub struct TsdfVolume {
    /// Samples along x, y, z.
    pub dims: [usize; 3],
    /// Position of sample `(0, 0, 0)`.
    pub origin: Vec3,
    /// Grid spacing.
    pub voxel_size: f32,
    /// Truncation distance.
    pub sdf_trunc: f32,
    /// Truncated signed distance over `sdf_trunc`, in `[−1, 1]` (1 where unobserved).
    pub tsdf: Vec<f32>,
    /// Number of views that updated each voxel.
    pub weight: Vec<f32>,
    /// Mean colour of the pixels that updated each voxel.
    pub colour: Vec<[f32; 3]>,
}

impl TsdfVolume {
    /// An empty (unobserved) volume for `params`' grid.
    ///
    /// # Errors
    ///
    /// What [`MeshParams::validate`] returns.
    pub fn new(params: &MeshParams) -> Result<Self, MeshError> {
        params.validate()?;
        let dims = params.dims();
        let n = dims.iter().product();
        Ok(Self {
            dims,
            origin: params.bounds_min,
            voxel_size: params.voxel_size,
            sdf_trunc: params.sdf_trunc,
            tsdf: vec![1.0; n],
            weight: vec![0.0; n],
            colour: vec![[0.0; 3]; n],
        })
    }

    /// Voxels with a non-zero weight.
    pub fn observed(&self) -> u64 {
        self.weight.iter().filter(|w| **w > 0.0).count() as u64
    }

    /// Fuses one depth map seen by `camera` ([module documentation](self)).
    ///
    /// # Panics
    ///
    /// When the map's size is not the camera's.
    pub fn integrate(&mut self, map: &DepthMap, camera: &Camera, depth_trunc: f32) {
        assert_eq!(
            (map.width, map.height),
            (camera.width, camera.height),
            "depth map and camera sizes differ"
        );
        let [nx, ny, _] = self.dims;
        let (origin, voxel, trunc) = (self.origin, self.voxel_size, self.sdf_trunc);
        let layer = nx * ny;
        self.tsdf
            .par_chunks_mut(layer)
            .zip(self.weight.par_chunks_mut(layer))
            .zip(self.colour.par_chunks_mut(layer))
            .enumerate()
            .for_each(|(z, ((tsdf, weight), colour))| {
                for y in 0..ny {
                    for x in 0..nx {
                        let p = origin + voxel * Vec3::new(x as f32, y as f32, z as f32);
                        let v = camera.world_to_view(p);
                        if v.z <= 0.0 {
                            continue;
                        }
                        let (rx, ry) = (v.x / v.z, v.y / v.z);
                        let (u, w) = (camera.fx * rx + camera.cx, camera.fy * ry + camera.cy);
                        if !(u >= 0.0 && w >= 0.0 && u < camera.width as f32 && w < camera.height as f32) {
                            continue;
                        }
                        let pixel = w as usize * camera.width as usize + u as usize;
                        let d = map.depth[pixel];
                        if !(d > 0.0 && d <= depth_trunc) {
                            continue;
                        }
                        let sdf = (d - v.z) * (1.0 + rx * rx + ry * ry).sqrt();
                        if sdf <= -trunc {
                            continue;
                        }
                        let value = (sdf / trunc).min(1.0);
                        let i = y * nx + x;
                        let old = weight[i];
                        let new = old + 1.0;
                        tsdf[i] = (tsdf[i] * old + value) / new;
                        let rgb = &map.rgb[pixel * 3..pixel * 3 + 3];
                        for k in 0..3 {
                            colour[i][k] = (colour[i][k] * old + rgb[k]) / new;
                        }
                        weight[i] = new;
                    }
                }
            });
    }
}

/// One view to fuse: its camera and, when the image had one, its own alpha channel.
#[derive(Clone, Copy, Debug)]
pub struct FusionView<'a> {
    /// The camera.
    pub camera: &'a Camera,
    /// The image's alpha (8-bit, `width · height`), masking the background as the reference.
    pub coverage: Option<&'a [u8]>,
}

/// Renders every view of `views` with `settings` at SH degree 0 (as the reference) and fuses
/// its depth map ([`DepthMap::from_render`] with `params`' depth kind, `min_alpha` and, when
/// `use_coverage`, the view's coverage) into a new volume, views in the given order.
///
/// # Errors
///
/// [`MeshError::NoViews`] without views; what [`TsdfVolume::new`] returns.
pub fn fuse_views(
    set: &ActivatedRef<'_>,
    views: &[FusionView<'_>],
    settings: &RenderSettings,
    params: &MeshParams,
) -> Result<TsdfVolume, MeshError> {
    if views.is_empty() {
        return Err(MeshError::NoViews);
    }
    let mut volume = TsdfVolume::new(params)?;
    let settings = RenderSettings {
        sh_degree: 0,
        ..*settings
    };
    // The render's storage recycled from view to view (the same maps, fewer fresh pages).
    let mut buffers = RenderBuffers::default();
    for view in views {
        let out = render_with(set, view.camera, &settings, std::mem::take(&mut buffers));
        let coverage = if params.use_coverage { view.coverage } else { None };
        let map = DepthMap::from_render(&out, params.depth, params.min_alpha, coverage);
        volume.integrate(&map, view.camera, params.depth_trunc);
        buffers = out.into_buffers();
    }
    Ok(volume)
}
