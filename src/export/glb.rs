//! glTF 2.0 binary (`.glb`) of the plane mesh and the dataset's cameras.
//!
//! One mesh (one primitive: `POSITION`, `TEXCOORD_0`, `u32` indices, two triangles per quad as
//! in [`super::planes`]), one material (`baseColorTexture` = the atlas PNG embedded in the
//! buffer, alpha in its A channel, `alphaMode: BLEND`, `doubleSided`, metallic 0, roughness 1,
//! `KHR_materials_unlit` so lighting does not change colours), a linear, non-mipmapped, clamped
//! sampler (mipmaps would bleed neighbouring tiles). Texture coordinates are the OBJ ones with
//! `t ↦ 1 − t` (glTF's origin is the image's top-left); the PNG is the same flipped atlas.
//!
//! Positions are in the dataset's world frame, unchanged. Each dataset camera becomes a node with
//! a perspective camera: translation = camera centre, rotation = camera-to-world rotation with
//! the y and z axes negated (OpenCV x right, y down, looking along +z → glTF y up, looking along
//! −z), `yfov = 2·atan(H / 2fy)`, `aspectRatio = W·fy / (H·fx)` (so the horizontal field of view
//! is `2·atan(W / 2fx)`), `znear = 0.2` (the renderer's near plane). glTF has no principal point:
//! the node's `extras` keep `width`, `height`, `fx`, `fy`, `cx`, `cy` for tools that can use them
//! (`tools/blender_check.py` sets Blender's lens shift from them). The scene's `extras` hold the
//! model's `background` colour.

use super::ExportError;
use super::atlas::encode_png;
use super::planes::{PlaneMesh, QUAD_TRIANGLES};
use crate::camera::Camera;
use glam::{Mat3, Quat, Vec3};
use serde_json::{Value, json};
use std::path::Path;

/// A dataset camera to export, with its name.
#[derive(Clone, Copy, Debug)]
pub struct NamedCamera<'a> {
    /// The view's name (the node's name).
    pub name: &'a str,
    /// The camera.
    pub camera: &'a Camera,
}

const GLB_MAGIC: u32 = 0x4654_6C67; // "glTF"
const CHUNK_JSON: u32 = 0x4E4F_534A; // "JSON"
const CHUNK_BIN: u32 = 0x004E_4942; // "BIN\0"
pub(crate) const FLOAT: u32 = 5126;
const UNSIGNED_INT: u32 = 5125;
pub(crate) const ARRAY_BUFFER: u32 = 34962;
const ELEMENT_ARRAY_BUFFER: u32 = 34963;
const LINEAR: u32 = 9729;
const CLAMP_TO_EDGE: u32 = 33071;

/// The near plane of the exported cameras (the renderer's, spec §3.5).
pub const CAMERA_ZNEAR: f32 = 0.2;

/// The glTF node rotation of `camera`: its camera-to-world rotation with the y and z axes negated.
///
/// ```
/// use bbsplat::camera::Camera;
/// use bbsplat::export::glb::gltf_camera_rotation;
/// use glam::Vec3;
/// // A camera looking along world −z with y up (glTF's identity) has the identity rotation.
/// let cam = Camera::look_at(Vec3::ZERO, Vec3::new(0.0, 0.0, -1.0), Vec3::Y, 100.0, 100.0, 64, 64);
/// let q = gltf_camera_rotation(&cam);
/// assert!(q.angle_between(glam::Quat::IDENTITY) < 1e-5);
/// ```
pub fn gltf_camera_rotation(camera: &Camera) -> Quat {
    let c2w = camera.rotation.transpose();
    let g = Mat3::from_cols(c2w.x_axis, -c2w.y_axis, -c2w.z_axis);
    Quat::from_mat3(&g).normalize()
}

/// Pads `bytes` with `fill` to a multiple of 4 bytes (glTF's chunk and buffer-view alignment).
pub(crate) fn pad_to_4(bytes: &mut Vec<u8>, fill: u8) {
    while !bytes.len().is_multiple_of(4) {
        bytes.push(fill);
    }
}

/// The glTF camera and its node for dataset camera `c`, camera index `index` (module docs).
pub(crate) fn camera_node(c: &NamedCamera<'_>, index: usize) -> (Value, Value) {
    let cam = c.camera;
    let (w, h) = (cam.width as f32, cam.height as f32);
    let camera = json!({
        "name": c.name,
        "type": "perspective",
        "perspective": {
            "yfov": 2.0 * (h / (2.0 * cam.fy)).atan(),
            "aspectRatio": w * cam.fy / (h * cam.fx),
            "znear": CAMERA_ZNEAR,
        }
    });
    let q = gltf_camera_rotation(cam);
    let t = cam.centre();
    let node = json!({
        "name": c.name,
        "camera": index,
        "translation": [t.x, t.y, t.z],
        "rotation": [q.x, q.y, q.z, q.w],
        "extras": {
            "width": cam.width, "height": cam.height,
            "fx": cam.fx, "fy": cam.fy, "cx": cam.cx, "cy": cam.cy,
        }
    });
    (camera, node)
}

/// The `.glb` bytes of `mesh` with `cameras`; `background` is recorded in the scene's extras.
pub fn glb_bytes(mesh: &PlaneMesh, cameras: &[NamedCamera<'_>], background: Vec3) -> Result<Vec<u8>, ExportError> {
    let quads = mesh.corners.len();
    let mut bin = Vec::new();
    // Positions.
    let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
    for p in mesh.corners.iter().flatten() {
        lo = lo.min(*p);
        hi = hi.max(*p);
        for x in p.to_array() {
            bin.extend_from_slice(&x.to_le_bytes());
        }
    }
    let positions_len = bin.len();
    // Texture coordinates, glTF origin at the top.
    let uv_offset = bin.len();
    for t in mesh.uvs.iter().flatten() {
        bin.extend_from_slice(&t.x.to_le_bytes());
        bin.extend_from_slice(&(1.0 - t.y).to_le_bytes());
    }
    let uv_len = bin.len() - uv_offset;
    // Indices.
    let index_offset = bin.len();
    for k in 0..quads as u32 {
        for tri in QUAD_TRIANGLES {
            for j in tri {
                bin.extend_from_slice(&(4 * k + j).to_le_bytes());
            }
        }
    }
    let index_len = bin.len() - index_offset;
    // The atlas.
    let image_offset = bin.len();
    let png = encode_png(&mesh.atlas)?;
    bin.extend_from_slice(&png);
    let image_len = png.len();
    pad_to_4(&mut bin, 0);

    let (gl_cameras, camera_nodes): (Vec<Value>, Vec<Value>) =
        cameras.iter().enumerate().map(|(i, c)| camera_node(c, i)).unzip();
    let mut nodes = vec![json!({"name": "billboards", "mesh": 0})];
    nodes.extend(camera_nodes);
    let node_indices: Vec<usize> = (0..nodes.len()).collect();
    let mut doc = json!({
        "asset": {"version": "2.0", "generator": concat!("bbsplat ", env!("CARGO_PKG_VERSION"))},
        "extensionsUsed": ["KHR_materials_unlit"],
        "scene": 0,
        "scenes": [{"name": "bbsplat", "nodes": node_indices,
                    "extras": {"background": background.to_array(), "billboards": quads}}],
        "nodes": nodes,
        "meshes": [{"name": "billboards", "primitives": [{
            "attributes": {"POSITION": 0, "TEXCOORD_0": 1},
            "indices": 2,
            "material": 0,
            "mode": 4
        }]}],
        "materials": [{
            "name": "billboards",
            "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}, "metallicFactor": 0.0, "roughnessFactor": 1.0},
            "alphaMode": "BLEND",
            "doubleSided": true,
            "extensions": {"KHR_materials_unlit": {}}
        }],
        "textures": [{"sampler": 0, "source": 0}],
        "samplers": [{"magFilter": LINEAR, "minFilter": LINEAR, "wrapS": CLAMP_TO_EDGE, "wrapT": CLAMP_TO_EDGE}],
        "images": [{"name": "atlas", "bufferView": 3, "mimeType": "image/png"}],
        "buffers": [{"byteLength": bin.len()}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": positions_len, "target": ARRAY_BUFFER},
            {"buffer": 0, "byteOffset": uv_offset, "byteLength": uv_len, "target": ARRAY_BUFFER},
            {"buffer": 0, "byteOffset": index_offset, "byteLength": index_len, "target": ELEMENT_ARRAY_BUFFER},
            {"buffer": 0, "byteOffset": image_offset, "byteLength": image_len}
        ],
        "accessors": [
            {"bufferView": 0, "componentType": FLOAT, "count": 4 * quads, "type": "VEC3",
             "min": lo.to_array(), "max": hi.to_array()},
            {"bufferView": 1, "componentType": FLOAT, "count": 4 * quads, "type": "VEC2"},
            {"bufferView": 2, "componentType": UNSIGNED_INT, "count": 6 * quads, "type": "SCALAR"}
        ]
    });
    if !gl_cameras.is_empty() {
        doc["cameras"] = Value::Array(gl_cameras);
    }
    Ok(glb_container(&doc, &bin))
}

/// The GLB container of the JSON document `doc` and the binary buffer `bin` (already padded to 4
/// bytes): the 12-byte header, the JSON chunk (padded with spaces), the BIN chunk.
pub(crate) fn glb_container(doc: &Value, bin: &[u8]) -> Vec<u8> {
    let mut json_bytes = serde_json::to_vec(doc).expect("a JSON value always serialises");
    pad_to_4(&mut json_bytes, b' ');

    let total = 12 + 8 + json_bytes.len() + 8 + bin.len();
    let mut out = Vec::with_capacity(total);
    for word in [GLB_MAGIC, 2, total as u32, json_bytes.len() as u32, CHUNK_JSON] {
        out.extend_from_slice(&word.to_le_bytes());
    }
    out.extend_from_slice(&json_bytes);
    for word in [bin.len() as u32, CHUNK_BIN] {
        out.extend_from_slice(&word.to_le_bytes());
    }
    out.extend_from_slice(bin);
    out
}

/// Writes [`glb_bytes`] to `path`; returns the size written.
pub fn write_glb(
    path: &Path,
    mesh: &PlaneMesh,
    cameras: &[NamedCamera<'_>],
    background: Vec3,
) -> Result<u64, ExportError> {
    let bytes = glb_bytes(mesh, cameras, background)?;
    super::write_file(path, &bytes)?;
    Ok(bytes.len() as u64)
}
