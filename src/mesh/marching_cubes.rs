//! Marching cubes: the zero level set of a sampled scalar field as an indexed triangle mesh.
//!
//! Written for this crate (no table copied): the 256-case table is *derived* at first use from
//! one rule, so that neighbouring cells always agree on the faces they share.
//!
//! - Corner `c` (0-7) of a cell sits at offset `(c & 1, (c >> 1) & 1, (c >> 2) & 1)`; a corner is
//!   *inside* when its value is `< 0` (a value of exactly 0 counts as outside).
//! - On each of the cell's six faces, walked counter-clockwise seen from outside the cell, a face
//!   edge whose corners differ is *crossed*: "down" from outside to inside, "up" from inside to
//!   outside. Each down crossing is joined to the next up crossing: a segment of the surface.
//!   On an ambiguous face (inside and outside corners alternating) this separates the inside
//!   corners. The rule depends only on the face's four signs, which the two cells sharing the face
//!   see alike, so the mesh has no cracks.
//! - Each crossed cell edge starts one segment on one of its two faces and ends one on the other,
//!   so the segments chain into closed loops. Each loop is fanned into triangles from one of its
//!   vertices, chosen so that no fan diagonal runs along a cell face: a loop can cross an
//!   ambiguous face twice, and a diagonal there would be an edge of the neighbouring cell's
//!   triangles too (every loop of the 256 cases has such a vertex; the table's derivation checks
//!   it). Segments run down → up, which makes every triangle counter-clockwise seen from the
//!   outside (positive side).
//! - One vertex per crossed *grid* edge, shared by the (up to four) cells around it, placed by
//!   linear interpolation of the two values; vertex colours are interpolated the same way.
//!
//! The result is an edge-manifold, consistently oriented mesh; it is closed (watertight) wherever
//! the level set stays inside the observed part of the grid. Cells with an unobserved corner are
//! skipped (the reference's Open3D rule: every corner needs a non-zero weight).
//!
//! Determinism: cells are processed in parallel per z layer and the layers' triangles joined in
//! layer order; vertices are numbered by sorted grid-edge key. Same input, same mesh, for any
//! thread count.

use super::{MeshError, TriangleMesh};
use glam::Vec3;
use rayon::prelude::*;
use std::sync::OnceLock;

/// A scalar field sampled on a regular grid, x fastest: sample `(x, y, z)` is at
/// `values[x + nx·(y + ny·z)]` and at position `origin + spacing·(x, y, z)`.
#[derive(Clone, Copy, Debug)]
pub struct SampledField<'a> {
    /// Samples along x, y, z (each ≥ 2 to hold a cell).
    pub dims: [usize; 3],
    /// Position of sample `(0, 0, 0)`.
    pub origin: Vec3,
    /// Distance between neighbouring samples.
    pub spacing: f32,
    /// The field's values (negative inside).
    pub values: &'a [f32],
    /// Per sample, whether it was observed; `None`: all are. A cell with an unobserved corner
    /// yields no triangle.
    pub observed: Option<&'a [bool]>,
    /// Per sample colour (linear RGB), interpolated onto the vertices; `None`: grey 0.5.
    pub colours: Option<&'a [[f32; 3]]>,
}

impl SampledField<'_> {
    fn index(&self, x: usize, y: usize, z: usize) -> usize {
        x + self.dims[0] * (y + self.dims[1] * z)
    }
}

/// A cell edge as `corner · 3 + axis`, `corner` the end with the lower coordinate.
type LocalEdge = u8;

/// Per case (bit `c` set when corner `c` is inside), the triangles as local edges.
fn case_table() -> &'static [Vec<[LocalEdge; 3]>; 256] {
    static TABLE: OnceLock<[Vec<[LocalEdge; 3]>; 256]> = OnceLock::new();
    TABLE.get_or_init(|| std::array::from_fn(|case| triangulate_case(case as u8)))
}

/// The four corners of face `(axis, side)`, counter-clockwise seen from outside the cell.
fn face_corners(axis: usize, side: usize) -> [u8; 4] {
    let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
    let corner = |a: usize, b: usize| ((side << axis) | (a << u) | (b << v)) as u8;
    // (u, v, axis) is right-handed: (0,0), (1,0), (1,1), (0,1) turns counter-clockwise about +axis.
    let ccw = [corner(0, 0), corner(1, 0), corner(1, 1), corner(0, 1)];
    if side == 1 {
        ccw
    } else {
        [ccw[0], ccw[3], ccw[2], ccw[1]]
    }
}

/// The two cell faces, as `(axis, side)`, that contain a cell edge.
fn faces_of(edge: LocalEdge) -> [(u8, u8); 2] {
    let (corner, axis) = (edge / 3, edge % 3);
    let [a, b] = match axis {
        0 => [1, 2],
        1 => [0, 2],
        _ => [0, 1],
    };
    [(a, corner >> a & 1), (b, corner >> b & 1)]
}

/// Whether two cell edges lie on a common cell face.
fn share_a_face(e: LocalEdge, f: LocalEdge) -> bool {
    let (fe, ff) = (faces_of(e), faces_of(f));
    fe.iter().any(|x| ff.contains(x))
}

fn edge_between(a: u8, b: u8) -> LocalEdge {
    let axis = (a ^ b).trailing_zeros() as u8;
    a.min(b) * 3 + axis
}

/// The triangles of one case, by the rule of the module documentation.
pub(crate) fn triangulate_case(case: u8) -> Vec<[LocalEdge; 3]> {
    let inside = |c: u8| case >> c & 1 == 1;
    // next[edge] = the edge the segment starting at `edge` ends at.
    let mut next: [Option<LocalEdge>; 24] = [None; 24];
    for axis in 0..3 {
        for side in 0..2 {
            let corners = face_corners(axis, side);
            // Crossings in counter-clockwise order: (edge, is_down).
            let crossings: Vec<(LocalEdge, bool)> = (0..4)
                .filter_map(|k| {
                    let (a, b) = (corners[k], corners[(k + 1) % 4]);
                    (inside(a) != inside(b)).then(|| (edge_between(a, b), inside(b)))
                })
                .collect();
            for (k, &(edge, down)) in crossings.iter().enumerate() {
                if down {
                    let up = crossings[(k + 1) % crossings.len()];
                    debug_assert!(!up.1, "crossings alternate");
                    next[edge as usize] = Some(up.0);
                }
            }
        }
    }
    let mut triangles = Vec::new();
    let mut used = [false; 24];
    for start in 0..24 {
        if used[start] || next[start].is_none() {
            continue;
        }
        let mut ring = Vec::new();
        let mut e = start;
        while !used[e] {
            used[e] = true;
            ring.push(e as LocalEdge);
            e = next[e].expect("a crossed edge starts a segment on its other face") as usize;
        }
        // A fan from ring[s] draws diagonals to every loop vertex but s's two neighbours.
        let len = ring.len();
        let s = (0..len)
            .find(|&s| (2..len - 1).all(|k| !share_a_face(ring[s], ring[(s + k) % len])))
            .expect("every loop has a vertex whose fan diagonals cross the cell's interior");
        for k in 1..len - 1 {
            triangles.push([ring[s], ring[(s + k) % len], ring[(s + k + 1) % len]]);
        }
    }
    triangles
}

/// Extracts the zero level set of `field` ([module documentation](self)).
///
/// # Errors
///
/// [`MeshError::InvalidParameter`] when a dimension is below 2, the spacing is not positive and
/// finite, or a slice's length does not match the dimensions.
pub fn extract(field: &SampledField<'_>) -> Result<TriangleMesh, MeshError> {
    let [nx, ny, nz] = field.dims;
    let count = nx * ny * nz;
    if nx < 2 || ny < 2 || nz < 2 {
        return Err(MeshError::InvalidParameter {
            name: "grid dimensions",
            value: nx.min(ny).min(nz) as f64,
            reason: "every axis needs at least 2 samples",
        });
    }
    if !(field.spacing.is_finite() && field.spacing > 0.0) {
        return Err(MeshError::InvalidParameter {
            name: "spacing",
            value: field.spacing as f64,
            reason: "must be positive and finite",
        });
    }
    let lengths_match = field.values.len() == count
        && field.observed.is_none_or(|o| o.len() == count)
        && field.colours.is_none_or(|c| c.len() == count);
    if !lengths_match {
        return Err(MeshError::InvalidParameter {
            name: "field samples",
            value: field.values.len() as f64,
            reason: "values, observed and colours must hold nx·ny·nz samples",
        });
    }
    let table = case_table();
    let layers: Vec<Vec<[u64; 3]>> = (0..nz - 1)
        .into_par_iter()
        .map(|z| {
            let mut out = Vec::new();
            for y in 0..ny - 1 {
                for x in 0..nx - 1 {
                    let corner_index = |c: u8| {
                        field.index(
                            x + (c & 1) as usize,
                            y + (c >> 1 & 1) as usize,
                            z + (c >> 2 & 1) as usize,
                        )
                    };
                    let mut case = 0u8;
                    let mut skip = false;
                    for c in 0..8u8 {
                        let i = corner_index(c);
                        if field.observed.is_some_and(|o| !o[i]) || !field.values[i].is_finite() {
                            skip = true;
                            break;
                        }
                        if field.values[i] < 0.0 {
                            case |= 1 << c;
                        }
                    }
                    if skip || case == 0 || case == 255 {
                        continue;
                    }
                    for tri in &table[case as usize] {
                        out.push(tri.map(|e| (corner_index(e / 3) as u64) * 3 + (e % 3) as u64));
                    }
                }
            }
            out
        })
        .collect();
    let edge_triangles: Vec<[u64; 3]> = layers.into_iter().flatten().collect();
    let mut keys: Vec<u64> = edge_triangles.iter().flatten().copied().collect();
    keys.par_sort_unstable();
    keys.dedup();
    let strides = [1usize, nx, nx * ny];
    let vertices: Vec<(Vec3, [f32; 3])> = keys
        .par_iter()
        .map(|&key| {
            let (p0, axis) = ((key / 3) as usize, (key % 3) as usize);
            let p1 = p0 + strides[axis];
            let (f0, f1) = (field.values[p0], field.values[p1]);
            let t = (f0 / (f0 - f1)).clamp(0.0, 1.0);
            let (x, y, z) = (p0 % nx, (p0 / nx) % ny, p0 / (nx * ny));
            let mut position = field.origin + field.spacing * Vec3::new(x as f32, y as f32, z as f32);
            position[axis] += t * field.spacing;
            let colour = field.colours.map_or([0.5; 3], |c| {
                let (c0, c1) = (c[p0], c[p1]);
                std::array::from_fn(|k| c0[k] + t * (c1[k] - c0[k]))
            });
            (position, colour)
        })
        .collect();
    let vertex_of = |key: u64| keys.binary_search(&key).expect("every key is listed") as u32;
    let triangles: Vec<[u32; 3]> = edge_triangles.par_iter().map(|t| t.map(vertex_of)).collect();
    let mut mesh = TriangleMesh {
        positions: vertices.iter().map(|v| v.0).collect(),
        normals: Vec::new(),
        colours: vertices.iter().map(|v| v.1).collect(),
        triangles,
    };
    mesh.recompute_normals();
    Ok(mesh)
}
