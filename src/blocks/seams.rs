//! The seam bands of a partition: the ground within a distance of where two cells meet, and
//! the pixels of a view whose surface lies there, for measuring a merged model where its blocks
//! join.
//!
//! Conventions: a ground point's distance to a seam is its distance to the boundary of its own
//! cell ([`Partition::cell_bounds`]; cells are convex, so no other cell's boundary is nearer),
//! the grid's outer sides excluded (they are not seams). A pixel's surface point is the expected
//! depth of a render, `depth / alpha` (view depth, [`crate::raster::RenderOutput::depth`]), put
//! back along the ray through the pixel's centre; a pixel whose accumulated opacity is below
//! [`MIN_ALPHA`] has no surface and is never in a band. Which render gives the depth is the
//! caller's choice: to compare models fairly, the same one for all (`bbsplat blocks seams` uses
//! the chain's coarse model).
//!
//! ```
//! use bbsplat::blocks::{GroundFrame, Partition, distance_to_seam};
//! use glam::{Vec2, Vec3};
//! let frame = GroundFrame { origin: Vec3::ZERO, up: Vec3::Y, along: Vec3::X, across: Vec3::NEG_Z };
//! let points: Vec<Vec2> = (0..8).map(|i| Vec2::new(i as f32, 0.0)).collect();
//! let p = Partition::balanced(frame, &points, 2, 1, 0.25).unwrap(); // one cut, at 3.5
//! assert_eq!(distance_to_seam(&p, Vec2::new(3.0, 9.0)), 0.5);
//! assert_eq!(distance_to_seam(&p, Vec2::new(4.5, -9.0)), 1.0);
//! ```

use super::Partition;
use crate::camera::Camera;
use glam::{Vec2, Vec3};

/// Least accumulated opacity of a pixel with a surface.
pub const MIN_ALPHA: f32 = 0.5;

/// Distance from ground point `q` to the nearest seam between cells (∞ for a single cell).
pub fn distance_to_seam(partition: &Partition, q: Vec2) -> f32 {
    let ((a0, a1), (b0, b1)) = partition.cell_bounds(partition.cell_of(q));
    [q.x - a0, a1 - q.x, q.y - b0, b1 - q.y]
        .into_iter()
        .fold(f32::INFINITY, f32::min)
}

/// The world point seen at the centre of pixel `(column, row)` at view depth `z`.
fn surface_point(camera: &Camera, column: usize, row: usize, z: f32) -> Vec3 {
    let x = (column as f32 + 0.5 - camera.cx) / camera.fx * z;
    let y = (row as f32 + 0.5 - camera.cy) / camera.fy * z;
    camera.rotation.transpose() * (Vec3::new(x, y, z) - camera.translation)
}

/// Per pixel of `camera`'s view (row-major): 255 where the surface of a render (its `alpha`
/// and alpha-weighted `depth` images) lies within `width` of a seam of `partition`, else 0
/// ([module documentation](self)).
///
/// # Panics
/// When `alpha` or `depth` does not hold one value per pixel.
pub fn seam_band_mask(partition: &Partition, camera: &Camera, alpha: &[f32], depth: &[f32], width: f32) -> Vec<u8> {
    let (w, h) = (camera.width as usize, camera.height as usize);
    assert!(
        alpha.len() == w * h && depth.len() == w * h,
        "one alpha and one depth per pixel"
    );
    let mut mask = vec![0u8; w * h];
    for row in 0..h {
        for column in 0..w {
            let k = row * w + column;
            if alpha[k] < MIN_ALPHA {
                continue;
            }
            let p = surface_point(camera, column, row, depth[k] / alpha[k]);
            if distance_to_seam(partition, partition.frame.project(p)) < width {
                mask[k] = 255;
            }
        }
    }
    mask
}
