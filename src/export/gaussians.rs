//! Billboards as flat 3D Gaussians: each billboard's alpha and colour textures approximated by a
//! few Gaussians in its plane, for the 3DGS PLY ([`super::splat_ply`]) and the glTF
//! `KHR_gaussian_splatting` ([`super::splat_glb`]) exports.
//!
//! Conventions (also in `docs/export.md`):
//! - **Texture space.** Texel `(row, col)` of a `TS × TS` texture is centred at
//!   `u = −1 + 2·col/(TS − 1)`, `v = −1 + 2·row/(TS − 1)` (the renderer's align-corners sampling,
//!   spec §3.4): texel spacing `h = 2/(TS − 1)` in `(u, v)` units.
//! - **One Gaussian from moments** ([`moment_gaussian`]): over a set of texels with alphas
//!   `a_i` (the weights), mass `m = Σ a_i`, mean `μ = Σ a_i·p_i / m`, covariance
//!   `Σ = Σ a_i·(p_i − μ)(p_i − μ)ᵀ / m + (h²/6)·I` (the second term is the variance of the
//!   bilinear tent of one texel, so a single texel is not a point), peak opacity
//!   `o = m·h² / (2π·√det Σ)` (the Gaussian holds the alpha mass `m·h²` of the bilinear alpha
//!   field), clamped to `≤` [`MAX_OPACITY`] (the renderer's `0.99`); colour = the alpha-weighted
//!   mean of the colour texture.
//! - **Splitting** ([`fit_billboard`]): the texels with alpha `> 0` start as one group. While the
//!   billboard has fewer than [`FitRule::max_gaussians`] Gaussians and its fit error is above
//!   [`FitRule::max_error`], the group with the largest share of the error is cut in two by the
//!   line through its mean across its principal axis (the eigenvector of its covariance with the
//!   larger eigenvalue), each half getting its moment Gaussian; the cut is kept only if it lowers
//!   the billboard's fit error, and a group whose cut was refused (or that cannot be cut: one
//!   side empty) is not tried again. So the error never grows with the cap.
//! - **Fit error** ([`fit_error`]): at every texel centre `p`, the Gaussians' alpha
//!   `α(p) = 1 − Π_k (1 − o_k·g_k(p))` (how they composite over each other) against the texture's
//!   `min(a(p), 0.99)`, and their premultiplied colour `α(p)·Σ_k c_k o_k g_k(p) / Σ_k o_k g_k(p)`
//!   against `min(a, 0.99)·rgb(p)`; the error is the root mean square of the four channel
//!   differences over the `TS²` texels (in `[0, 1]` units).
//! - **World placement** ([`place`]): billboard centre `x`, rotation `R` (columns `t_u`, `t_v`,
//!   `n`), half sides `s = (s_u, s_v)`: the plane point `(u, v)` is `x + R·(s_u·u, s_v·v, 0)`, so a
//!   UV Gaussian `(μ, Σ)` becomes the world Gaussian with mean `x + R·(s_u μ_u, s_v μ_v, 0)` and
//!   in-plane covariance `S Σ S` (`S = diag(s_u, s_v)`), factored as `R_g · diag(σ₁², σ₂², σ₃²) ·
//!   R_gᵀ` with `R_g = R · R_z(θ)` (θ the angle of the larger eigenvector in the `t_u, t_v` frame),
//!   `σ₁ ≥ σ₂` the square roots of the eigenvalues and the thickness `σ₃ = ` [`FLAT_RATIO`]`·σ₂`.
//! - **Colour.** The renderer adds the texture colour to the SH colour
//!   (`rgb(u, v) + max(SH(dir) + 0.5, 0)`, spec §3.3 step 5); a Gaussian's colour is
//!   `max(SH(dir) + 0.5, 0)`, so its SH are the billboard's with the fitted texture colour `c`
//!   folded into the DC term: `f_dc += c / SH_C0`, coefficients above the model's SH degree set to
//!   0. The two agree wherever the billboard's SH colour is not clamped (`SH(dir) + 0.5 ≥ 0`);
//!   the texture's variation inside one Gaussian is replaced by its mean.
//! - Gaussians whose opacity is below [`MIN_OPACITY`] (`1/255`, what a 3DGS renderer skips) are
//!   dropped; a billboard may then have none.

use crate::raster::ActivatedRef;
use crate::stages::rotation::quat_to_rotation;
use crate::stages::sh::{SH_C0, SH_FLOATS, sh_coeff_count};
use glam::{Mat3, Quat, Vec2, Vec3};
use rayon::prelude::*;

/// The largest opacity of a Gaussian (the billboard renderer's alpha clamp, spec §3.3).
pub const MAX_OPACITY: f32 = 0.99;

/// Gaussians with a lower peak opacity are dropped (3DGS renderers skip alphas below `1/255`).
pub const MIN_OPACITY: f32 = 1.0 / 255.0;

/// The thickness of a flat Gaussian: its third standard deviation over its smaller in-plane one.
pub const FLAT_RATIO: f32 = 0.01;

/// How finely billboards are split.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FitRule {
    /// At most this many Gaussians per billboard (`≥ 1`).
    pub max_gaussians: usize,
    /// Stop splitting a billboard once its fit error ([`fit_error`]) is at most this.
    pub max_error: f32,
}

impl Default for FitRule {
    /// 8 Gaussians per billboard at most, splitting until the RMS error is at most 0.02.
    fn default() -> Self {
        Self {
            max_gaussians: 8,
            max_error: 0.02,
        }
    }
}

/// A Gaussian in a billboard's texture plane, `(u, v)` units.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UvGaussian {
    /// Mean `(u, v)`.
    pub mean: Vec2,
    /// Covariance `[[σ_uu, σ_uv], [σ_uv, σ_vv]]` as `(σ_uu, σ_uv, σ_vv)`.
    pub covariance: Vec3,
    /// Peak opacity in `(0, MAX_OPACITY]`.
    pub opacity: f32,
    /// The alpha-weighted mean texture colour (`[0, 1]` per channel).
    pub colour: Vec3,
}

impl UvGaussian {
    /// `o·exp(−½ dᵀ Σ⁻¹ d)` at `p`, `d = p − mean`.
    ///
    /// ```
    /// use bbsplat::export::gaussians::UvGaussian;
    /// use glam::{Vec2, Vec3};
    /// let g = UvGaussian { mean: Vec2::ZERO, covariance: Vec3::new(1.0, 0.0, 4.0), opacity: 0.5, colour: Vec3::ONE };
    /// assert_eq!(g.alpha_at(Vec2::ZERO), 0.5);
    /// assert!((g.alpha_at(Vec2::new(0.0, 2.0)) - 0.5 * (-0.5f32).exp()).abs() < 1e-7);
    /// ```
    pub fn alpha_at(&self, p: Vec2) -> f32 {
        let d = p - self.mean;
        let (a, b, c) = (self.covariance.x, self.covariance.y, self.covariance.z);
        let det = a * c - b * b;
        let q = (c * d.x * d.x - 2.0 * b * d.x * d.y + a * d.y * d.y) / det;
        self.opacity * (-0.5 * q).exp()
    }
}

/// The centre `(u, v)` of texel `index` (row-major) of a `ts × ts` texture.
///
/// ```
/// use bbsplat::export::gaussians::texel_centre;
/// use glam::Vec2;
/// assert_eq!(texel_centre(0, 16), Vec2::new(-1.0, -1.0));
/// assert_eq!(texel_centre(16 * 16 - 1, 16), Vec2::new(1.0, 1.0));
/// assert_eq!(texel_centre(15, 16), Vec2::new(1.0, -1.0)); // last column of the first row
/// ```
pub fn texel_centre(index: usize, ts: usize) -> Vec2 {
    let h = 2.0 / (ts as f32 - 1.0);
    let (row, col) = (index / ts, index % ts);
    Vec2::new(-1.0 + h * col as f32, -1.0 + h * row as f32)
}

/// Eigen-decomposition of the symmetric 2×2 matrix `(a, b, c)` = `[[a, b], [b, c]]`: the larger
/// and the smaller eigenvalue and the unit eigenvector of the larger (`x ≥ 0` or, when `x = 0`,
/// `y > 0`).
///
/// ```
/// use bbsplat::export::gaussians::symmetric_eigen_2x2;
/// use glam::Vec3;
/// let (l1, l2, e) = symmetric_eigen_2x2(Vec3::new(1.0, 0.0, 4.0));
/// assert_eq!((l1, l2), (4.0, 1.0));
/// assert!((e - glam::Vec2::Y).length() < 1e-6);
/// ```
pub fn symmetric_eigen_2x2(m: Vec3) -> (f32, f32, Vec2) {
    let (a, b, c) = (m.x, m.y, m.z);
    let half_trace = 0.5 * (a + c);
    let radius = (0.25 * (a - c) * (a - c) + b * b).sqrt();
    let (l1, l2) = (half_trace + radius, half_trace - radius);
    // (b, l1 − a) and (l1 − c, b) are both eigenvectors of l1; take the better conditioned.
    let e = if b == 0.0 {
        if a >= c { Vec2::X } else { Vec2::Y }
    } else {
        let v1 = Vec2::new(b, l1 - a);
        let v2 = Vec2::new(l1 - c, b);
        if v1.length_squared() >= v2.length_squared() {
            v1
        } else {
            v2
        }
        .normalize()
    };
    let e = if e.x < 0.0 || (e.x == 0.0 && e.y < 0.0) { -e } else { e };
    (l1, l2.max(0.0), e)
}

/// The moment Gaussian of the texels `members` of `texture` (RGBA, `ts × ts`, row-major), with
/// the alphas as weights (module docs); `None` when their alpha mass is 0.
///
/// ```
/// use bbsplat::export::gaussians::moment_gaussian;
/// // A 4 × 4 texture with one opaque red texel at row 1, column 2.
/// let mut t = vec![[0.0f32; 4]; 16];
/// t[1 * 4 + 2] = [1.0, 0.0, 0.0, 0.9];
/// let g = moment_gaussian(&t, 4, &[6]).unwrap();
/// let h = 2.0f32 / 3.0;
/// assert!((g.mean - glam::Vec2::new(-1.0 + 2.0 * h, -1.0 + h)).length() < 1e-6);
/// assert!((g.covariance.x - h * h / 6.0).abs() < 1e-7 && g.covariance.y == 0.0);
/// assert_eq!(g.colour, glam::Vec3::X);
/// // Mass 0.9·h² over the Gaussian integral 2π·√det = 2π·h²/6: peak 0.9·6/(2π) ≈ 0.86.
/// assert!((g.opacity - 0.9 * 6.0 / (2.0 * std::f32::consts::PI)).abs() < 1e-5);
/// ```
pub fn moment_gaussian(texture: &[[f32; 4]], ts: usize, members: &[usize]) -> Option<UvGaussian> {
    let mut mass = 0.0f64;
    let (mut su, mut sv) = (0.0f64, 0.0f64);
    let mut colour = [0.0f64; 3];
    for &i in members {
        let a = f64::from(texture[i][3]);
        let p = texel_centre(i, ts);
        mass += a;
        su += a * f64::from(p.x);
        sv += a * f64::from(p.y);
        for (c, t) in colour.iter_mut().zip(&texture[i][..3]) {
            *c += a * f64::from(*t);
        }
    }
    if mass <= 0.0 {
        return None;
    }
    let (mu, mv) = (su / mass, sv / mass);
    let (mut cuu, mut cuv, mut cvv) = (0.0f64, 0.0f64, 0.0f64);
    for &i in members {
        let a = f64::from(texture[i][3]);
        let p = texel_centre(i, ts);
        let (du, dv) = (f64::from(p.x) - mu, f64::from(p.y) - mv);
        cuu += a * du * du;
        cuv += a * du * dv;
        cvv += a * dv * dv;
    }
    let h = 2.0 / (ts as f64 - 1.0);
    let tent = h * h / 6.0;
    let (cuu, cuv, cvv) = (cuu / mass + tent, cuv / mass, cvv / mass + tent);
    let det = (cuu * cvv - cuv * cuv).max(tent * tent * 1e-6);
    let opacity = (mass * h * h / (2.0 * std::f64::consts::PI * det.sqrt())).min(f64::from(MAX_OPACITY));
    Some(UvGaussian {
        mean: Vec2::new(mu as f32, mv as f32),
        covariance: Vec3::new(cuu as f32, cuv as f32, cvv as f32),
        opacity: opacity as f32,
        colour: Vec3::new(
            (colour[0] / mass) as f32,
            (colour[1] / mass) as f32,
            (colour[2] / mass) as f32,
        ),
    })
}

/// Per texel, the squared error (summed over the four channels) of `gaussians` against `texture`
/// (module docs: alpha, and premultiplied colour).
fn texel_errors(texture: &[[f32; 4]], ts: usize, gaussians: &[UvGaussian]) -> Vec<f32> {
    (0..texture.len())
        .map(|i| {
            let p = texel_centre(i, ts);
            let mut transmittance = 1.0f32;
            let (mut weight, mut colour) = (0.0f32, Vec3::ZERO);
            for g in gaussians {
                let a = g.alpha_at(p);
                transmittance *= 1.0 - a;
                weight += a;
                colour += a * g.colour;
            }
            let alpha = 1.0 - transmittance;
            let premultiplied = if weight > 0.0 {
                colour * (alpha / weight)
            } else {
                Vec3::ZERO
            };
            let target_alpha = texture[i][3].min(MAX_OPACITY);
            let target = Vec3::from_slice(&texture[i][..3]) * target_alpha;
            (alpha - target_alpha).powi(2) + (premultiplied - target).length_squared()
        })
        .collect()
}

/// The fit error of `gaussians` against `texture` (module docs): the RMS over the `TS²` texels
/// and four channels, in `[0, 1]` units.
///
/// ```
/// use bbsplat::export::gaussians::fit_error;
/// // A fully transparent texture is fitted exactly by no Gaussian.
/// assert_eq!(fit_error(&vec![[0.3, 0.2, 0.1, 0.0]; 16], 4, &[]), 0.0);
/// ```
pub fn fit_error(texture: &[[f32; 4]], ts: usize, gaussians: &[UvGaussian]) -> f32 {
    let sum: f64 = texel_errors(texture, ts, gaussians).iter().map(|&e| f64::from(e)).sum();
    (sum / (4 * texture.len()) as f64).sqrt() as f32
}

/// Cuts `members` in two across the principal axis of `g` (through its mean); `None` when one side
/// would be empty.
fn cut(members: &[usize], ts: usize, g: &UvGaussian) -> Option<(Vec<usize>, Vec<usize>)> {
    let (_, _, axis) = symmetric_eigen_2x2(g.covariance);
    let (low, high): (Vec<usize>, Vec<usize>) = members
        .iter()
        .partition(|&&i| (texel_centre(i, ts) - g.mean).dot(axis) <= 0.0);
    (!low.is_empty() && !high.is_empty()).then_some((low, high))
}

/// One billboard's texture (RGBA, `ts × ts`, row-major) as at most `rule.max_gaussians` UV
/// Gaussians (module docs), with their fit error ([`fit_error`]).
///
/// ```
/// use bbsplat::export::gaussians::{FitRule, fit_billboard};
/// // Two separate opaque dots: one Gaussian fits badly, two fit well.
/// let ts = 16;
/// let mut t = vec![[0.0f32; 4]; ts * ts];
/// for (row, col) in [(4, 3), (4, 4), (5, 3), (5, 4), (11, 11), (11, 12), (12, 11), (12, 12)] {
///     t[row * ts + col] = [0.8, 0.4, 0.2, 0.9];
/// }
/// let (one, e1) = fit_billboard(&t, ts, &FitRule { max_gaussians: 1, max_error: 0.0 });
/// let (two, e2) = fit_billboard(&t, ts, &FitRule { max_gaussians: 2, max_error: 0.0 });
/// assert_eq!((one.len(), two.len()), (1, 2));
/// assert!(e2 < 0.5 * e1, "{e1} {e2}");
/// ```
pub fn fit_billboard(texture: &[[f32; 4]], ts: usize, rule: &FitRule) -> (Vec<UvGaussian>, f32) {
    let start: Vec<usize> = (0..texture.len()).filter(|&i| texture[i][3] > 0.0).collect();
    // Groups of texels, each with its Gaussian; `splittable` is false once a cut failed.
    let mut groups: Vec<(Vec<usize>, UvGaussian, bool)> = Vec::new();
    if let Some(g) = moment_gaussian(texture, ts, &start) {
        groups.push((start, g, true));
    }
    let gaussians_of = |groups: &[(Vec<usize>, UvGaussian, bool)]| groups.iter().map(|g| g.1).collect::<Vec<_>>();
    loop {
        let gaussians = gaussians_of(&groups);
        let errors = texel_errors(texture, ts, &gaussians);
        let total: f64 = errors.iter().map(|&e| f64::from(e)).sum();
        let rms = (total / (4 * texture.len()) as f64).sqrt() as f32;
        if groups.len() >= rule.max_gaussians.max(1) || rms <= rule.max_error {
            break;
        }
        // The splittable group with the largest error over its texels (the first on a tie).
        let worst = groups
            .iter()
            .enumerate()
            .filter(|(_, g)| g.2)
            .map(|(k, g)| (k, g.0.iter().map(|&i| f64::from(errors[i])).sum::<f64>()))
            .fold(None, |best: Option<(usize, f64)>, (k, e)| match best {
                Some((_, b)) if b >= e => best,
                _ => Some((k, e)),
            });
        let Some((k, _)) = worst else { break };
        let halves = cut(&groups[k].0, ts, &groups[k].1).and_then(|(low, high)| {
            let gl = moment_gaussian(texture, ts, &low)?;
            let gh = moment_gaussian(texture, ts, &high)?;
            Some(((low, gl), (high, gh)))
        });
        let Some(((low, gl), (high, gh))) = halves else {
            groups[k].2 = false;
            continue;
        };
        // The cut is kept only if it lowers the billboard's error (two overlapping halves can
        // fit worse than their parent); otherwise the group is not cut again.
        let mut trial = gaussians.clone();
        trial[k] = gl;
        trial.insert(k + 1, gh);
        let trial_total: f64 = texel_errors(texture, ts, &trial).iter().map(|&e| f64::from(e)).sum();
        if trial_total < total {
            groups[k] = (low, gl, true);
            groups.insert(k + 1, (high, gh, true));
        } else {
            groups[k].2 = false;
        }
    }
    let kept: Vec<UvGaussian> = gaussians_of(&groups)
        .into_iter()
        .filter(|g| g.opacity >= MIN_OPACITY)
        .collect();
    let error = fit_error(texture, ts, &kept);
    (kept, error)
}

/// The Gaussians of a set of billboards, in world space, structure of arrays.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct GaussianSet {
    /// Means in the dataset's world frame.
    pub positions: Vec<Vec3>,
    /// Unit rotations (local axes → world), columns = the Gaussian's principal axes.
    pub rotations: Vec<Quat>,
    /// Standard deviations along the local axes (linear, not log): in-plane `σ₁ ≥ σ₂`, then the
    /// thickness `σ₃`.
    pub scales: Vec<Vec3>,
    /// Peak opacities in `[MIN_OPACITY, MAX_OPACITY]`.
    pub opacities: Vec<f32>,
    /// SH coefficients, 48 per Gaussian, `[coeff][rgb]` as in [`crate::stages::sh`].
    pub sh: Vec<f32>,
    /// The SH degree the coefficients are meant for (the higher ones are 0).
    pub sh_degree: u32,
    /// Per exported billboard (in the order given), how many Gaussians it became.
    pub per_billboard: Vec<usize>,
    /// Per exported billboard, its fit error ([`fit_error`]).
    pub fit_errors: Vec<f32>,
}

impl GaussianSet {
    /// Number of Gaussians.
    pub fn len(&self) -> usize {
        self.positions.len()
    }

    /// True when there is no Gaussian.
    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }

    /// The 48 SH coefficients of Gaussian `i`.
    pub fn sh_of(&self, i: usize) -> &[f32] {
        &self.sh[i * SH_FLOATS..(i + 1) * SH_FLOATS]
    }
}

/// A world Gaussian: mean, rotation, standard deviations.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlacedGaussian {
    /// Mean in world coordinates.
    pub position: Vec3,
    /// Unit rotation, local axes → world.
    pub rotation: Quat,
    /// Standard deviations along the local axes (`σ₁ ≥ σ₂`, thickness `σ₃`).
    pub scale: Vec3,
}

/// The world Gaussian of the UV Gaussian `g` on the billboard with centre `position`, raw
/// quaternion `quaternion` (w, x, y, z) and log half sides `log_scale` (module docs).
///
/// ```
/// use bbsplat::export::gaussians::{UvGaussian, place};
/// use glam::{Vec2, Vec3};
/// // An unrotated billboard of half sides (2, 1): u is world x, v is world y.
/// let g = UvGaussian { mean: Vec2::new(0.5, 0.0), covariance: Vec3::new(0.01, 0.0, 0.04), opacity: 0.5, colour: Vec3::ZERO };
/// let p = place(Vec3::new(0.0, 0.0, 3.0), [1.0, 0.0, 0.0, 0.0], Vec2::new(2f32.ln(), 0.0), &g);
/// assert!((p.position - Vec3::new(1.0, 0.0, 3.0)).length() < 1e-6);
/// // S Σ S = diag(0.04, 0.04): equal eigenvalues, σ = 0.2 both ways.
/// assert!((p.scale.x - 0.2).abs() < 1e-6 && (p.scale.y - 0.2).abs() < 1e-6);
/// assert!((p.scale.z - 0.002).abs() < 1e-7);
/// assert!(((p.rotation * Vec3::Z) - Vec3::Z).length() < 1e-6); // the normal stays the normal
/// ```
pub fn place(position: Vec3, quaternion: [f32; 4], log_scale: Vec2, g: &UvGaussian) -> PlacedGaussian {
    let r = quat_to_rotation(quaternion);
    let s = Vec2::new(log_scale.x.exp(), log_scale.y.exp());
    let centre = position + r * Vec3::new(s.x * g.mean.x, s.y * g.mean.y, 0.0);
    let plane = Vec3::new(
        s.x * s.x * g.covariance.x,
        s.x * s.y * g.covariance.y,
        s.y * s.y * g.covariance.z,
    );
    let (l1, l2, e) = symmetric_eigen_2x2(plane);
    let local = Mat3::from_cols(Vec3::new(e.x, e.y, 0.0), Vec3::new(-e.y, e.x, 0.0), Vec3::Z);
    let (s1, s2) = (l1.sqrt(), l2.sqrt());
    PlacedGaussian {
        position: centre,
        rotation: Quat::from_mat3(&(r * local)).normalize(),
        scale: Vec3::new(s1, s2, FLAT_RATIO * s2),
    }
}

/// The Gaussians of the billboards `kept` of `set` (in `kept` order), each billboard fitted by
/// [`fit_billboard`] and placed by [`place`]; the SH are the billboard's up to `sh_degree` with
/// the fitted colour folded into the DC term (module docs). Billboards are fitted in parallel and
/// gathered in order: the same set for any number of threads.
pub fn billboards_as_gaussians(set: &ActivatedRef<'_>, kept: &[usize], sh_degree: u32, rule: &FitRule) -> GaussianSet {
    let ts = set.texture_size;
    let used = 3 * sh_coeff_count(sh_degree);
    let fits: Vec<(Vec<UvGaussian>, f32)> = kept
        .par_iter()
        .map(|&i| fit_billboard(set.texture_of(i), ts, rule))
        .collect();
    let mut out = GaussianSet {
        sh_degree,
        ..GaussianSet::default()
    };
    for (&i, (gaussians, error)) in kept.iter().zip(fits) {
        out.per_billboard.push(gaussians.len());
        out.fit_errors.push(error);
        for g in &gaussians {
            let placed = place(set.positions[i], set.quaternions[i], set.log_scales[i], g);
            out.positions.push(placed.position);
            out.rotations.push(placed.rotation);
            out.scales.push(placed.scale);
            out.opacities.push(g.opacity);
            let mut sh = [0.0f32; SH_FLOATS];
            sh[..used].copy_from_slice(&set.sh_of(i)[..used]);
            for c in 0..3 {
                sh[c] += g.colour[c] / SH_C0;
            }
            out.sh.extend_from_slice(&sh);
        }
    }
    out
}
