//! The model's `point_cloud.ply`: binary little-endian float32 vertices with exactly the
//! reference's 60 properties (spec §10.1), in this order:
//! `x y z nx ny nz f_dc_0..2 f_rest_0..44 scale_0 scale_1 rot_0..3` (normals are written as 0).

use super::ModelFileError;
use std::path::Path;

/// Float32 properties per vertex.
pub const PLY_FLOATS: usize = 3 + 3 + 3 + 45 + 2 + 4;

/// Largest header we look for `end_header` in.
const MAX_HEADER: usize = 16 * 1024;

/// The property names, in file order.
pub fn property_names() -> Vec<String> {
    let mut names: Vec<String> = ["x", "y", "z", "nx", "ny", "nz"]
        .iter()
        .map(|s| s.to_string())
        .collect();
    names.extend((0..3).map(|i| format!("f_dc_{i}")));
    names.extend((0..45).map(|i| format!("f_rest_{i}")));
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

/// Parses a model PLY: checks the header (format, one `vertex` element, the exact property
/// list) and the body length, and returns the vertex rows (`PLY_FLOATS` floats each).
pub(crate) fn parse(path: &Path, bytes: &[u8]) -> Result<Vec<f32>, ModelFileError> {
    let bad = |reason: String| ModelFileError::Ply {
        path: path.to_path_buf(),
        reason,
    };
    let window = &bytes[..bytes.len().min(MAX_HEADER)];
    let end = window
        .windows(11)
        .position(|w| w == b"end_header\n")
        .ok_or_else(|| bad("no `end_header` line in the first 16 KiB (not a PLY file, or truncated)".into()))?;
    let body_start = end + 11;
    let text = std::str::from_utf8(&bytes[..end]).map_err(|_| bad("header is not text".into()))?;
    let mut lines = text.lines().map(str::trim_end);
    if lines.next() != Some("ply") {
        return Err(bad("first line is not `ply`".into()));
    }
    let mut count: Option<usize> = None;
    let mut properties = Vec::new();
    let mut format_ok = false;
    for line in lines {
        let words: Vec<&str> = line.split_whitespace().collect();
        match words.as_slice() {
            [] => {}
            ["comment", ..] | ["obj_info", ..] => {}
            ["format", "binary_little_endian", "1.0"] => format_ok = true,
            ["format", other @ ..] => {
                return Err(bad(format!(
                    "format `{}` is not binary_little_endian 1.0",
                    other.join(" ")
                )));
            }
            ["element", "vertex", n] if count.is_none() => {
                count = Some(n.parse().map_err(|_| bad(format!("bad vertex count `{n}`")))?);
            }
            ["element", name, ..] => {
                return Err(bad(format!("unexpected element `{name}` (only `vertex` is allowed)")));
            }
            ["property", ty, name] if count.is_some() => {
                if !matches!(*ty, "float" | "float32") {
                    return Err(bad(format!("property `{name}` has type `{ty}`, expected float")));
                }
                properties.push(name.to_string());
            }
            _ => return Err(bad(format!("unexpected header line `{line}`"))),
        }
    }
    if !format_ok {
        return Err(bad("no `format binary_little_endian 1.0` line".into()));
    }
    let count = count.ok_or_else(|| bad("no `element vertex` line".into()))?;
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
    let body = &bytes[body_start..];
    let need = (count as u128) * (PLY_FLOATS as u128) * 4;
    if body.len() as u128 != need {
        return Err(bad(format!(
            "{} bytes of vertex data for {count} vertices, expected {need}",
            body.len()
        )));
    }
    Ok(body
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect())
}
