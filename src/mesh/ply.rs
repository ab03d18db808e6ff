//! PLY output of a [`TriangleMesh`]: binary little-endian, what Blender and MeshLab read.
//!
//! Layout: `element vertex` with `float x, y, z, nx, ny, nz` and `uchar red, green, blue`
//! (colours quantised as the crate's 8-bit images, [`crate::loss::psnr::quantize_u8`]), then
//! `element face` with `list uchar int vertex_indices` (three per face, counter-clockwise seen
//! from outside). Written into memory, then to the file in one write.

use super::{MeshError, TriangleMesh};
use crate::loss::psnr::quantize_u8;
use std::path::Path;

/// The bytes of `mesh` as a binary little-endian PLY file. Missing normals are written as zero.
pub fn ply_bytes(mesh: &TriangleMesh) -> Vec<u8> {
    let header = format!(
        "ply\nformat binary_little_endian 1.0\ncomment written by bbsplat mesh\nelement vertex {}\n\
         property float x\nproperty float y\nproperty float z\n\
         property float nx\nproperty float ny\nproperty float nz\n\
         property uchar red\nproperty uchar green\nproperty uchar blue\n\
         element face {}\nproperty list uchar int vertex_indices\nend_header\n",
        mesh.positions.len(),
        mesh.triangles.len()
    );
    let mut bytes = Vec::with_capacity(header.len() + 27 * mesh.positions.len() + 13 * mesh.triangles.len());
    bytes.extend_from_slice(header.as_bytes());
    for (i, p) in mesh.positions.iter().enumerate() {
        let n = mesh.normals.get(i).copied().unwrap_or_default();
        for v in p.to_array().into_iter().chain(n.to_array()) {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
        let c = mesh.colours.get(i).copied().unwrap_or([0.5; 3]);
        bytes.extend(c.map(quantize_u8));
    }
    for tri in &mesh.triangles {
        bytes.push(3);
        for &v in tri {
            bytes.extend_from_slice(&(v as i32).to_le_bytes());
        }
    }
    bytes
}

/// Writes `mesh` to `path` ([`ply_bytes`]) atomically ([`crate::file_io::write_atomic`]: a
/// temporary file beside it renamed over it, through links); returns the file's size in bytes.
///
/// # Errors
///
/// [`MeshError::Io`] naming the file when it cannot be written; [`MeshError::File`] when it is
/// a folder, a device or a FIFO (left as it is).
pub fn write_ply(path: &Path, mesh: &TriangleMesh) -> Result<u64, MeshError> {
    let bytes = ply_bytes(mesh);
    crate::file_io::write_atomic(path, &bytes)?;
    Ok(bytes.len() as u64)
}
