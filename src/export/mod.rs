//! Export of a trained model to ordinary graphics software: textured planes (OBJ + MTL + PNG, and
//! glTF 2.0 binary), flat 3D Gaussians fitted to the billboards (3DGS PLY, glTF
//! `KHR_gaussian_splatting`), a self-contained WebGL2 viewer page, and an orbit camera path for
//! clips.
//!
//! Method: spec §10.3 (the reference's `render.py --save_planes`). Conventions (also in
//! `docs/export.md`):
//! - **Pruning** ([`prune`]): a billboard is kept when its share of the impact summed over the
//!   training views is `> 1e-6` of the total **and** its largest alpha texel is `> 0.2`.
//! - **Quads** ([`planes`]): billboard `i` becomes the corners `x + R·diag(s_u, s_v, 0)·c` for the
//!   local corners `c` = (−1,−1,0), (1,1,0), (1,−1,0), (−1,1,0), in this order, and the two
//!   triangles (0, 2, 1), (0, 1, 3) (counter-clockwise seen from the normal `n = R·ẑ`).
//!   Positions stay in the dataset's world frame.
//! - **Atlas** ([`atlas`]): tiles of `TS` texels with a 2-texel transparent gap (pitch `TS + 2`),
//!   `max(1, ⌊√N⌋)` tiles per row, tile `k` at column `k mod per_row`, row `k div per_row`.
//!   RGB = colour texture + SH DC colour (`max(SH_C0·f_dc + 0.5, 0)`, view dependence dropped),
//!   A = alpha texture, both 8-bit. The image is stored flipped vertically, so that OBJ's
//!   `v` (origin at the image's bottom) equals the unflipped atlas row over the height.
//! - **UVs** span exactly the `TS` texels of the tile (pixel-edge convention): billboard
//!   `u = −1` ↔ the tile's left texel edge, `u = +1` ↔ its right edge (the renderer samples
//!   align-corners, texel centres at `u = ±1`: the exported texture is 15/16 of the rendered one
//!   at TS 16, as in the reference).
//! - **glTF**: the same quads and atlas PNG, texture `t = 1 − v` (glTF's origin is the top);
//!   alpha BLEND, double-sided, `KHR_materials_unlit`; every dataset camera a perspective
//!   camera node (OpenCV axes turned to glTF's: the camera looks along its −z, y up).
//! - **Gaussians** ([`gaussians`]): each kept billboard becomes at most `max_gaussians` flat
//!   Gaussians fitted to its alpha and colour textures (moments, split across the principal axis
//!   where the fit is poor); written as the Inria 3DGS PLY ([`splat_ply`]) or a glTF with
//!   `KHR_gaussian_splatting` ([`splat_glb`]).

pub mod atlas;
pub mod gaussians;
pub mod glb;
pub mod obj;
pub mod orbit;
pub mod planes;
pub mod prune;
pub mod splat_glb;
pub mod splat_ply;
pub mod viewer;

use std::path::{Path, PathBuf};

/// Errors of the exporters.
#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    /// Writing a file failed.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// Encoding the atlas as PNG failed.
    #[error("encoding the atlas as PNG: {0}")]
    Png(#[from] image::ImageError),
    /// Nothing is left to export.
    #[error(
        "no billboard left to export (all {total} pruned: impact share ≤ {min_impact_share} or max alpha ≤ {min_max_alpha})"
    )]
    NothingKept {
        /// Billboards before pruning.
        total: usize,
        /// The impact-share threshold used.
        min_impact_share: f64,
        /// The alpha threshold used.
        min_max_alpha: f32,
    },
    /// Per-billboard data of the wrong length.
    #[error("{what}: {got} values for {billboards} billboards")]
    Length {
        /// Which input.
        what: &'static str,
        /// Its length.
        got: usize,
        /// The number of billboards.
        billboards: usize,
    },
    /// The atlas would exceed the PNG size limit.
    #[error("the atlas of {tiles} tiles would be {width}×{height} texels, over the {max} limit")]
    AtlasTooLarge {
        /// Tiles.
        tiles: usize,
        /// Width in texels.
        width: u64,
        /// Height in texels.
        height: u64,
        /// The side limit.
        max: u64,
    },
    /// An orbit was asked with no camera to place it.
    #[error("an orbit needs at least one dataset camera and one frame")]
    NoOrbitCamera,
    /// The output exists and is not a regular file (a folder, a device, a FIFO): it is left as
    /// it is ([`crate::file_io::write_atomic`]).
    #[error(transparent)]
    File(crate::file_io::FileError),
}

/// An operating-system error is [`ExportError::Io`]; the rest is [`ExportError::File`].
impl From<crate::file_io::FileError> for ExportError {
    fn from(e: crate::file_io::FileError) -> Self {
        match e {
            crate::file_io::FileError::Io { path, source, .. } => ExportError::Io { path, source },
            other => ExportError::File(other),
        }
    }
}

/// Writes `bytes` to `path` through a temporary file in the same folder renamed over it (a reader
/// never sees half a file; [`crate::file_io::write_atomic`]: through links, a device, a FIFO or
/// a folder at `path` refused and left as it is); the error names the file.
pub fn write_file(path: &Path, bytes: &[u8]) -> Result<(), ExportError> {
    Ok(crate::file_io::write_atomic(path, bytes)?)
}
