//! Surfaces from a trained model: TSDF fusion of rendered depth maps, marching cubes, the largest
//! connected components, vertex colours, a PLY writer and the Chamfer distance to a reference
//! surface (spec §10.4, after 2DGS's `utils/mesh_utils.py`).
//!
//! Pipeline (each step one file):
//! 1. [`params`]: the grid (bounds, voxel size), the truncation distances and the depth kind,
//!    scaled to the scene from its cameras and billboards ([`params::MeshParams::for_scene`]).
//! 2. [`tsdf`]: every training view is rendered (SH degree 0, as the reference), its depth map
//!    (expected or median) is fused into a truncated signed distance volume with colour.
//! 3. [`marching_cubes`]: the zero level set of the volume as a triangle mesh, one vertex per
//!    crossed grid edge (shared by the cells around it), watertight where the volume is observed.
//! 4. [`components`]: connected components (triangles sharing an edge); the reference's rule
//!    keeps the largest ones.
//! 5. [`ply`]: binary little-endian PLY with normals and 8-bit vertex colours.
//! 6. [`chamfer`]: area-uniform samples of a mesh and the Chamfer distance / normal consistency
//!    between two sampled surfaces.
//!
//! Conventions: world units and frame of the scene (cameras of [`crate::camera`]: world to
//! camera, OpenCV axes); depth is *view depth* `z` (along the optical axis), as the rasterizer's
//! [`RenderOutput`](crate::raster::RenderOutput); signed distances are positive in front of the
//! surface (free space, towards the cameras) and negative behind it; triangles are
//! counter-clockwise seen from the positive (outside) side, so their right-hand normals point out
//! of the object; vertex colours are linear RGB in `[0, 1]` (8-bit in the PLY file).
//!
//! Determinism: every parallel loop writes slots fixed by the input (a voxel, a grid slab, a
//! sample) and every sum runs in a fixed order, so the mesh is bit-identical for any rayon
//! thread count (tested in `tests/suite/mesh.rs`).

pub mod chamfer;
pub mod components;
pub mod marching_cubes;
pub mod params;
pub mod pipeline;
pub mod ply;
pub mod tsdf;

use glam::Vec3;
use std::path::PathBuf;

/// An indexed triangle mesh with per-vertex normals and colours.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TriangleMesh {
    /// Vertex positions (world units).
    pub positions: Vec<Vec3>,
    /// Unit vertex normals (area-weighted mean of the adjacent triangles' normals), pointing to
    /// the outside; zero for a vertex whose triangles all have zero area.
    pub normals: Vec<Vec3>,
    /// Vertex colours, linear RGB in `[0, 1]`.
    pub colours: Vec<[f32; 3]>,
    /// Triangles as vertex indices, counter-clockwise seen from the outside.
    pub triangles: Vec<[u32; 3]>,
}

impl TriangleMesh {
    /// Area of triangle `t`.
    pub fn triangle_area(&self, t: usize) -> f32 {
        let [a, b, c] = self.triangles[t].map(|i| self.positions[i as usize]);
        0.5 * (b - a).cross(c - a).length()
    }

    /// Total surface area, summed in triangle order (f64).
    pub fn area(&self) -> f64 {
        (0..self.triangles.len()).map(|t| self.triangle_area(t) as f64).sum()
    }

    /// Signed enclosed volume by the divergence theorem (`Σ a·(b×c)/6`, f64, triangle order):
    /// positive for a closed mesh oriented outwards.
    pub fn signed_volume(&self) -> f64 {
        self.triangles
            .iter()
            .map(|tri| {
                let [a, b, c] = tri.map(|i| self.positions[i as usize].as_dvec3());
                a.dot(b.cross(c)) / 6.0
            })
            .sum()
    }

    /// Recomputes [`TriangleMesh::normals`]: per vertex, the sum of the adjacent triangles'
    /// `(b − a) × (c − a)` (area-weighted), in triangle order, normalised.
    pub fn recompute_normals(&mut self) {
        let mut sums = vec![Vec3::ZERO; self.positions.len()];
        for tri in &self.triangles {
            let [a, b, c] = tri.map(|i| self.positions[i as usize]);
            let n = (b - a).cross(c - a);
            for &i in tri {
                sums[i as usize] += n;
            }
        }
        self.normals = sums.into_iter().map(|n| n.normalize_or_zero()).collect();
    }
}

/// What can go wrong while extracting, measuring or writing a mesh.
#[derive(Debug, thiserror::Error)]
pub enum MeshError {
    /// A parameter is out of its range.
    #[error("mesh parameter {name} = {value}: {reason}")]
    InvalidParameter {
        /// The parameter's name (as the command-line flag spells it, without dashes).
        name: &'static str,
        /// Its value.
        value: f64,
        /// What is wrong with it.
        reason: &'static str,
    },
    /// The grid would need more voxels than allowed.
    #[error("the TSDF grid would hold {voxels} voxels ({dims:?}), more than the limit {limit}; raise the voxel size")]
    GridTooLarge {
        /// Voxels along x, y, z.
        dims: [usize; 3],
        /// Their product.
        voxels: u64,
        /// The limit.
        limit: u64,
    },
    /// Nothing to fuse: no view, or no camera to scale the defaults from.
    #[error("no view to fuse")]
    NoViews,
    /// The grid bounds could not be derived (no finite billboard position, degenerate box).
    #[error("cannot bound the grid: {0}")]
    NoBounds(&'static str),
    /// The fused volume has no zero crossing between observed voxels.
    #[error("no surface found: the fused volume has no zero crossing ({observed} of {voxels} voxels observed)")]
    NoSurface {
        /// Voxels with a non-zero weight.
        observed: u64,
        /// All voxels.
        voxels: u64,
    },
    /// A mesh has no triangle with positive area to sample.
    #[error("the mesh has no triangle of positive area to sample")]
    EmptyMesh,
    /// Writing a file failed.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// The output exists and is not a regular file (a folder, a device, a FIFO): it is left as
    /// it is ([`crate::file_io::write_atomic`]).
    #[error(transparent)]
    File(crate::file_io::FileError),
}

/// An operating-system error is [`MeshError::Io`]; the rest is [`MeshError::File`].
impl From<crate::file_io::FileError> for MeshError {
    fn from(e: crate::file_io::FileError) -> Self {
        match e {
            crate::file_io::FileError::Io { path, source, .. } => MeshError::Io { path, source },
            other => MeshError::File(other),
        }
    }
}
