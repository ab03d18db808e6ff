//! The model's `point_cloud.ply`: binary little-endian float32 vertices with exactly the
//! reference's 60 properties (spec §10.1), in this order:
//! `x y z nx ny nz f_dc_0..2 f_rest_0..44 scale_0 scale_1 rot_0..3` (normals are written as 0).

use super::ModelFileError;
use crate::scene::Location;
use crate::scene::ply::layout::{Encoding, Scalar, read_header};
use std::path::Path;

/// Float32 properties per vertex.
pub const PLY_FLOATS: usize = 3 + 3 + 3 + 45 + 2 + 4;

/// The property names, in file order.
pub fn property_names() -> Vec<String> {
    let mut names = crate::stages::sh::ply_position_and_sh_names();
    names.extend((0..2).map(|i| format!("scale_{i}")));
    names.extend((0..4).map(|i| format!("rot_{i}")));
    names
}

/// The header for `count` vertices (as `plyfile` writes it).
pub(crate) fn header(count: usize) -> String {
    let mut h = format!("ply\nformat binary_little_endian 1.0\nelement vertex {count}\n");
    for name in property_names() {
        h.push_str(&format!("property float {name}\n"));
    }
    h.push_str("end_header\n");
    h
}

/// Bytes of the header written for `count` vertices (the file is this plus `240·count`).
pub fn header_len(count: usize) -> usize {
    header(count).len()
}

/// Parses a model PLY: reads the header with the crate's PLY reader
/// ([`crate::scene::ply::layout`]), checks it (format, one `vertex` element, the exact float
/// property list) and the body length, and returns the vertex rows (`PLY_FLOATS` floats each).
pub(crate) fn parse(path: &Path, bytes: &[u8]) -> Result<Vec<f32>, ModelFileError> {
    let bad = |reason: String| ModelFileError::Ply {
        path: path.to_path_buf(),
        reason,
    };
    let header = read_header(bytes).map_err(|e| match e.location {
        Location::File => bad(e.message),
        at => bad(format!("{at}: {}", e.message)),
    })?;
    if header.encoding != Encoding::BinaryLittleEndian || header.version != "1.0" {
        return Err(bad(format!(
            "format `{} {}` is not binary_little_endian 1.0",
            header.encoding.name(),
            header.version
        )));
    }
    let vertex = match header.elements.as_slice() {
        [] => return Err(bad("no `element vertex` line".into())),
        [vertex] if vertex.name == "vertex" => vertex,
        elements => {
            let other = elements.iter().find(|e| e.name != "vertex").unwrap_or(&elements[1]);
            return Err(bad(format!(
                "unexpected element `{}` (only one `vertex` element is allowed)",
                other.name
            )));
        }
    };
    if let Some(p) = vertex
        .properties
        .iter()
        .find(|p| p.list.is_some() || p.kind != Scalar::F32)
    {
        let ty = match p.list {
            Some(_) => "list",
            None => p.kind.name(),
        };
        return Err(bad(format!("property `{}` has type `{ty}`, expected float", p.name)));
    }
    let properties: Vec<&str> = vertex.properties.iter().map(|p| p.name.as_str()).collect();
    let expected = property_names();
    if properties != expected {
        let first = properties
            .iter()
            .zip(&expected)
            .position(|(a, b)| a != b)
            .unwrap_or(properties.len().min(expected.len()));
        return Err(bad(format!(
            "vertex properties differ from the expected {} ({}): at position {first} found {:?}, expected {:?} \
             (BBSplat models have no opacity field)",
            expected.len(),
            "x y z nx ny nz f_dc_0..2 f_rest_0..44 scale_0..1 rot_0..3",
            properties.get(first),
            expected.get(first)
        )));
    }
    let count = vertex.count;
    let body = &bytes[header.body_start..];
    let need = (count as u128) * (PLY_FLOATS as u128) * 4;
    if body.len() as u128 != need {
        return Err(bad(format!(
            "{} bytes of vertex data for {count} vertices, expected {need}",
            body.len()
        )));
    }
    // Every property is a little-endian float32 (checked above): the rows are the body's floats.
    Ok(body
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect())
}
