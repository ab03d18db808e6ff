//! One textured quad per billboard (spec §10.3 step 2): the billboard's square `[−1, 1]²` in its
//! plane, as four world-space corners and two triangles.

use crate::stages::rotation::quat_to_rotation;
use glam::{Vec2, Vec3};

/// The local corners `(u, v)` of a quad, in the reference's order: (−1,−1), (1,1), (1,−1), (−1,1).
pub const QUAD_CORNERS: [Vec2; 4] = [
    Vec2::new(-1.0, -1.0),
    Vec2::new(1.0, 1.0),
    Vec2::new(1.0, -1.0),
    Vec2::new(-1.0, 1.0),
];

/// The two triangles of a quad, as indices into [`QUAD_CORNERS`]: counter-clockwise in `(u, v)`,
/// so their front faces look along the billboard normal `R·ẑ`.
pub const QUAD_TRIANGLES: [[u32; 3]; 2] = [[0, 2, 1], [0, 1, 3]];

/// The world-space corners of a billboard's quad, in [`QUAD_CORNERS`] order:
/// `position + R·diag(s_u, s_v, 0)·(u, v, 0)` with `R` the rotation of the raw quaternion
/// `(w, x, y, z)` (normalised) and `s = exp(log_scale)` the half side lengths.
///
/// ```
/// use bbsplat::export::planes::quad_corners;
/// use glam::{Vec2, Vec3};
/// let c = quad_corners(Vec3::new(1.0, 2.0, 3.0), [1.0, 0.0, 0.0, 0.0], Vec2::new(0.0, 2f32.ln()));
/// assert_eq!(c[0], Vec3::new(0.0, 0.0, 3.0));
/// assert_eq!(c[1], Vec3::new(2.0, 4.0, 3.0));
/// ```
pub fn quad_corners(position: Vec3, quaternion: [f32; 4], log_scale: Vec2) -> [Vec3; 4] {
    let r = quat_to_rotation(quaternion);
    let axis_u = r.x_axis * log_scale.x.exp();
    let axis_v = r.y_axis * log_scale.y.exp();
    QUAD_CORNERS.map(|c| position + c.x * axis_u + c.y * axis_v)
}

/// The quads of the billboards `kept` (indices into the set), 4 corners each, in `kept` order.
pub fn quads(positions: &[Vec3], quaternions: &[[f32; 4]], log_scales: &[Vec2], kept: &[usize]) -> Vec<[Vec3; 4]> {
    kept.iter()
        .map(|&i| quad_corners(positions[i], quaternions[i], log_scales[i]))
        .collect()
}

/// What the OBJ and glTF writers share: the kept billboards' quads, their texture coordinates
/// (OBJ convention, see [`super::atlas`]) and the atlas.
#[derive(Clone, Debug, PartialEq)]
pub struct PlaneMesh {
    /// Indices of the exported billboards in the model, ascending.
    pub kept: Vec<usize>,
    /// Four world-space corners per quad ([`QUAD_CORNERS`] order).
    pub corners: Vec<[Vec3; 4]>,
    /// Texture coordinates `(s, t)` of the corners, origin at the bottom-left of the stored atlas.
    pub uvs: Vec<[Vec2; 4]>,
    /// The RGBA atlas.
    pub atlas: super::atlas::Atlas,
}

/// The plane mesh of the billboards `kept` of `set` (quad `k` and tile `k` = billboard `kept[k]`).
pub fn plane_mesh(set: &crate::raster::ActivatedRef<'_>, kept: &[usize]) -> Result<PlaneMesh, super::ExportError> {
    let atlas = super::atlas::build_atlas(set, kept)?;
    let corners = quads(set.positions, set.quaternions, set.log_scales, kept);
    let uvs = (0..kept.len())
        .map(|k| QUAD_CORNERS.map(|c| atlas.layout.uv(k, c)))
        .collect();
    Ok(PlaneMesh {
        kept: kept.to_vec(),
        corners,
        uvs,
        atlas,
    })
}
