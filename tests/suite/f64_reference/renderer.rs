//! The float64 reference renderer: every billboard at every pixel, written from the method's
//! specification (the BBSplat spec, §3) and the crate's documented conventions, without calling
//! any of the crate's stage functions. Only the crate's data types are read (billboard arrays,
//! the camera's public fields, the compositing thresholds' values).
//!
//! Per billboard: normalised quaternion `[w, x, y, z]` → rotation with columns `t_u, t_v, n`;
//! `s = exp(log_scales)`; view-space axes `a = s_u·R_cw·t_u`, `b = s_v·R_cw·t_v` and centre
//! `c = R_cw·x + t`. Culled when `c.z ≤ near` or the camera lies exactly in the plane.
//!
//! Per pixel centre `(i + 0.5, j + 0.5)`: the ray `r = ((x − cx)/fx, (y − cy)/fy, 1)` meets the
//! plane `c + u·a + v·b` where `c + u·a + v·b = z·r`, solved by Cramer's rule with scalar triple
//! products: `D = a·(b × r)`, `u = −c·(b × r)/D`, `v = c·(a × r)/D`, `z = c·(a × b)/D` (`z` is the
//! hit's view depth because `r.z = 1`). This is a different formulation from the crate's
//! homogeneous-line intersection `p = k × l`; the crate's grazing-ray guard is a rule on those
//! lines, so it is mirrored by evaluating `k`, `l` in f64 (it changes values only for rays within
//! ~1e-4 rad of the plane).
//!
//! Texture: align-corners texel coordinates `X = (u + 1)/2·(TS − 1)` (column, from `u`) and
//! `Y = (v + 1)/2·(TS − 1)` (row, from `v`), bilinear with zero padding. SH colour with the
//! 3DGS polynomial forms, view direction from the camera centre `−R_cwᵀ·t` to the billboard
//! centre, `max(Σ + 0.5, 0)`. Colour = texture rgb + SH colour. Compositing over all billboards
//! sorted by centre view depth (ties by index), with the thresholds of [`Thresholds`].

use bbsplat::billboards::ActivatedBillboards;
use bbsplat::camera::Camera;
use bbsplat::raster::RenderSettings;
use bbsplat::stages::composite::CompositeParams;

pub type V3 = [f64; 3];

#[inline]
pub fn dot(a: V3, b: V3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

#[inline]
pub fn cross(a: V3, b: V3) -> V3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// A pinhole camera in f64: world-to-view rotation rows, translation, intrinsics, image size.
#[derive(Clone, Copy, Debug)]
pub struct Cam64 {
    pub rot: [V3; 3],
    pub t: V3,
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    pub width: usize,
    pub height: usize,
}

impl Cam64 {
    /// The crate's camera, every field read exactly (f32 → f64).
    pub fn of(cam: &Camera) -> Self {
        let r = cam.rotation;
        let row = |i: usize| [r.x_axis[i] as f64, r.y_axis[i] as f64, r.z_axis[i] as f64];
        Self {
            rot: [row(0), row(1), row(2)],
            t: cam.translation.to_array().map(f64::from),
            fx: cam.fx as f64,
            fy: cam.fy as f64,
            cx: cam.cx as f64,
            cy: cam.cy as f64,
            width: cam.width as usize,
            height: cam.height as usize,
        }
    }

    /// `R·p`.
    pub fn rotate(&self, p: V3) -> V3 {
        [dot(self.rot[0], p), dot(self.rot[1], p), dot(self.rot[2], p)]
    }

    /// Camera centre in world coordinates, `−Rᵀ·t`.
    pub fn centre(&self) -> V3 {
        let mut c = [0.0; 3];
        for (i, row) in self.rot.iter().enumerate() {
            for k in 0..3 {
                c[k] -= row[k] * self.t[i];
            }
        }
        c
    }

    pub fn pixels(&self) -> usize {
        self.width * self.height
    }
}

/// The billboard parameters in f64 (what the finite differences perturb), plus the render
/// settings that matter: background and SH degree.
#[derive(Clone, Debug)]
pub struct Scene64 {
    pub pos: Vec<V3>,
    pub quat: Vec<[f64; 4]>,
    pub log_scale: Vec<[f64; 2]>,
    /// `[billboard][coeff][rgb]`, 48 per billboard.
    pub sh: Vec<f64>,
    /// `[billboard][row][col]` texels `[r, g, b, alpha]`.
    pub tex: Vec<[f64; 4]>,
    pub ts: usize,
    pub background: V3,
    pub sh_degree: u32,
}

impl Scene64 {
    /// Exact f64 copy of an f32 billboard set and its settings.
    pub fn of(b: &ActivatedBillboards, settings: &RenderSettings) -> Self {
        Self {
            pos: b.positions.iter().map(|p| p.to_array().map(f64::from)).collect(),
            quat: b.quaternions.iter().map(|q| q.map(f64::from)).collect(),
            log_scale: b.log_scales.iter().map(|s| s.to_array().map(f64::from)).collect(),
            sh: b.sh.iter().map(|&x| x as f64).collect(),
            tex: b.textures.iter().map(|t| t.map(f64::from)).collect(),
            ts: b.texture_size,
            background: settings.background.to_array().map(f64::from),
            sh_degree: settings.sh_degree,
        }
    }

    pub fn len(&self) -> usize {
        self.pos.len()
    }
}

/// The thresholds of the method.
#[derive(Clone, Copy, Debug)]
pub struct Thresholds {
    pub max_alpha: f64,
    pub min_alpha: f64,
    pub min_transmittance: f64,
    /// Near plane on the centre depth (cull when `≤`) and on the hit depth (reject when `<`).
    pub near: f64,
    /// The crate's grazing-ray guard on the intersection (`|p.z| > eps·(|k.x·l.y| + |k.y·l.x|)`);
    /// 0 disables it (the method itself only skips `p.z == 0`).
    pub grazing_eps: f64,
}

impl Thresholds {
    /// The crate's thresholds exactly as it compares them: the f32 values of `params` (training
    /// settings: `CompositeParams::default()`), the f32 near plane 0.2 and the crate's grazing
    /// guard 1e-4 (f32).
    pub fn crate_values(params: &CompositeParams) -> Self {
        Self {
            max_alpha: params.max_alpha as f64,
            min_alpha: params.min_alpha as f64,
            min_transmittance: params.min_transmittance as f64,
            near: 0.2f32 as f64,
            grazing_eps: 1e-4f32 as f64,
        }
    }

    /// The specification's decimal values in f64 (0.99, 1/255, 1e-4, 0.2), no grazing guard: the
    /// method in real arithmetic, used to show where the f32 thresholds decide differently.
    pub fn decimal() -> Self {
        Self {
            max_alpha: 0.99,
            min_alpha: 1.0 / 255.0,
            min_transmittance: 1e-4,
            near: 0.2,
            grazing_eps: 0.0,
        }
    }
}

/// The images of a render: rgb interleaved, opacity `Σ α·T`, alpha-weighted depth `Σ α·T·z`.
#[derive(Clone, Debug)]
pub struct Image64 {
    pub rgb: Vec<f64>,
    pub alpha: Vec<f64>,
    pub depth: Vec<f64>,
}

/// What happened to one (pixel, billboard) pair.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Fate {
    /// The billboard is culled (centre behind the near plane or camera in its plane).
    Culled,
    /// Compositing stopped before this billboard.
    Unreached,
    /// Reached but contributes nothing: no hit (parallel ray, grazing guard, hit behind the near
    /// plane), hit outside the texture support, or alpha below the cut-off.
    Nothing,
    /// Blended.
    Blend,
    /// The transmittance stop: compositing ends here, this pair not blended.
    Stop,
}

/// The continuous quantities of one pair whose thresholds are discontinuities.
#[derive(Clone, Copy, Debug)]
pub struct PairTrace {
    pub fate: Fate,
    /// The ray is not parallel to the plane (`D ≠ 0`): the fields below are defined.
    pub hit: bool,
    /// Grazing-guard ratio `|p.z| / (|k.x·l.y| + |k.y·l.x|)` of the crate's formulation.
    pub rho: f64,
    /// View depth of the hit.
    pub depth: f64,
    /// Continuous texel coordinates (column, row).
    pub tx: f64,
    pub ty: f64,
    /// Sampled (raw, unclamped) alpha at the hit, whether or not the hit is accepted; 0 outside
    /// the support.
    pub a: f64,
    /// `T·(1 − min(max_alpha, a))` (when reached and not skipped).
    pub test_t: f64,
}

const EMPTY_PAIR: PairTrace = PairTrace {
    fate: Fate::Culled,
    hit: false,
    rho: 0.0,
    depth: 0.0,
    tx: 0.0,
    ty: 0.0,
    a: 0.0,
    test_t: 0.0,
};

/// Everything the margin checks need: per billboard its centre depth and SH sums, per
/// (pixel, billboard) pair its [`PairTrace`] (`pairs[pixel·n + billboard]`).
#[derive(Clone, Debug)]
pub struct Trace {
    pub visible: Vec<bool>,
    pub centre_depth: Vec<f64>,
    /// `Σ Y·coeffs + 0.5` per channel, before the clamp at 0.
    pub sh_sum: Vec<V3>,
    /// Visible billboards in compositing order.
    pub order: Vec<usize>,
    pub pairs: Vec<PairTrace>,
}

/// One billboard prepared for the per-pixel loop.
#[derive(Clone, Copy, Debug)]
struct Splat {
    visible: bool,
    a: V3,
    b: V3,
    c: V3,
    /// `a × b` (plane normal scaled by `s_u·s_v`).
    n: V3,
    /// Rows of the ray-splat matrix `K·[a | b | c]`, for the crate's grazing guard only.
    tu: V3,
    tv: V3,
    tw: V3,
    rgb: V3,
    sh_sum: V3,
}

/// Rotation matrix of a unit quaternion `[w, x, y, z]`, returned as its columns.
pub fn rotation_columns(q: [f64; 4]) -> [V3; 3] {
    let n = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
    let [w, x, y, z] = q.map(|c| c / n);
    // R = (w² − |v|²)·I + 2·v·vᵀ + 2·w·[v]×, column by column.
    let s = w * w - x * x - y * y - z * z;
    [
        [s + 2.0 * x * x, 2.0 * (x * y + w * z), 2.0 * (x * z - w * y)],
        [2.0 * (x * y - w * z), s + 2.0 * y * y, 2.0 * (y * z + w * x)],
        [2.0 * (x * z + w * y), 2.0 * (y * z - w * x), s + 2.0 * z * z],
    ]
}

/// Real SH basis (3DGS polynomial forms) up to `degree` at the unit direction `d`.
pub fn sh_basis64(degree: u32, d: V3) -> [f64; 16] {
    const C0: f64 = 0.282_094_791_773_878_14;
    const C1: f64 = 0.488_602_511_902_919_9;
    const C2: [f64; 5] = [
        1.092_548_430_592_079_2,
        -1.092_548_430_592_079_2,
        0.315_391_565_252_520_05,
        -1.092_548_430_592_079_2,
        0.546_274_215_296_039_6,
    ];
    const C3: [f64; 7] = [
        -0.590_043_589_926_643_5,
        2.890_611_442_640_554,
        -0.457_045_799_464_465_8,
        0.373_176_332_590_115_4,
        -0.457_045_799_464_465_8,
        1.445_305_721_320_277,
        -0.590_043_589_926_643_5,
    ];
    let mut y = [0.0; 16];
    y[0] = C0;
    let [x, yy, z] = d;
    if degree >= 1 {
        y[1] = -C1 * yy;
        y[2] = C1 * z;
        y[3] = -C1 * x;
    }
    let (x2, y2, z2) = (x * x, yy * yy, z * z);
    if degree >= 2 {
        y[4] = C2[0] * x * yy;
        y[5] = C2[1] * yy * z;
        y[6] = C2[2] * (2.0 * z2 - x2 - y2);
        y[7] = C2[3] * x * z;
        y[8] = C2[4] * (x2 - y2);
    }
    if degree >= 3 {
        y[9] = C3[0] * yy * (3.0 * x2 - y2);
        y[10] = C3[1] * x * yy * z;
        y[11] = C3[2] * yy * (4.0 * z2 - x2 - y2);
        y[12] = C3[3] * z * (2.0 * z2 - 3.0 * x2 - 3.0 * y2);
        y[13] = C3[4] * x * (4.0 * z2 - x2 - y2);
        y[14] = C3[5] * z * (x2 - y2);
        y[15] = C3[6] * x * (x2 - 3.0 * y2);
    }
    y
}

fn prepare(scene: &Scene64, i: usize, cam: &Cam64, th: &Thresholds) -> Splat {
    let [tu_w, tv_w, n_w] = rotation_columns(scene.quat[i]);
    let (su, sv) = (scene.log_scale[i][0].exp(), scene.log_scale[i][1].exp());
    let a = cam.rotate(tu_w).map(|x| x * su);
    let b = cam.rotate(tv_w).map(|x| x * sv);
    let rp = cam.rotate(scene.pos[i]);
    let c = [rp[0] + cam.t[0], rp[1] + cam.t[1], rp[2] + cam.t[2]];
    let normal_view = cam.rotate(n_w);
    // Culls: centre at or behind the near plane; camera exactly in the plane (cos θ = 0).
    let visible = c[2] > th.near && dot(normal_view, c) != 0.0;
    let tw = [a[2], b[2], c[2]];
    let tu = [
        cam.fx * a[0] + cam.cx * tw[0],
        cam.fx * b[0] + cam.cx * tw[1],
        cam.fx * c[0] + cam.cx * tw[2],
    ];
    let tv = [
        cam.fy * a[1] + cam.cy * tw[0],
        cam.fy * b[1] + cam.cy * tw[1],
        cam.fy * c[1] + cam.cy * tw[2],
    ];
    // SH colour: direction from the camera centre to the billboard centre.
    let centre = cam.centre();
    let d = [
        scene.pos[i][0] - centre[0],
        scene.pos[i][1] - centre[1],
        scene.pos[i][2] - centre[2],
    ];
    let len = dot(d, d).sqrt();
    let basis = sh_basis64(scene.sh_degree, d.map(|x| x / len));
    let coeffs = &scene.sh[48 * i..48 * (i + 1)];
    let mut sh_sum = [0.5; 3];
    for (k, y) in basis.iter().enumerate() {
        for ch in 0..3 {
            sh_sum[ch] += y * coeffs[3 * k + ch];
        }
    }
    Splat {
        visible,
        a,
        b,
        c,
        n: cross(a, b),
        tu,
        tv,
        tw,
        rgb: sh_sum.map(|s| s.max(0.0)),
        sh_sum,
    }
}

/// Bilinear sample of the four channels at texel coordinates `(x, y)` (zero padding), or `None`
/// outside the support `(−1, TS)²`.
fn sample(tex: &[[f64; 4]], ts: usize, x: f64, y: f64) -> Option<[f64; 4]> {
    let n = ts as f64;
    if !(x > -1.0 && x < n && y > -1.0 && y < n) {
        return None;
    }
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = (x - x0, y - y0);
    let mut out = [0.0; 4];
    for (dy, wy) in [(0, 1.0 - fy), (1, fy)] {
        let row = y0 as i64 + dy;
        if row < 0 || row >= ts as i64 {
            continue;
        }
        for (dx, wx) in [(0, 1.0 - fx), (1, fx)] {
            let col = x0 as i64 + dx;
            if col < 0 || col >= ts as i64 {
                continue;
            }
            let texel = tex[row as usize * ts + col as usize];
            for k in 0..4 {
                out[k] += wx * wy * texel[k];
            }
        }
    }
    Some(out)
}

/// The hit of pixel centre `(px, py)` on billboard `s`: `(rho, u, v, depth, accepted)` or `None`
/// when the ray is parallel to the plane.
#[inline]
fn hit(s: &Splat, cam: &Cam64, px: f64, py: f64, th: &Thresholds) -> Option<(f64, f64, f64, f64, bool)> {
    let r = [(px - cam.cx) / cam.fx, (py - cam.cy) / cam.fy, 1.0];
    let br = cross(s.b, r);
    let det = dot(s.a, br);
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    let u = -dot(s.c, br) / det;
    let v = dot(s.c, cross(s.a, r)) / det;
    let z = dot(s.c, s.n) / det;
    // The crate's grazing guard and (u, v) bound, on its homogeneous lines k, l.
    let k = [px * s.tw[0] - s.tu[0], px * s.tw[1] - s.tu[1]];
    let l = [py * s.tw[0] - s.tv[0], py * s.tw[1] - s.tv[1]];
    let (m, nn) = (k[0] * l[1], k[1] * l[0]);
    let rho = (m - nn).abs() / (m.abs() + nn.abs());
    let accepted = rho > th.grazing_eps && u.abs() < 1e4 && v.abs() < 1e4 && z >= th.near;
    Some((rho, u, v, z, accepted))
}

/// Renders `scene` seen by `cam` in f64; with `trace`, also records every pair.
pub fn render64(scene: &Scene64, cam: &Cam64, th: &Thresholds, trace: bool) -> (Image64, Option<Trace>) {
    let n = scene.len();
    let ts = scene.ts;
    let t2 = ts * ts;
    let splats: Vec<Splat> = (0..n).map(|i| prepare(scene, i, cam, th)).collect();
    let mut order: Vec<usize> = (0..n).filter(|&i| splats[i].visible).collect();
    order.sort_by(|&i, &j| splats[i].c[2].total_cmp(&splats[j].c[2]).then(i.cmp(&j)));
    let npix = cam.pixels();
    let mut img = Image64 {
        rgb: vec![0.0; 3 * npix],
        alpha: vec![0.0; npix],
        depth: vec![0.0; npix],
    };
    let mut pairs = if trace { vec![EMPTY_PAIR; npix * n] } else { Vec::new() };
    let scale = 0.5 * (ts - 1) as f64;
    for j in 0..cam.height {
        for i in 0..cam.width {
            let pix = j * cam.width + i;
            let (px, py) = (i as f64 + 0.5, j as f64 + 0.5);
            let mut t = 1.0;
            let mut rgb = [0.0; 3];
            let (mut alpha, mut depth) = (0.0, 0.0);
            let mut stopped = false;
            for &b in &order {
                let s = &splats[b];
                let mut rec = PairTrace {
                    fate: Fate::Nothing,
                    ..EMPTY_PAIR
                };
                if stopped {
                    rec.fate = Fate::Unreached;
                    if trace {
                        pairs[pix * n + b] = rec;
                    }
                    continue;
                }
                let Some((rho, u, v, z, accepted)) = hit(s, cam, px, py, th) else {
                    if trace {
                        pairs[pix * n + b] = rec;
                    }
                    continue;
                };
                let (tx, ty) = ((u + 1.0) * scale, (v + 1.0) * scale);
                let texture = &scene.tex[b * t2..(b + 1) * t2];
                let sampled = sample(texture, ts, tx, ty);
                rec.hit = true;
                rec.rho = rho;
                rec.depth = z;
                rec.tx = tx;
                rec.ty = ty;
                rec.a = sampled.map_or(0.0, |c| c[3]);
                let write = |rec: PairTrace, pairs: &mut Vec<PairTrace>| {
                    if trace {
                        pairs[pix * n + b] = rec;
                    }
                };
                let Some(texel) = sampled.filter(|_| accepted) else {
                    write(rec, &mut pairs);
                    continue;
                };
                let al = texel[3].min(th.max_alpha);
                if al.is_nan() || al < th.min_alpha {
                    write(rec, &mut pairs);
                    continue;
                }
                let next = t * (1.0 - al);
                rec.test_t = next;
                if next < th.min_transmittance {
                    rec.fate = Fate::Stop;
                    write(rec, &mut pairs);
                    stopped = true;
                    continue;
                }
                rec.fate = Fate::Blend;
                write(rec, &mut pairs);
                let w = al * t;
                for ch in 0..3 {
                    rgb[ch] += w * (texel[ch] + s.rgb[ch]);
                }
                alpha += w;
                depth += w * z;
                t = next;
            }
            for ch in 0..3 {
                img.rgb[3 * pix + ch] = rgb[ch] + t * scene.background[ch];
            }
            img.alpha[pix] = alpha;
            img.depth[pix] = depth;
        }
    }
    let trace = trace.then(|| Trace {
        visible: splats.iter().map(|s| s.visible).collect(),
        centre_depth: splats.iter().map(|s| s.c[2]).collect(),
        sh_sum: splats.iter().map(|s| s.sh_sum).collect(),
        order,
        pairs,
    });
    (img, trace)
}
