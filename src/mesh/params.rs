//! Parameters of the mesh extraction and their defaults scaled to a scene.
//!
//! The reference (spec §10.4; BBSplat's `render.py` on 2DGS's `utils/mesh_utils.py`) fuses into
//! Open3D's sparse `ScalableTSDFVolume` with voxel 0.004, `sdf_trunc` = 5 · voxel and
//! `depth_trunc` 3.0 in the DTU scenes' units; 2DGS's own rule for other scenes is
//! `depth_trunc` = 2 · r, voxel = `depth_trunc` / 1024, `sdf_trunc` = 5 · voxel, with `r` the
//! smallest distance from a training camera to the *focus point* (the point nearest to all
//! optical axes in the least-squares sense). This crate fuses into a dense grid, so the grid needs
//! bounds; [`MeshParams::for_scene`] sets:
//!
//! - `depth_trunc` = 2 · r (2DGS's rule; depths beyond are not fused);
//! - the grid box: per axis the 1st to 99th percentile of the given billboard centres (the caller
//!   passes the ones that matter, e.g. those with a visible alpha), clipped to the cube of half
//!   side r around the focus point, then widened by 2 % of its longest side on every side;
//! - voxel = the box's longest side / `resolution` (256 by default: 2DGS's 1024 over the whole
//!   `2r` would hold 10⁹ dense voxels), `sdf_trunc` = 5 · voxel (the reference's ratio);
//! - pixels with rendered alpha below `min_alpha` (default 0: only pixels with *no* coverage,
//!   whose expected depth is 0/0, are skipped, as in the reference) and, when a view has its
//!   own alpha channel (NeRF-synthetic), pixels whose image alpha is below 0.5 (the reference's
//!   mask) fuse nothing: they neither carve free space nor add surface;
//! - components: the reference's `num_cluster` 1000 and 50 triangles at least.

use super::MeshError;
use crate::camera::Camera;
use glam::{DMat3, DVec3, Vec3};

/// Which rendered depth is fused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DepthKind {
    /// `Σ α·T·z / Σ α·T` (the reference's default, `depth_ratio` 0).
    Expected,
    /// The median depth of the renderer (`depth_ratio` 1).
    Median,
}

/// Everything the extraction needs ([module documentation](self) for the defaults).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MeshParams {
    /// The depth fused.
    pub depth: DepthKind,
    /// Grid spacing (world units).
    pub voxel_size: f32,
    /// Truncation distance of the signed distance (world units along the ray).
    pub sdf_trunc: f32,
    /// Depths beyond this view depth are not fused.
    pub depth_trunc: f32,
    /// Pixels whose rendered alpha is below this fuse nothing (0: only pixels with no coverage).
    pub min_alpha: f32,
    /// Skip pixels whose image alpha (the view's `coverage`) is below 0.5, when there is one.
    pub use_coverage: bool,
    /// Lowest corner of the grid (the position of sample `(0, 0, 0)`).
    pub bounds_min: Vec3,
    /// Highest corner of the grid.
    pub bounds_max: Vec3,
    /// The reference's `num_cluster`: how many of the largest components to keep.
    pub keep_components: usize,
    /// Components with fewer triangles are dropped whatever `keep_components` says.
    pub min_component_triangles: u32,
}

/// At most this many voxels in a grid (20 bytes each: 5 GB).
pub const MAX_VOXELS: u64 = 256_000_000;

/// The focus point of the cameras (least-squares nearest point to their optical axes) and the
/// smallest distance from a camera centre to it. `None` for no camera or parallel axes.
pub fn focus_and_radius(cameras: &[Camera]) -> Option<(Vec3, f32)> {
    let mut m = DMat3::ZERO;
    let mut rhs = DVec3::ZERO;
    for c in cameras {
        // The optical axis in the world: the third row of the world-to-camera rotation.
        let d = c.rotation.row(2).as_dvec3().normalize();
        let proj = DMat3::IDENTITY - DMat3::from_cols(d * d.x, d * d.y, d * d.z);
        m += proj;
        rhs += proj * c.centre_f64();
    }
    if cameras.is_empty() || m.determinant().abs() < 1e-9 * cameras.len().pow(3) as f64 {
        return None;
    }
    let focus = m.inverse() * rhs;
    let radius = cameras
        .iter()
        .map(|c| (c.centre_f64() - focus).length())
        .fold(f64::INFINITY, f64::min);
    Some((focus.as_vec3(), radius as f32))
}

fn percentile(sorted: &[f32], q: f64) -> f32 {
    sorted[((sorted.len() - 1) as f64 * q).round() as usize]
}

impl MeshParams {
    /// Defaults scaled to a scene from its training `cameras` and the billboard `centres` that
    /// bound the object ([module documentation](self)); `resolution` voxels along the grid's
    /// longest side.
    ///
    /// # Errors
    ///
    /// [`MeshError::NoViews`] without cameras, [`MeshError::NoBounds`] when the cameras have no
    /// focus point or no centre is finite, [`MeshError::InvalidParameter`] for a resolution
    /// below 2.
    pub fn for_scene(cameras: &[Camera], centres: &[Vec3], resolution: usize) -> Result<Self, MeshError> {
        if cameras.is_empty() {
            return Err(MeshError::NoViews);
        }
        if resolution < 2 {
            return Err(MeshError::InvalidParameter {
                name: "resolution",
                value: resolution as f64,
                reason: "at least 2 voxels along the longest side",
            });
        }
        let (focus, radius) =
            focus_and_radius(cameras).ok_or(MeshError::NoBounds("the cameras' axes have no focus point"))?;
        let finite: Vec<Vec3> = centres.iter().copied().filter(|p| p.is_finite()).collect();
        if finite.is_empty() {
            return Err(MeshError::NoBounds("no finite billboard centre"));
        }
        let mut lo = Vec3::ZERO;
        let mut hi = Vec3::ZERO;
        for axis in 0..3 {
            let mut v: Vec<f32> = finite.iter().map(|p| p[axis]).collect();
            v.sort_unstable_by(f32::total_cmp);
            lo[axis] = percentile(&v, 0.01).max(focus[axis] - radius);
            hi[axis] = percentile(&v, 0.99).min(focus[axis] + radius);
        }
        if !(hi - lo).cmpgt(Vec3::ZERO).all() {
            return Err(MeshError::NoBounds(
                "the billboards and the cameras' focus region do not overlap",
            ));
        }
        let pad = 0.02 * (hi - lo).max_element();
        let (bounds_min, bounds_max) = (lo - pad, hi + pad);
        let voxel_size = (bounds_max - bounds_min).max_element() / resolution as f32;
        Ok(Self {
            depth: DepthKind::Expected,
            voxel_size,
            sdf_trunc: 5.0 * voxel_size,
            depth_trunc: 2.0 * radius,
            min_alpha: 0.0,
            use_coverage: true,
            bounds_min,
            bounds_max,
            keep_components: 1000,
            min_component_triangles: 50,
        })
    }

    /// Samples along x, y, z: enough to cover the bounds at `voxel_size` (at least 2).
    pub fn dims(&self) -> [usize; 3] {
        let extent = self.bounds_max - self.bounds_min;
        std::array::from_fn(|a| ((extent[a] / self.voxel_size).ceil() as usize + 1).max(2))
    }

    /// Checks the ranges: sizes positive and finite, bounds ordered, grid not above
    /// [`MAX_VOXELS`], `min_alpha` in `[0, 1]`.
    ///
    /// # Errors
    ///
    /// [`MeshError::InvalidParameter`] or [`MeshError::GridTooLarge`].
    pub fn validate(&self) -> Result<(), MeshError> {
        let positive = [
            ("voxel-size", self.voxel_size),
            ("sdf-trunc", self.sdf_trunc),
            ("depth-trunc", self.depth_trunc),
        ];
        for (name, value) in positive {
            if !(value.is_finite() && value > 0.0) {
                return Err(MeshError::InvalidParameter {
                    name,
                    value: value as f64,
                    reason: "must be positive and finite",
                });
            }
        }
        if !(0.0..=1.0).contains(&self.min_alpha) {
            return Err(MeshError::InvalidParameter {
                name: "min-alpha",
                value: self.min_alpha as f64,
                reason: "must be in [0, 1]",
            });
        }
        if !(self.bounds_min.is_finite()
            && self.bounds_max.is_finite()
            && (self.bounds_max - self.bounds_min).cmpgt(Vec3::ZERO).all())
        {
            return Err(MeshError::NoBounds("the grid bounds are not finite and ordered"));
        }
        let extent = self.bounds_max - self.bounds_min;
        let per_axis: Vec<f64> = (0..3).map(|a| (extent[a] / self.voxel_size) as f64 + 1.0).collect();
        let voxels = per_axis.iter().product::<f64>();
        if voxels > MAX_VOXELS as f64 {
            return Err(MeshError::GridTooLarge {
                dims: std::array::from_fn(|a| per_axis[a].min(usize::MAX as f64) as usize),
                voxels: voxels.min(u64::MAX as f64) as u64,
                limit: MAX_VOXELS,
            });
        }
        Ok(())
    }
}
