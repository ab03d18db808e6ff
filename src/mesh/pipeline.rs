//! The whole extraction: fuse the views, run marching cubes on the observed voxels, keep the
//! largest components (spec §10.4).

use super::components::{KeptComponents, keep_largest};
use super::marching_cubes::{SampledField, extract};
use super::params::MeshParams;
use super::tsdf::{FusionView, fuse_views};
use super::{MeshError, TriangleMesh};
use crate::raster::{ActivatedRef, RenderSettings};

/// What [`extract_mesh`] did.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MeshReport {
    /// Grid samples along x, y, z.
    pub dims: [usize; 3],
    /// Voxels observed by at least one view.
    pub observed: u64,
    /// Triangles straight out of marching cubes.
    pub raw_triangles: usize,
    /// The components and what was kept of them.
    pub components: KeptComponents,
}

/// Fuses `views` ([`fuse_views`]), extracts the zero level set of the observed voxels
/// ([`extract`], colours from the fused colour) and keeps the largest components
/// ([`keep_largest`] with `params`' counts).
///
/// # Errors
///
/// What [`fuse_views`] returns; [`MeshError::NoSurface`] when no triangle comes out.
pub fn extract_mesh(
    set: &ActivatedRef<'_>,
    views: &[FusionView<'_>],
    settings: &RenderSettings,
    params: &MeshParams,
) -> Result<(TriangleMesh, MeshReport), MeshError> {
    let volume = fuse_views(set, views, settings, params)?;
    let observed_mask: Vec<bool> = volume.weight.iter().map(|w| *w > 0.0).collect();
    let observed = observed_mask.iter().filter(|o| **o).count() as u64;
    let field = SampledField {
        dims: volume.dims,
        origin: volume.origin,
        spacing: volume.voxel_size,
        values: &volume.tsdf,
        observed: Some(&observed_mask),
        colours: Some(&volume.colour),
    };
    let mut mesh = extract(&field)?;
    let raw_triangles = mesh.triangles.len();
    let components = keep_largest(&mut mesh, params.keep_components, params.min_component_triangles);
    if mesh.triangles.is_empty() {
        return Err(MeshError::NoSurface {
            observed,
            voxels: volume.tsdf.len() as u64,
        });
    }
    Ok((
        mesh,
        MeshReport {
            dims: volume.dims,
            observed,
            raw_triangles,
            components,
        },
    ))
}
