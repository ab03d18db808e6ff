//! The Gaussians ([`super::gaussians`]) as a 3D Gaussian Splatting PLY, the layout the Inria
//! reference implementation writes (and 3DGS viewers read).
//!
//! Binary little-endian, one `vertex` element, 62 `float` properties per Gaussian in this order:
//! `x y z` (mean, dataset world frame), `nx ny nz` (0), `f_dc_0..2` (SH degree 0, RGB),
//! `f_rest_0..44` (degrees 1-3, channel-major: `f_rest_{15·c + k − 1}` is coefficient `k` of
//! channel `c`, [`crate::stages::sh::channel_major_rest`]; always 45, zeros above the model's SH
//! degree), `opacity` (the logit of the peak opacity), `scale_0..2` (natural logs of the standard
//! deviations), `rot_0..3` (the unit quaternion `w, x, y, z`, local axes → world).

use super::ExportError;
use super::gaussians::GaussianSet;
use crate::model::logit;
use crate::stages::sh::channel_major_rest;
use std::path::Path;

/// Float32 properties per Gaussian.
pub const SPLAT_PLY_FLOATS: usize = 3 + 3 + 3 + 45 + 1 + 3 + 4;

/// The property names, in file order.
///
/// ```
/// use bbsplat::export::splat_ply::{SPLAT_PLY_FLOATS, splat_property_names};
/// let names = splat_property_names();
/// assert_eq!(names.len(), SPLAT_PLY_FLOATS);
/// assert_eq!((names[6].as_str(), names[54].as_str(), names[61].as_str()), ("f_dc_0", "opacity", "rot_3"));
/// ```
pub fn splat_property_names() -> Vec<String> {
    let mut names = crate::stages::sh::ply_position_and_sh_names();
    names.push("opacity".to_string());
    names.extend((0..3).map(|i| format!("scale_{i}")));
    names.extend((0..4).map(|i| format!("rot_{i}")));
    names
}

/// The row of Gaussian `i` of `set`, in [`splat_property_names`] order.
pub fn splat_row(set: &GaussianSet, i: usize) -> [f32; SPLAT_PLY_FLOATS] {
    let mut row = [0.0f32; SPLAT_PLY_FLOATS];
    row[..3].copy_from_slice(&set.positions[i].to_array());
    let sh = set.sh_of(i);
    row[6..9].copy_from_slice(&sh[..3]);
    row[9..54].copy_from_slice(&channel_major_rest(sh));
    row[54] = logit(set.opacities[i]);
    let s = set.scales[i];
    row[55..58].copy_from_slice(&[s.x.ln(), s.y.ln(), s.z.ln()]);
    let q = set.rotations[i];
    row[58..62].copy_from_slice(&[q.w, q.x, q.y, q.z]);
    row
}

/// The PLY bytes of `set`.
pub fn splat_ply_bytes(set: &GaussianSet) -> Vec<u8> {
    let mut header = format!("ply\nformat binary_little_endian 1.0\nelement vertex {}\n", set.len());
    for name in splat_property_names() {
        header.push_str(&format!("property float {name}\n"));
    }
    header.push_str("end_header\n");
    let mut bytes = header.into_bytes();
    bytes.reserve(set.len() * SPLAT_PLY_FLOATS * 4);
    for i in 0..set.len() {
        for v in splat_row(set, i) {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
    }
    bytes
}

/// Writes [`splat_ply_bytes`] to `path` (atomically, [`super::write_file`]); returns the size.
pub fn write_splat_ply(path: &Path, set: &GaussianSet) -> Result<u64, ExportError> {
    let bytes = splat_ply_bytes(set);
    super::write_file(path, &bytes)?;
    Ok(bytes.len() as u64)
}
