//! A small PLY point-cloud reader (for nerfstudio's `ply_file_path`): the field mapping of the
//! `vertex` element onto a [`PointCloud`]; the header and the records are read by [`layout`], the
//! PLY reader the model files share.
//!
//! Reads the `vertex` element of ASCII, binary little-endian and binary big-endian PLY files:
//! positions from the `x y z` properties (any numeric type) and colours from `red green blue`
//! when present (integer types are divided by their maximum, 255 for `uchar`; float colours
//! are taken as they are and clamped to `[0, 1]`). Without colour properties every point is
//! mid-grey `[0.5, 0.5, 0.5]`. Other elements and properties (including lists) are skipped. In
//! ASCII files each element instance must be on its own line.
//!
//! ```
//! use bbsplat::scene::ply::parse_point_cloud;
//! use std::path::Path;
//! let text = "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n\
//!             property float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\n\
//!             end_header\n1 2 3 255 0 51\n";
//! let cloud = parse_point_cloud(text.as_bytes(), Path::new("points.ply")).unwrap();
//! assert_eq!(cloud.positions[0], glam::Vec3::new(1.0, 2.0, 3.0));
//! assert_eq!(cloud.colours[0], [1.0, 0.0, 0.2]);
//! ```

pub mod layout;

use crate::scene::PointCloud;
use crate::scene::error::{Location, SceneError};
use glam::Vec3;
use layout::{PlyError, read_element, read_header};
use std::path::Path;

/// Parses a PLY file's bytes into a point cloud. `file` is only used in error messages.
pub fn parse_point_cloud(bytes: &[u8], file: &Path) -> Result<PointCloud, SceneError> {
    let perr = |e: PlyError| SceneError::parse(file, e.location, e.message);
    let header = read_header(bytes).map_err(perr)?;
    let Some(vi) = header.element("vertex") else {
        return Err(SceneError::parse(file, Location::File, "no vertex element"));
    };
    let vertex = &header.elements[vi];
    let find = |n: &str| vertex.scalar(n);
    let (Some(ix), Some(iy), Some(iz)) = (find("x"), find("y"), find("z")) else {
        return Err(SceneError::parse(
            file,
            Location::File,
            "the vertex element lacks an x, y or z property",
        ));
    };
    let colour = match (find("red"), find("green"), find("blue")) {
        (Some(r), Some(g), Some(b)) => Some([r, g, b]),
        _ => None,
    };
    let mut cloud = PointCloud::default();
    read_element(bytes, &header, vi, |_, values| {
        let p = Vec3::new(values[ix] as f32, values[iy] as f32, values[iz] as f32);
        if !p.is_finite() {
            return Err(format!(
                "position ({}, {}, {}) is not finite",
                values[ix], values[iy], values[iz]
            ));
        }
        cloud.positions.push(p);
        cloud.colours.push(match colour {
            // Integer colours are divided by their type's maximum, float colours taken as they are.
            Some(c) => c.map(|i| {
                let v = values[i] / vertex.properties[i].kind.integer_max();
                if v.is_finite() { v.clamp(0.0, 1.0) as f32 } else { 0.5 }
            }),
            None => [0.5; 3],
        });
        Ok(())
    })
    .map_err(perr)?;
    Ok(cloud)
}
