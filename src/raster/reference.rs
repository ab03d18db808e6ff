//! A plain brute-force reference renderer: every pixel against every billboard.
//!
//! No screen boxes, no tiles, no parallelism: each pixel composites, with the
//! [`crate::stages::composite::composite`] stage, all non-culled billboards sorted by centre view
//! depth (ties by index), exactly the order the tiled renderer uses within a tile. The tiled
//! renderer is tested against it; any contribution lost to binning or per-pixel culling shows
//! up as a difference.

use super::input::{ActivatedRef, RenderSettings, planar_textures};
use crate::camera::Camera;
use crate::stages::bilinear;
use crate::stages::composite::composite;
use crate::stages::depth_distortion::mapped_depth;
use crate::stages::ray_plane::{ViewPlane, intersect_with, pixel_ray};
use crate::stages::sh::sh_colour;
use crate::stages::splat_transform::{splat_frame, view_plane};

/// Output of the reference renderer.
#[derive(Clone, Debug, PartialEq)]
pub struct ReferenceOutput {
    /// Colour, interleaved RGB row-major.
    pub rgb: Vec<f32>,
    /// `1 − T_final` per pixel (as `Σ α·T`).
    pub alpha: Vec<f32>,
    /// Alpha-weighted depth per pixel.
    pub depth: Vec<f32>,
    /// Alpha-weighted facing view-space normal per pixel, interleaved xyz.
    pub normal: Vec<f32>,
    /// Depth distortion per pixel, as the pairwise sum `Σ_i Σ_{j<i} w_i w_j (m_i − m_j)²` of
    /// the blended entries' weights and mapped depths ([`mapped_depth`]), not the running
    /// formula of the rasterizer; computed whatever [`RenderSettings::distortion`] says.
    pub distortion: Vec<f32>,
    /// Per billboard `Σ α·T` over all pixels.
    pub impact: Vec<f32>,
}

/// Renders with the brute-force method. `O(pixels · billboards)`: for tests on small scenes.
pub fn render_reference(set: &ActivatedRef<'_>, camera: &Camera, settings: &RenderSettings) -> ReferenceOutput {
    set.assert_consistent();
    let n_pix = camera.pixel_count();
    let ts = set.texture_size;
    let mut order: Vec<(usize, f32)> = Vec::new();
    let mut projected = Vec::with_capacity(set.len());
    for b in 0..set.len() {
        let p = splat_frame(set.positions[b], set.log_scales[b], set.quaternions[b], camera).map(|f| {
            let (normal, offset) = view_plane(set.positions[b], set.quaternions[b], camera, f.normal_sign);
            let plane = ViewPlane { normal, offset };
            (f, plane)
        });
        if let Some((f, _)) = &p {
            order.push((b, f.view_depth));
        }
        projected.push(p);
    }
    order.sort_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
    // Planar copies of the RGBA textures, sampled with the planar bilinear stage (independent of
    // the rasterizer's RGBA path): alpha `[texel]`, colour `[channel][texel]`.
    let (alpha_planes, colour_planes): (Vec<Vec<f32>>, Vec<Vec<f32>>) = (0..set.len())
        .map(|b| planar_textures(set.texture_of(b), set.texels()))
        .unzip();
    let sh_rgb: Vec<_> = (0..set.len())
        .map(|b| sh_colour(settings.sh_degree, set.sh_of(b), camera.view_offset(set.positions[b])).rgb)
        .collect();
    let mut out = ReferenceOutput {
        rgb: vec![0.0; 3 * n_pix],
        alpha: vec![0.0; n_pix],
        depth: vec![0.0; n_pix],
        normal: vec![0.0; 3 * n_pix],
        distortion: vec![0.0; n_pix],
        impact: vec![0.0; set.len()],
    };
    // Features per entry: r, g, b, 1 (opacity), depth, normal; background (bg, 0, 0, 0).
    let background = [
        settings.background.x,
        settings.background.y,
        settings.background.z,
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
    ];
    let mut alphas = Vec::new();
    let mut features = Vec::new();
    let mut ids = Vec::new();
    let mut depths = Vec::new();
    for j in 0..camera.height {
        for i in 0..camera.width {
            let (px, py) = (i as f32 + 0.5, j as f32 + 0.5);
            alphas.clear();
            features.clear();
            ids.clear();
            depths.clear();
            for &(b, _) in &order {
                let (p, plane) = projected[b].as_ref().expect("sorted billboards are projected");
                let ray = pixel_ray(camera, px, py);
                let Some(hit) = intersect_with(&p.transform, px, py, |_, _| plane.depth(ray)) else {
                    continue;
                };
                let mut a = [0.0f32];
                bilinear::sample(&alpha_planes[b], ts, 1, hit.u, hit.v, &mut a);
                let mut c = [0.0f32; 3];
                bilinear::sample(&colour_planes[b], ts, 3, hit.u, hit.v, &mut c);
                alphas.push(a[0]);
                features.extend_from_slice(&[
                    c[0] + sh_rgb[b].x,
                    c[1] + sh_rgb[b].y,
                    c[2] + sh_rgb[b].z,
                    1.0,
                    hit.depth,
                    plane.normal.x,
                    plane.normal.y,
                    plane.normal.z,
                ]);
                ids.push(b);
                depths.push(hit.depth);
            }
            let r = composite(&alphas, &features, 8, &background, &settings.composite);
            let pix = (j * camera.width + i) as usize;
            out.rgb[3 * pix..3 * pix + 3].copy_from_slice(&r.features[..3]);
            out.alpha[pix] = r.features[3];
            out.depth[pix] = r.features[4];
            out.normal[3 * pix..3 * pix + 3].copy_from_slice(&r.features[5..8]);
            let mut distortion = 0.0f64;
            for i in 0..ids.len() {
                for j in 0..i {
                    let dm = f64::from(mapped_depth(depths[i])) - f64::from(mapped_depth(depths[j]));
                    distortion += f64::from(r.weights[i]) * f64::from(r.weights[j]) * dm * dm;
                }
            }
            out.distortion[pix] = distortion as f32;
            for (k, &b) in ids.iter().enumerate() {
                out.impact[b] += r.weights[k];
            }
        }
    }
    out
}
