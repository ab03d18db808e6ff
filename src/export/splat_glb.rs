//! The Gaussians ([`super::gaussians`]) as a glTF 2.0 binary with the `KHR_gaussian_splatting`
//! extension (Khronos, Review Draft), and the dataset's cameras.
//!
//! One mesh with one primitive in `POINTS` mode (`mode: 0`), so that a client without the
//! extension draws a point cloud (the extension's fallback; it is listed in `extensionsUsed`
//! only, not `extensionsRequired`). Attributes, all `float` accessors of one Gaussian each, in one
//! buffer view per attribute:
//! - `POSITION` (VEC3, with `min`/`max`): the means, in the dataset's world frame;
//! - `COLOR_0` (VEC4): the fallback colour, the degree-0 colour `clamp(SH_C0·f_dc + 0.5, 0, 1)`
//!   (as stored, no transfer function), alpha = opacity;
//! - `KHR_gaussian_splatting:ROTATION` (VEC4): the unit quaternion `(x, y, z, w)`, local → world;
//! - `KHR_gaussian_splatting:SCALE` (VEC3): the standard deviations, **linear** (the extension's
//!   text said log-space until KhronosGroup/glTF issue 2563 made them linear and non-negative;
//!   Babylon.js's loader reads them linear);
//! - `KHR_gaussian_splatting:OPACITY` (SCALAR): the peak opacity in `[0, 1]`;
//! - `KHR_gaussian_splatting:SH_DEGREE_0_COEF_0` (VEC3, RGB) and, for each degree `1 ≤ ℓ ≤` the
//!   model's, `KHR_gaussian_splatting:SH_DEGREE_ℓ_COEF_n` for `n = 0 … 2ℓ` (VEC3, RGB): basis
//!   function `k = ℓ² + n` of [`crate::stages::sh`] (`m = n − ℓ`; the extension's basis, with the
//!   Condon–Shortley phase, is the 3DGS one the crate uses).
//!
//! The primitive's extension object: `kernel: "ellipse"`, `colorSpace: "srgb_rec709_display"`
//! (the colours are what the renderer blends, 8-bit display values), `sortingMethod:
//! "cameraDistance"`, `projection: "perspective"`. Cameras are nodes as in [`super::glb`].

use super::ExportError;
use super::gaussians::GaussianSet;
use super::glb::{ARRAY_BUFFER, FLOAT, NamedCamera, camera_node, glb_container, pad_to_4};
use crate::stages::sh::sh_to_rgb;
use glam::Vec3;
use serde_json::{Value, json};
use std::path::Path;

/// The extension's name.
pub const EXTENSION: &str = "KHR_gaussian_splatting";

/// The attribute names of the SH coefficients up to `degree`, in basis-function order `k`.
///
/// ```
/// use bbsplat::export::splat_glb::sh_attribute_names;
/// let names = sh_attribute_names(1);
/// assert_eq!(names[0], "KHR_gaussian_splatting:SH_DEGREE_0_COEF_0");
/// assert_eq!(names[3], "KHR_gaussian_splatting:SH_DEGREE_1_COEF_2");
/// assert_eq!(sh_attribute_names(3).len(), 16);
/// ```
pub fn sh_attribute_names(degree: u32) -> Vec<String> {
    (0..=degree)
        .flat_map(|l| (0..=2 * l).map(move |n| format!("{EXTENSION}:SH_DEGREE_{l}_COEF_{n}")))
        .collect()
}

/// Appends the floats `values` to `bin` and records a buffer view and a float accessor of
/// `count` elements of `kind`; returns the accessor's index.
fn push_attribute(
    bin: &mut Vec<u8>,
    views: &mut Vec<Value>,
    accessors: &mut Vec<Value>,
    values: impl IntoIterator<Item = f32>,
    count: usize,
    kind: &str,
) -> usize {
    let offset = bin.len();
    for v in values {
        bin.extend_from_slice(&v.to_le_bytes());
    }
    views.push(json!({"buffer": 0, "byteOffset": offset, "byteLength": bin.len() - offset, "target": ARRAY_BUFFER}));
    accessors.push(json!({"bufferView": views.len() - 1, "componentType": FLOAT, "count": count, "type": kind}));
    accessors.len() - 1
}

/// The `.glb` bytes of `set` with `cameras`; `background` is recorded in the scene's extras.
pub fn splat_glb_bytes(set: &GaussianSet, cameras: &[NamedCamera<'_>], background: Vec3) -> Vec<u8> {
    let n = set.len();
    let mut bin = Vec::new();
    let (mut views, mut accessors) = (Vec::new(), Vec::new());
    let mut attributes = serde_json::Map::new();
    let position = push_attribute(
        &mut bin,
        &mut views,
        &mut accessors,
        set.positions.iter().flat_map(|p| p.to_array()),
        n,
        "VEC3",
    );
    let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
    for p in &set.positions {
        lo = lo.min(*p);
        hi = hi.max(*p);
    }
    if n > 0 {
        accessors[position]["min"] = json!(lo.to_array());
        accessors[position]["max"] = json!(hi.to_array());
    }
    attributes.insert("POSITION".into(), json!(position));
    let colours = (0..n).flat_map(|i| {
        let sh = set.sh_of(i);
        let c = |ch: usize| sh_to_rgb(sh[ch]).clamp(0.0, 1.0);
        [c(0), c(1), c(2), set.opacities[i]]
    });
    let colour = push_attribute(&mut bin, &mut views, &mut accessors, colours, n, "VEC4");
    attributes.insert("COLOR_0".into(), json!(colour));
    let rotations = set.rotations.iter().flat_map(|q| [q.x, q.y, q.z, q.w]);
    let rotation = push_attribute(&mut bin, &mut views, &mut accessors, rotations, n, "VEC4");
    attributes.insert(format!("{EXTENSION}:ROTATION"), json!(rotation));
    let scales = set.scales.iter().flat_map(|s| s.to_array());
    let scale = push_attribute(&mut bin, &mut views, &mut accessors, scales, n, "VEC3");
    attributes.insert(format!("{EXTENSION}:SCALE"), json!(scale));
    let opacity = push_attribute(
        &mut bin,
        &mut views,
        &mut accessors,
        set.opacities.iter().copied(),
        n,
        "SCALAR",
    );
    attributes.insert(format!("{EXTENSION}:OPACITY"), json!(opacity));
    for (k, name) in sh_attribute_names(set.sh_degree).into_iter().enumerate() {
        let coeffs = (0..n).flat_map(|i| {
            let sh = set.sh_of(i);
            [sh[3 * k], sh[3 * k + 1], sh[3 * k + 2]]
        });
        let index = push_attribute(&mut bin, &mut views, &mut accessors, coeffs, n, "VEC3");
        attributes.insert(name, json!(index));
    }
    pad_to_4(&mut bin, 0);

    let (gl_cameras, camera_nodes): (Vec<Value>, Vec<Value>) =
        cameras.iter().enumerate().map(|(i, c)| camera_node(c, i)).unzip();
    let mut nodes = vec![json!({"name": "gaussians", "mesh": 0})];
    nodes.extend(camera_nodes);
    let node_indices: Vec<usize> = (0..nodes.len()).collect();
    let mut doc = json!({
        "asset": {"version": "2.0", "generator": concat!("bbsplat ", env!("CARGO_PKG_VERSION"))},
        "extensionsUsed": [EXTENSION],
        "scene": 0,
        "scenes": [{"name": "bbsplat", "nodes": node_indices,
                    "extras": {"background": background.to_array(), "gaussians": n,
                               "billboards": set.per_billboard.len()}}],
        "nodes": nodes,
        "meshes": [{"name": "gaussians", "primitives": [{
            "attributes": Value::Object(attributes),
            "mode": 0,
            "extensions": {EXTENSION: {
                "kernel": "ellipse",
                "colorSpace": "srgb_rec709_display",
                "sortingMethod": "cameraDistance",
                "projection": "perspective"
            }}
        }]}],
        "buffers": [{"byteLength": bin.len()}],
        "bufferViews": views,
        "accessors": accessors,
    });
    if !gl_cameras.is_empty() {
        doc["cameras"] = Value::Array(gl_cameras);
    }
    glb_container(&doc, &bin)
}

/// Writes [`splat_glb_bytes`] to `path` (atomically, [`super::write_file`]); returns the size.
pub fn write_splat_glb(
    path: &Path,
    set: &GaussianSet,
    cameras: &[NamedCamera<'_>],
    background: Vec3,
) -> Result<u64, ExportError> {
    let bytes = splat_glb_bytes(set, cameras, background);
    super::write_file(path, &bytes)?;
    Ok(bytes.len() as u64)
}
