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
//!   vertices, chosen so that no fan diagonal runs along a cell face (a loop can cross an
//!   ambiguous face twice, and a diagonal there would be the neighbouring cell's edge too); a loop
//!   with no such vertex is fanned from an extra vertex at its centre. Segments run down → up,
//!   which makes every triangle counter-clockwise seen from the outside (positive side).
//! - One vertex per crossed *grid* edge, shared by the (up to four) cells around it, placed by
//!   linear interpolation of the two values; vertex colours are interpolated the same way. A loop's
//!   centre vertex is the mean of its loop's vertices (positions and colours).
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

/// A cell edge as `corner · 3 + axis`, `corner` the end with the lower coordinate; a value
/// `CENTRE + k` in a triangle stands for the centre vertex of the case's `k`-th centred loop.
type LocalEdge = u8;

/// The first local index that names a loop centre instead of a cell edge (a cell has 12 edges,
/// numbered below 24).
const CENTRE: LocalEdge = 24;

/// The triangles of one case and the loops fanned from a centre vertex.
#[derive(Debug, Default)]
struct CaseTriangles {
    /// Triangles as local edges or `CENTRE + k`.
    triangles: Vec<[LocalEdge; 3]>,
    /// The loops whose centre is a vertex, as local edges in loop order.
    centred_loops: Vec<Vec<LocalEdge>>,
}

/// Per case (bit `c` set when corner `c` is inside), its triangles.
fn case_table() -> &'static [CaseTriangles; 256] {
    static TABLE: OnceLock<[CaseTriangles; 256]> = OnceLock::new();
    TABLE.get_or_init(|| std::array::from_fn(|case| triangulate_case(case as u8)))
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

fn edge_between(a: u8, b: u8) -> LocalEdge {
    let axis = (a ^ b).trailing_zeros() as u8;
    a.min(b) * 3 + axis
}

/// The triangles of one case, by the rule of the module documentation.
fn triangulate_case(case: u8) -> CaseTriangles {
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
    let mut out = CaseTriangles::default();
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
        let len = ring.len();
        // A fan from ring[s] draws diagonals to every vertex but its two neighbours.
        let fan_start = (0..len).find(|&s| (2..len - 1).all(|k| !share_a_face(ring[s], ring[(s + k) % len])));
        match fan_start {
            Some(s) => {
                for k in 1..len - 1 {
                    out.triangles.push([ring[s], ring[(s + k) % len], ring[(s + k + 1) % len]]);
                }
            }
            None => {
                let centre = CENTRE + out.centred_loops.len() as LocalEdge;
                for k in 0..len {
                    out.triangles.push([centre, ring[k], ring[(k + 1) % len]]);
                }
                out.centred_loops.push(ring);
            }
        }
    }
    out
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
    // Vertex keys: `grid index · 3 + axis` for a grid edge's vertex (below `centre_keys`), and
    // `centre_keys + cell · 4 + k` for the centre of a cell's `k`-th centred loop, `cell` the grid
    // index of the cell's corner 0.
    let centre_keys = count as u64 * 3;
    // Per z layer: the triangles as vertex keys, and the centred loops as (key, ring keys).
    type Layer = (Vec<[u64; 3]>, Vec<(u64, Vec<u64>)>);
    let layers: Vec<Layer> = (0..nz - 1)
        .into_par_iter()
        .map(|z| {
            let mut out = Vec::new();
            let mut centres = Vec::new();
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
                    let cell = corner_index(0) as u64;
                    let key_of = |e: LocalEdge| {
                        if e >= CENTRE {
                            centre_keys + cell * 4 + (e - CENTRE) as u64
                        } else {
                            (corner_index(e / 3) as u64) * 3 + (e % 3) as u64
                        }
                    };
                    let case_triangles = &table[case as usize];
                    out.extend(case_triangles.triangles.iter().map(|tri| tri.map(key_of)));
                    for (k, ring) in case_triangles.centred_loops.iter().enumerate() {
                        centres.push((key_of(CENTRE + k as LocalEdge), ring.iter().map(|&e| key_of(e)).collect()));
                    }
                }
            }
            (out, centres)
        })
        .collect();
    let mut edge_triangles: Vec<[u64; 3]> = Vec::new();
    // In increasing key order: layers in z order, cells in grid order within a layer.
    let mut centred_loops: Vec<(u64, Vec<u64>)> = Vec::new();
    for (triangles, centres) in layers {
        edge_triangles.extend(triangles);
        centred_loops.extend(centres);
    }
    let mut keys: Vec<u64> = edge_triangles.iter().flatten().copied().collect();
    keys.par_sort_unstable();
    keys.dedup();
    let strides = [1usize, nx, nx * ny];
    let edge_vertex = |key: u64| {
        let (p0, axis) = ((key / 3) as usize, (key % 3) as usize);
        let p1 = p0 + strides[axis];
        let (f0, f1) = (field.values[p0], field.values[p1]);
        let t = (f0 / (f0 - f1)).clamp(0.0, 1.0);
        let (x, y, z) = (p0 % nx, (p0 / nx) % ny, p0 / (nx * ny));
        let mut position = field.origin + field.spacing * Vec3::new(x as f32, y as f32, z as f32);
        position[axis] += t * field.spacing;
        let colour: [f32; 3] = field.colours.map_or([0.5; 3], |c| {
            let (c0, c1) = (c[p0], c[p1]);
            std::array::from_fn(|k| c0[k] + t * (c1[k] - c0[k]))
        });
        (position, colour)
    };
    let vertices: Vec<(Vec3, [f32; 3])> = keys
        .par_iter()
        .map(|&key| {
            if key < centre_keys {
                return edge_vertex(key);
            }
            let at = centred_loops.binary_search_by_key(&key, |c| c.0).expect("every centre is listed");
            let ring = &centred_loops[at].1;
            let (mut position, mut colour) = (Vec3::ZERO, [0.0f32; 3]);
            for &edge_key in ring {
                let (p, c) = edge_vertex(edge_key);
                position += p;
                (0..3).for_each(|k| colour[k] += c[k]);
            }
            let share = 1.0 / ring.len() as f32;
            (position * share, colour.map(|c| c * share))
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_case_has_closed_consistent_loops() {
        for case in 0..=255u8 {
            let tris = triangulate_case(case).triangles;
            let crossed = (0..8u8)
                .flat_map(|c| (0..3).filter(move |a| c >> a & 1 == 0).map(move |a| (c, a)))
                .filter(|&(c, a)| (case >> c & 1) != (case >> (c | 1 << a) & 1))
                .count();
            // Every crossed edge is a vertex of some triangle, and nothing else is.
            let mut seen: Vec<u8> = tris.iter().flatten().copied().filter(|&e| e < CENTRE).collect();
            seen.sort_unstable();
            seen.dedup();
            assert_eq!(seen.len(), crossed, "case {case}");
            assert_eq!(case == 0 || case == 255, tris.is_empty());
        }
    }

    #[test]
    fn a_single_inside_corner_gives_one_outward_triangle() {
        let tris = triangulate_case(1).triangles;
        assert_eq!(tris.len(), 1);
        // Edges from corner 0 along x, y, z: 0, 1, 2; the triangle's normal points away from
        // corner 0, i.e. along (1, 1, 1).
        let p = |e: u8| {
            let mut v = Vec3::ZERO;
            v[(e % 3) as usize] = 0.5;
            v
        };
        let [a, b, c] = tris[0].map(p);
        assert!((b - a).cross(c - a).dot(Vec3::ONE) > 0.0);
    }
}
