//! An independent 3D Gaussian Splatting renderer (f64), written from the 3DGS paper's method and
//! the Inria PLY layout, sharing no code with the crate: it checks the Gaussians that
//! `bbsplat export --format splat-ply|gltf-splat` writes against `bbsplat render` of the
//! billboards.
//!
//! The standard EWA splatting forward pass, as the Inria rasterizer does it:
//! - a Gaussian with mean `μ`, rotation `R` (unit quaternion `w, x, y, z`) and standard deviations
//!   `s` has the covariance `Σ = R·diag(s²)·Rᵀ`; with the camera's world-to-view rotation `W` and
//!   the view-space mean `(x, y, z)` (culled when `z ≤ 0.2`, the billboard renderer's near plane),
//!   the image-plane covariance is `J·W·Σ·Wᵀ·Jᵀ + 0.3·I` (the Inria dilation of 0.3 pixel², which
//!   Babylon.js and most viewers add too), `J = [[fx/z, 0, −fx·x/z²], [0, fy/z, −fy·y/z²]]` with
//!   `x/z` and `y/z` clamped to `±1.3·W/(2fx)` and `±1.3·H/(2fy)` (Inria's guard for Gaussians
//!   beside the frustum), the mean projects to `(fx·x/z + cx, fy·y/z + cy)`;
//! - the extent is `3·√λ_max` pixels (the 3σ cut-off); pixel `(i, j)` is sampled at
//!   `(i + 0.5, j + 0.5)` (the crate's camera convention);
//! - colour: the real SH (3DGS basis, the f64 reference's [`sh_basis64`]) at the direction from
//!   the camera centre to the mean, `max(Σ + 0.5, 0)`;
//! - all Gaussians sorted by view depth `z` (ties by index), composited front to back with
//!   `α = min(0.99, o·exp(−½ dᵀ Σ₂⁻¹ d))`, skipped below `1/255`, stopped when the transmittance
//!   would fall below `1e-4`, then the background times the remaining transmittance.

use super::f64_reference::renderer::{Cam64, V3, dot, rotation_columns, sh_basis64};
use bbsplat::camera::Camera;

/// One Gaussian as a 3DGS file stores it, activated: mean, unit quaternion `(w, x, y, z)`,
/// standard deviations, peak opacity, 48 SH coefficients `[coeff][rgb]`.
#[derive(Clone, Debug, PartialEq)]
pub struct Splat64 {
    pub position: V3,
    pub rotation: [f64; 4],
    pub scale: V3,
    pub opacity: f64,
    pub sh: Vec<f64>,
}

/// Parses a binary little-endian 3DGS PLY of float properties into named columns: returns the
/// property names and the rows.
pub fn parse_float_ply(bytes: &[u8]) -> (Vec<String>, Vec<Vec<f32>>) {
    let end = b"end_header\n";
    let header_len = bytes
        .windows(end.len())
        .position(|w| w == end)
        .expect("an end_header line")
        + end.len();
    let header = std::str::from_utf8(&bytes[..header_len]).expect("an ASCII header");
    let mut lines = header.lines();
    assert_eq!(lines.next(), Some("ply"));
    assert_eq!(lines.next(), Some("format binary_little_endian 1.0"));
    let mut count = 0usize;
    let mut names = Vec::new();
    for line in lines {
        let words: Vec<&str> = line.split_whitespace().collect();
        match words.as_slice() {
            ["element", "vertex", n] => count = n.parse().unwrap(),
            ["property", "float", name] => names.push(name.to_string()),
            ["end_header"] => {}
            other => panic!("unexpected header line {other:?}"),
        }
    }
    let body = &bytes[header_len..];
    assert_eq!(body.len(), count * names.len() * 4, "body size");
    let rows = body
        .chunks_exact(names.len() * 4)
        .map(|r| {
            r.chunks_exact(4)
                .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
                .collect()
        })
        .collect();
    (names, rows)
}

/// The Gaussians of a 3DGS PLY (Inria names: `f_rest` channel-major, `opacity` a logit, `scale_*`
/// logs, `rot_*` = `w, x, y, z`).
pub fn splats_from_ply(bytes: &[u8]) -> Vec<Splat64> {
    let (names, rows) = parse_float_ply(bytes);
    let col = |name: &str| {
        names
            .iter()
            .position(|n| n == name)
            .unwrap_or_else(|| panic!("no {name}"))
    };
    let (x, dc, rest, op, sc, rot) = (
        col("x"),
        col("f_dc_0"),
        col("f_rest_0"),
        col("opacity"),
        col("scale_0"),
        col("rot_0"),
    );
    rows.iter()
        .map(|r| {
            let v = |k: usize| f64::from(r[k]);
            let mut sh = vec![0.0; 48];
            for c in 0..3 {
                sh[c] = v(dc + c);
                for k in 1..16 {
                    sh[3 * k + c] = v(rest + 15 * c + k - 1);
                }
            }
            let q = [v(rot), v(rot + 1), v(rot + 2), v(rot + 3)];
            let n = q.iter().map(|c| c * c).sum::<f64>().sqrt();
            Splat64 {
                position: [v(x), v(x + 1), v(x + 2)],
                rotation: q.map(|c| c / n),
                scale: [v(sc).exp(), v(sc + 1).exp(), v(sc + 2).exp()],
                opacity: 1.0 / (1.0 + (-v(op)).exp()),
                sh,
            }
        })
        .collect()
}

struct Projected {
    depth: f64,
    index: usize,
    mean: [f64; 2],
    /// The inverse of the 2D covariance, `(a, b, c)` of `[[a, b], [b, c]]`.
    conic: [f64; 3],
    radius: f64,
    colour: V3,
}

/// Renders `splats` from `camera` with SH up to `sh_degree` over `background`: linear RGB, row
/// major, 3 floats per pixel.
pub fn render_splats(splats: &[Splat64], camera: &Camera, sh_degree: u32, background: V3) -> Vec<f64> {
    let cam = Cam64::of(camera);
    let centre = cam.centre();
    let mut projected: Vec<Projected> = Vec::new();
    for (index, s) in splats.iter().enumerate() {
        let v = cam.rotate(s.position);
        let view = [v[0] + cam.t[0], v[1] + cam.t[1], v[2] + cam.t[2]];
        let z = view[2];
        if z <= 0.2 {
            continue;
        }
        // Σ = R diag(s²) Rᵀ in world space, then W Σ Wᵀ.
        let cols = rotation_columns(s.rotation);
        let mut world = [[0.0f64; 3]; 3];
        for i in 0..3 {
            for j in 0..3 {
                world[i][j] = (0..3).map(|k| cols[k][i] * cols[k][j] * s.scale[k] * s.scale[k]).sum();
            }
        }
        let w = cam.rot;
        let mut viewcov = [[0.0f64; 3]; 3];
        for i in 0..3 {
            for j in 0..3 {
                viewcov[i][j] = (0..3)
                    .map(|a| (0..3).map(|b| w[i][a] * world[a][b] * w[j][b]).sum::<f64>())
                    .sum();
            }
        }
        // The Jacobian at the mean, its x/z and y/z clamped to 1.3 times the half field of view
        // (as Inria's rasterizer does, so that Gaussians beside the frustum do not blow up).
        let (limit_x, limit_y) = (
            1.3 * 0.5 * cam.width as f64 / cam.fx,
            1.3 * 0.5 * cam.height as f64 / cam.fy,
        );
        let tx = (view[0] / z).clamp(-limit_x, limit_x) * z;
        let ty = (view[1] / z).clamp(-limit_y, limit_y) * z;
        let jac = [
            [cam.fx / z, 0.0, -cam.fx * tx / (z * z)],
            [0.0, cam.fy / z, -cam.fy * ty / (z * z)],
        ];
        let mut cov2 = [[0.0f64; 2]; 2];
        for i in 0..2 {
            for j in 0..2 {
                cov2[i][j] = (0..3)
                    .map(|a| (0..3).map(|b| jac[i][a] * viewcov[a][b] * jac[j][b]).sum::<f64>())
                    .sum();
            }
        }
        let (a, b, c) = (cov2[0][0] + 0.3, cov2[0][1], cov2[1][1] + 0.3);
        let det = a * c - b * b;
        if det <= 0.0 {
            continue;
        }
        let mid = 0.5 * (a + c);
        let lambda = mid + (mid * mid - det).max(0.1).sqrt();
        let dir = {
            let d = [
                s.position[0] - centre[0],
                s.position[1] - centre[1],
                s.position[2] - centre[2],
            ];
            let n = dot(d, d).sqrt();
            [d[0] / n, d[1] / n, d[2] / n]
        };
        let basis = sh_basis64(sh_degree, dir);
        let coeffs = (sh_degree as usize + 1).pow(2);
        let mut colour = [0.0; 3];
        for (ch, out) in colour.iter_mut().enumerate() {
            let sum: f64 = (0..coeffs).map(|k| basis[k] * s.sh[3 * k + ch]).sum();
            *out = (sum + 0.5).max(0.0);
        }
        projected.push(Projected {
            depth: z,
            index,
            mean: [cam.fx * view[0] / z + cam.cx, cam.fy * view[1] / z + cam.cy],
            conic: [c / det, -b / det, a / det],
            radius: 3.0 * lambda.sqrt(),
            colour,
        });
    }
    projected.sort_by(|p, q| p.depth.total_cmp(&q.depth).then(p.index.cmp(&q.index)));
    let (w, h) = (cam.width, cam.height);
    let mut colour = vec![[0.0f64; 3]; w * h];
    let mut transmittance = vec![1.0f64; w * h];
    let mut done = vec![false; w * h];
    for p in &projected {
        let x0 = ((p.mean[0] - p.radius - 0.5).floor().max(0.0)) as usize;
        let y0 = ((p.mean[1] - p.radius - 0.5).floor().max(0.0)) as usize;
        let x1 = ((p.mean[0] + p.radius - 0.5).ceil().min(w as f64 - 1.0)).max(-1.0);
        let y1 = ((p.mean[1] + p.radius - 0.5).ceil().min(h as f64 - 1.0)).max(-1.0);
        if x1 < 0.0 || y1 < 0.0 {
            continue;
        }
        for j in y0..=y1 as usize {
            for i in x0..=x1 as usize {
                let at = j * w + i;
                if done[at] {
                    continue;
                }
                let (dx, dy) = (i as f64 + 0.5 - p.mean[0], j as f64 + 0.5 - p.mean[1]);
                let power = -0.5 * (p.conic[0] * dx * dx + p.conic[2] * dy * dy) - p.conic[1] * dx * dy;
                if power > 0.0 {
                    continue;
                }
                let alpha = (splats[p.index].opacity * power.exp()).min(0.99);
                if alpha < 1.0 / 255.0 {
                    continue;
                }
                let t = transmittance[at];
                let next = t * (1.0 - alpha);
                if next < 1e-4 {
                    done[at] = true;
                    continue;
                }
                for ch in 0..3 {
                    colour[at][ch] += p.colour[ch] * alpha * t;
                }
                transmittance[at] = next;
            }
        }
    }
    colour
        .iter()
        .zip(&transmittance)
        .flat_map(|(c, &t)| {
            [
                c[0] + t * background[0],
                c[1] + t * background[1],
                c[2] + t * background[2],
            ]
        })
        .collect()
}

/// 8-bit RGB of a linear image (`round(255·clamp(x, 0, 1))`).
pub fn to_bytes(rgb: &[f64]) -> Vec<u8> {
    rgb.iter().map(|&x| (x.clamp(0.0, 1.0) * 255.0).round() as u8).collect()
}
