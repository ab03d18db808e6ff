//! The self-contained WebGL2 viewer page of `bbsplat view`: one HTML file with the model and the
//! dataset cameras embedded (base64), no network access and no JavaScript dependency.
//!
//! What the page draws is what the renderer computes (spec §3), up to floating point: every
//! billboard is a quad covering its texture's support `|u|, |v| ≤ 1 + 2/(TS − 1)`; the fragment
//! shader samples both textures align-corners with zero padding (spec §3.4) by `texelFetch`,
//! takes `alpha = min(0.99, a)`, skips `alpha < 1/255` and hits nearer than 0.2, and adds the
//! view-dependent SH colour (evaluated per billboard on the CPU each frame, degree of the model);
//! billboards whose centre is nearer than 0.2 are culled. The planes are sorted by centre view
//! depth every frame and blended back to front (premultiplied, into a half-float target when the
//! browser can render to one) over the model's background: the same order as the renderer's
//! per-tile front-to-back lists. Differences: the renderer stops a pixel at transmittance
//! `< 1e-4`, and the page's framebuffer rounds.
//!
//! The page reads `#camera=K` from its URL to start at dataset camera `K` with the canvas at that
//! camera's size (as the browser test does).

use super::ExportError;
use super::orbit::look_target;
use crate::camera::Camera;
use crate::loss::psnr::quantize_u8;
use crate::raster::ActivatedRef;
use crate::stages::rotation::quat_to_rotation;
use crate::stages::sh::sh_coeff_count;
use glam::Vec3;
use serde_json::json;
use std::path::Path;

/// The page template; `/*BBSPLAT_DATA*/` is replaced by the model's JSON.
const TEMPLATE: &str = include_str!("viewer.html");
const DATA_MARK: &str = "/*BBSPLAT_DATA*/";

/// Standard base64 (RFC 4648, with padding).
///
/// ```
/// use bbsplat::export::viewer::base64;
/// assert_eq!(base64(b"Man"), "TWFu");
/// assert_eq!(base64(b"Ma"), "TWE=");
/// assert_eq!(base64(b"M"), "TQ==");
/// assert_eq!(base64(b""), "");
/// ```
pub fn base64(bytes: &[u8]) -> String {
    const ALPHABET: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for chunk in bytes.chunks(3) {
        let b = [chunk[0], *chunk.get(1).unwrap_or(&0), *chunk.get(2).unwrap_or(&0)];
        let n = (u32::from(b[0]) << 16) | (u32::from(b[1]) << 8) | u32::from(b[2]);
        for k in 0..4 {
            if k <= chunk.len() {
                out.push(ALPHABET[((n >> (18 - 6 * k)) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

fn f32_base64(values: impl IntoIterator<Item = f32>) -> String {
    let bytes: Vec<u8> = values.into_iter().flat_map(f32::to_le_bytes).collect();
    base64(&bytes)
}

/// A dataset camera shown by the viewer.
#[derive(Clone, Copy, Debug)]
pub struct ViewerCamera<'a> {
    /// The view's name.
    pub name: &'a str,
    /// The camera.
    pub camera: &'a Camera,
}

/// The model and cameras the viewer page embeds, as JSON (what `bbsplat train --view` serves as
/// `/model`; the page's `loadModel` reads it): `count`, `texture_size`, `sh_degree` (at most 3),
/// `background` (linear RGB in 0-1), `target` (world point the orbit turns about), base64
/// little-endian `f32` arrays `positions` (3 per billboard), `axes` (the scaled u then v axes, 6),
/// `sh` (3 per coefficient), 8-bit RGBA `textures` (row-major TS×TS per billboard) and `cameras`
/// (world-to-camera rotation rows, translation, pinhole intrinsics in pixels).
///
/// ```
/// use bbsplat::billboards::ActivatedBillboards;
/// let set = ActivatedBillboards::empty(4);
/// let json = bbsplat::export::viewer::viewer_data(&set.borrowed(), 0, glam::Vec3::ONE, &[]);
/// let data: serde_json::Value = serde_json::from_str(&json).unwrap();
/// assert_eq!(data["count"], 0);
/// assert_eq!(data["texture_size"], 4);
/// ```
pub fn viewer_data(set: &ActivatedRef<'_>, sh_degree: u32, background: Vec3, cameras: &[ViewerCamera<'_>]) -> String {
    let n = set.len();
    let positions = f32_base64(set.positions.iter().flat_map(|p| p.to_array()));
    let axes = f32_base64((0..n).flat_map(|i| {
        let r = quat_to_rotation(set.quaternions[i]);
        let s = set.log_scales[i];
        let (u, v) = (r.x_axis * s.x.exp(), r.y_axis * s.y.exp());
        [u.x, u.y, u.z, v.x, v.y, v.z]
    }));
    let degree = sh_degree.min(3);
    let floats = 3 * sh_coeff_count(degree);
    let sh = f32_base64((0..n).flat_map(|i| set.sh_of(i)[..floats].to_vec()));
    let textures: Vec<u8> = set.textures.iter().flat_map(|t| t.map(quantize_u8)).collect();
    let all_cameras: Vec<Camera> = cameras.iter().map(|c| *c.camera).collect();
    let target = look_target(&all_cameras).unwrap_or(Vec3::ZERO);
    let cams: Vec<_> = cameras
        .iter()
        .map(|c| {
            let m = c.camera.rotation;
            json!({
                "name": c.name,
                "rotation": [m.row(0).to_array(), m.row(1).to_array(), m.row(2).to_array()],
                "translation": c.camera.translation.to_array(),
                "fx": c.camera.fx, "fy": c.camera.fy, "cx": c.camera.cx, "cy": c.camera.cy,
                "width": c.camera.width, "height": c.camera.height,
            })
        })
        .collect();
    let data = json!({
        "count": n,
        "texture_size": set.texture_size,
        "sh_degree": degree,
        "background": background.to_array(),
        "target": target.to_array(),
        "positions": positions,
        "axes": axes,
        "sh": sh,
        "textures": base64(&textures),
        "cameras": cams,
    });
    data.to_string()
}

/// The page around `data` (a [`viewer_data`] JSON text).
pub fn page_of_data(data: &str) -> String {
    // `</` inside a script element would end it early.
    TEMPLATE.replacen(DATA_MARK, &data.replace("</", "<\\/"), 1)
}

/// The viewer page of `set` (SH evaluated up to `sh_degree`) over `background`, with `cameras`.
pub fn viewer_html(set: &ActivatedRef<'_>, sh_degree: u32, background: Vec3, cameras: &[ViewerCamera<'_>]) -> String {
    page_of_data(&viewer_data(set, sh_degree, background, cameras))
}

/// Writes [`viewer_html`] to `path`; returns the size written.
pub fn write_viewer(
    path: &Path,
    set: &ActivatedRef<'_>,
    sh_degree: u32,
    background: Vec3,
    cameras: &[ViewerCamera<'_>],
) -> Result<u64, ExportError> {
    let html = viewer_html(set, sh_degree, background, cameras);
    super::write_file(path, html.as_bytes())?;
    Ok(html.len() as u64)
}
