//! View-dependent colour from real spherical harmonics (degrees 0-3), and its backward pass.
//!
//! Conventions (see `docs/numerics-appearance.md`; identical to 3DGS, gsplat and Brush):
//! - Real SH with the Sloan (JCGT 2013) constants, index `k` over `(l, m)` in the order
//!   `l = 0`; `l = 1, m = −1, 0, 1`; … so degree `d` uses the first `(d + 1)²` of 16 functions.
//!   For a unit direction `(x, y, z)`: `Y₀ = 0.28209…`, `Y₁ = −0.48860·y`, `Y₂ = 0.48860·z`,
//!   `Y₃ = −0.48860·x`, then the degree-2 and degree-3 polynomials of [`sh_basis`].
//! - Coefficients are stored `[coeff k][rgb]` interleaved: 16 × 3 = 48 floats per primitive,
//!   `coeffs[3k + c]`. Only the first `3·(degree + 1)²` are read.
//! - The view direction is `normalize(view_offset)`, where `view_offset = position − camera_centre`
//!   is the vector from the camera centre to the point in the world frame. The functions take the
//!   offset, not the two points, so that the caller can form it accurately: the rasterizer uses
//!   [`crate::camera::Camera::view_offset`], which subtracts in f64 (in f32, positions and a camera
//!   centre near 1e4 lose about 1e-3 of the offset, 1e-4 of the colour).
//!   The position gradient the backward returns is `∂L/∂view_offset`, which equals `∂L/∂position`.
//! - Colour per channel is `max(Σₖ Yₖ(dir)·coeffs[3k + c] + 0.5, 0)` (clamped at 0, no upper
//!   clamp). A channel is *clamped* when the sum plus 0.5 is **strictly** negative; its gradient
//!   is then 0 (at exactly 0 the gradient passes).
//! - Degenerate direction: when `|view_offset| ≤` [`SH_MIN_DISTANCE`] or the
//!   squared distance is not finite (NaN or overflowing coordinates), only degree 0 is evaluated
//!   (the direction-averaged colour: higher bands integrate to 0 over the sphere), and the
//!   position gradient is exactly 0.
//!
//! ```
//! use bbsplat::stages::sh::{rgb_to_sh, sh_colour, SH_FLOATS};
//! use glam::Vec3;
//! let mut coeffs = [0.0f32; SH_FLOATS];
//! coeffs[..3].copy_from_slice(&[rgb_to_sh(0.2), rgb_to_sh(0.5), rgb_to_sh(0.9)]);
//! let c = sh_colour(3, &coeffs, Vec3::new(1.0, 2.0, 3.0));
//! assert!((c.rgb - Vec3::new(0.2, 0.5, 0.9)).abs().max_element() < 1e-6);
//! assert_eq!(c.clamped, [false; 3]);
//! ```

use glam::Vec3;

// The constants are written as f64 literals (the closed forms' values) and rounded to f32 once.

/// `Y₀₀ = 1/(2√π)`.
pub const SH_C0: f32 = 0.28209479177387814_f64 as f32;
/// Degree-1 constant `√3/(2√π)`: `Y₁ = −C1·y`, `Y₂ = C1·z`, `Y₃ = −C1·x`.
pub const SH_C1: f32 = 0.4886025119029199_f64 as f32;
/// Degree-2 constants: `k4 = C2[0]·xy`, `k5 = C2[1]·yz`, `k6 = C2[2]·z² + C2[3]`,
/// `k7 = C2[1]·xz`, `k8 = C2[4]·(x² − y²)`.
pub const SH_C2: [f32; 5] = [
    1.0925484305920792_f64 as f32,   // √15/(2√π)
    -1.0925484305920792_f64 as f32,  // −√15/(2√π)
    0.9461746957575602_f64 as f32,   // 3√5/(4√π)
    -0.31539156525252005_f64 as f32, // −√5/(4√π)
    0.5462742152960396_f64 as f32,   // √15/(4√π)
];
/// Degree-3 constants: with `c1 = x² − y²`, `s1 = 2xy`, `c2 = x·c1 − y·s1`, `s2 = x·s1 + y·c1`:
/// `k9 = C3[0]·s2`, `k10 = C3[1]·z·s1`, `k11 = (C3[2]·z² + C3[3])·y`,
/// `k12 = z·(C3[4]·z² + C3[5])`, `k13 = (C3[2]·z² + C3[3])·x`, `k14 = C3[1]·z·c1`,
/// `k15 = C3[0]·c2`.
pub const SH_C3: [f32; 6] = [
    -0.5900435899266435_f64 as f32, // −√70/(8√π)
    1.4453057213202771_f64 as f32,  // √105/(4√π)
    -2.2852289973223288_f64 as f32, // −5√42/(8√π)
    0.4570457994644658_f64 as f32,  // √42/(8√π)
    1.865881662950577_f64 as f32,   // 5√7/(4√π)
    -1.1195289977703464_f64 as f32, // −3√7/(4√π)
];

/// Highest supported degree.
pub const SH_MAX_DEGREE: u32 = 3;
/// Number of basis functions at the highest degree, `(3 + 1)²`.
pub const SH_COEFFS: usize = 16;
/// Floats of one primitive's coefficients, `16 × 3`.
pub const SH_FLOATS: usize = SH_COEFFS * 3;
/// Below this camera-to-point distance (world units) the view direction is treated as undefined
/// and only degree 0 is evaluated. Rendered primitives are at least the near plane (0.2) away,
/// so this only guards culled or degenerate cases; 1e-6 keeps `1/|d|` (the scale of the position
/// gradient) finite and far from overflow.
pub const SH_MIN_DISTANCE: f32 = 1e-6;

/// Number of basis functions used by `degree`, `(degree + 1)²`.
#[inline]
pub const fn sh_coeff_count(degree: u32) -> usize {
    ((degree + 1) * (degree + 1)) as usize
}

/// Colour to degree-0 coefficient: `(c − 0.5)/SH_C0`.
#[inline]
pub fn rgb_to_sh(c: f32) -> f32 {
    (c - 0.5) / SH_C0
}

/// Degree-0 coefficient to colour (before the clamp): `s·SH_C0 + 0.5`.
#[inline]
pub fn sh_to_rgb(s: f32) -> f32 {
    s * SH_C0 + 0.5
}

/// The property names of a 3DGS PLY vertex up to its SH coefficients, in file order: `x y z nx
/// ny nz f_dc_0..2 f_rest_0..44` (the f_rest values in [`channel_major_rest`]'s order); the model's
/// PLY and the splat export's PLY each append their own shape properties.
///
/// ```
/// let names = bbsplat::stages::sh::ply_position_and_sh_names();
/// assert_eq!((names.len(), names[6].as_str(), names[53].as_str()), (54, "f_dc_0", "f_rest_44"));
/// ```
pub fn ply_position_and_sh_names() -> Vec<String> {
    let mut names: Vec<String> = ["x", "y", "z", "nx", "ny", "nz"]
        .iter()
        .map(|s| s.to_string())
        .collect();
    names.extend((0..3).map(|i| format!("f_dc_{i}")));
    names.extend((0..45).map(|i| format!("f_rest_{i}")));
    names
}

/// The 45 higher-degree coefficients of `coeffs` (48 floats, `[coeff][rgb]`) in the channel-major
/// order of the 3DGS PLY (`f_rest_{15·c + k − 1}` = coefficient `k ≥ 1` of channel `c`): the
/// layout of the model's and the splat export's PLY files.
///
/// ```
/// use bbsplat::stages::sh::channel_major_rest;
/// let coeffs: Vec<f32> = (0..48).map(|i| i as f32).collect();
/// let rest = channel_major_rest(&coeffs);
/// assert_eq!((rest[0], rest[1], rest[15], rest[44]), (3.0, 6.0, 4.0, 47.0));
/// ```
pub fn channel_major_rest(coeffs: &[f32]) -> [f32; 45] {
    let mut rest = [0.0f32; 45];
    for c in 0..3 {
        for k in 1..SH_COEFFS {
            rest[15 * c + k - 1] = coeffs[3 * k + c];
        }
    }
    rest
}

#[inline]
fn check_degree(degree: u32) {
    assert!(degree <= SH_MAX_DEGREE, "SH degree must be 0..=3, got {degree}");
}

/// Evaluates the real SH basis up to `degree` at the unit direction `dir` into
/// `out[..(degree + 1)²]`; the remaining entries are set to 0.
///
/// `dir` is not normalised here (the polynomials are evaluated as given).
///
/// # Panics
/// If `degree > 3`.
///
/// ```
/// use bbsplat::stages::sh::{sh_basis, SH_C0, SH_C1};
/// use glam::Vec3;
/// let mut b = [0.0; 16];
/// sh_basis(1, Vec3::Z, &mut b);
/// assert_eq!(&b[..4], &[SH_C0, 0.0, SH_C1, 0.0]);
/// assert!(b[4..].iter().all(|&x| x == 0.0));
/// ```
#[inline]
pub fn sh_basis(degree: u32, dir: Vec3, out: &mut [f32; 16]) {
    check_degree(degree);
    *out = [0.0; 16];
    out[0] = SH_C0;
    if degree == 0 {
        return;
    }
    let (x, y, z) = (dir.x, dir.y, dir.z);
    out[1] = -SH_C1 * y;
    out[2] = SH_C1 * z;
    out[3] = -SH_C1 * x;
    if degree == 1 {
        return;
    }
    let (xx, yy, zz) = (x * x, y * y, z * z);
    out[4] = SH_C2[0] * x * y;
    out[5] = SH_C2[1] * y * z;
    out[6] = SH_C2[2] * zz + SH_C2[3];
    out[7] = SH_C2[1] * x * z;
    out[8] = SH_C2[4] * (xx - yy);
    if degree == 2 {
        return;
    }
    let c1 = xx - yy;
    let s1 = 2.0 * x * y;
    let c2 = x * c1 - y * s1;
    let s2 = x * s1 + y * c1;
    let p = SH_C3[2] * zz + SH_C3[3];
    out[9] = SH_C3[0] * s2;
    out[10] = SH_C3[1] * z * s1;
    out[11] = p * y;
    out[12] = z * (SH_C3[4] * zz + SH_C3[5]);
    out[13] = p * x;
    out[14] = SH_C3[1] * z * c1;
    out[15] = SH_C3[0] * c2;
}

/// Vector-Jacobian product of [`sh_basis`] with respect to the direction components, treating
/// `x, y, z` as independent variables: returns `Σₖ d_basis[k]·∇Yₖ(dir)` over the first
/// `(degree + 1)²` entries. (Project onto the tangent plane for a unit-vector constraint.)
///
/// # Panics
/// If `degree > 3`.
#[inline]
pub fn sh_basis_vjp(degree: u32, dir: Vec3, d_basis: &[f32; 16]) -> Vec3 {
    check_degree(degree);
    if degree == 0 {
        return Vec3::ZERO;
    }
    let (x, y, z) = (dir.x, dir.y, dir.z);
    let b = d_basis;
    let mut gx = -SH_C1 * b[3];
    let mut gy = -SH_C1 * b[1];
    let mut gz = SH_C1 * b[2];
    if degree >= 2 {
        let a = SH_C2[0];
        // k4 = a·xy, k5 = −a·yz, k6 = C·z² + D, k7 = −a·xz, k8 = (a/2)(x² − y²).
        gx += a * (y * b[4] - z * b[7] + x * b[8]);
        gy += a * (x * b[4] - z * b[5] - y * b[8]);
        gz += -a * (y * b[5] + x * b[7]) + 2.0 * SH_C2[2] * z * b[6];
    }
    if degree >= 3 {
        let (xx, yy, zz) = (x * x, y * y, z * z);
        let c0 = SH_C3[0];
        let c1 = SH_C3[1];
        let p = SH_C3[2] * zz + SH_C3[3];
        let dp = 2.0 * SH_C3[2] * z;
        // k9 = c0·(3x²y − y³)
        gx += c0 * 6.0 * x * y * b[9];
        gy += c0 * 3.0 * (xx - yy) * b[9];
        // k10 = 2·c1·xyz
        gx += 2.0 * c1 * y * z * b[10];
        gy += 2.0 * c1 * x * z * b[10];
        gz += 2.0 * c1 * x * y * b[10];
        // k11 = p(z)·y
        gy += p * b[11];
        gz += dp * y * b[11];
        // k12 = C3[4]·z³ + C3[5]·z
        gz += (3.0 * SH_C3[4] * zz + SH_C3[5]) * b[12];
        // k13 = p(z)·x
        gx += p * b[13];
        gz += dp * x * b[13];
        // k14 = c1·z·(x² − y²)
        gx += 2.0 * c1 * z * x * b[14];
        gy -= 2.0 * c1 * z * y * b[14];
        gz += c1 * (xx - yy) * b[14];
        // k15 = c0·(x³ − 3xy²)
        gx += c0 * 3.0 * (xx - yy) * b[15];
        gy -= c0 * 6.0 * x * y * b[15];
    }
    Vec3::new(gx, gy, gz)
}

/// SH colour of one primitive.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ShColour {
    /// `max(Σ Yₖ coeffsₖ + 0.5, 0)` per channel.
    pub rgb: Vec3,
    /// Per channel: the sum plus 0.5 was strictly negative and the channel was clamped to 0
    /// (its gradient is 0).
    pub clamped: [bool; 3],
}

/// The view direction and its length, or `None` when degenerate (see the module docs).
#[inline]
fn view_direction(view_offset: Vec3) -> Option<(Vec3, f32)> {
    let d = view_offset;
    let len2 = d.length_squared();
    // Written positively: NaN and +inf are degenerate.
    if len2 > SH_MIN_DISTANCE * SH_MIN_DISTANCE && len2 < f32::INFINITY {
        let len = len2.sqrt();
        Some((d / len, len))
    } else {
        None
    }
}

/// Basis values and the effective degree at the view direction.
#[inline]
fn basis_for(degree: u32, view_offset: Vec3, basis: &mut [f32; 16]) -> Option<(Vec3, f32)> {
    check_degree(degree);
    // Degree 0 is view-independent: no direction needed.
    let view = if degree > 0 { view_direction(view_offset) } else { None };
    match view {
        Some((dir, _)) => sh_basis(degree, dir, basis),
        None => sh_basis(0, Vec3::ZERO, basis),
    }
    view
}

#[inline]
fn raw_colour(n: usize, coeffs: &[f32], basis: &[f32; 16]) -> [f32; 3] {
    assert!(coeffs.len() >= 3 * n, "need 3·(degree + 1)² coefficients");
    let mut raw = [0.5f32; 3];
    for (c, &b) in coeffs[..3 * n].chunks_exact(3).zip(&basis[..n]) {
        raw[0] += b * c[0];
        raw[1] += b * c[1];
        raw[2] += b * c[2];
    }
    raw
}

/// Colour of a primitive seen along `view_offset` (its position minus the camera centre), from SH coefficients of
/// `degree` (layout `[coeff][rgb]`, at least `3·(degree + 1)²` values).
///
/// # Panics
/// If `degree > 3` or `coeffs` is too short.
pub fn sh_colour(degree: u32, coeffs: &[f32], view_offset: Vec3) -> ShColour {
    let mut basis = [0.0; 16];
    let view = basis_for(degree, view_offset, &mut basis);
    let n = if view.is_some() { sh_coeff_count(degree) } else { 1 };
    clamp_colour(raw_colour(n, coeffs, &basis))
}

/// `max(raw, 0)` per channel, with the clamp flags.
#[inline]
fn clamp_colour(raw: [f32; 3]) -> ShColour {
    ShColour {
        rgb: Vec3::from_array(raw.map(|r| if r < 0.0 { 0.0 } else { r })),
        clamped: raw.map(|r| r < 0.0),
    }
}

/// [`sh_colour`] of `L` primitives at once (`coeffs[l]` seen along `view_offsets[l]`), bit for bit the same
/// values as `L` separate calls (tested).
///
/// Each channel's sum over the coefficients is a chain of dependent additions; a single call
/// waits on three such chains. Here the `L` primitives' chains are interleaved, coefficient by
/// coefficient, so the processor works on `3·L` independent chains at once. Every primitive's
/// own arithmetic, and so its result, is exactly that of [`sh_colour`]. When the primitives do
/// not all use the same number of coefficients (a degenerate view direction falls back to
/// degree 0), it is `L` separate calls.
///
/// # Panics
/// If `degree > 3` or a coefficient slice is too short.
///
/// ```
/// use bbsplat::stages::sh::{sh_colour, sh_colour_batch, SH_FLOATS};
/// use glam::Vec3;
/// let a: Vec<f32> = (0..SH_FLOATS).map(|k| (k as f32 * 0.37).sin()).collect();
/// let b: Vec<f32> = (0..SH_FLOATS).map(|k| (k as f32 * 0.11).cos()).collect();
/// let (pa, pb, eye) = (Vec3::new(1.0, 2.0, 3.0), Vec3::new(-1.0, 0.5, 2.0), Vec3::ZERO);
/// let both = sh_colour_batch(3, [&a, &b], ([pa, pb]).map(|p| p - eye));
/// assert_eq!(both, [sh_colour(3, &a, pa - eye), sh_colour(3, &b, pb - eye)]);
/// assert_eq!(sh_colour_batch::<0>(3, [], []), []); // an empty batch is fine
/// ```
pub fn sh_colour_batch<const L: usize>(degree: u32, coeffs: [&[f32]; L], view_offsets: [Vec3; L]) -> [ShColour; L] {
    let mut basis = [[0.0f32; 16]; L];
    let mut counts = [1usize; L];
    for l in 0..L {
        let view = basis_for(degree, view_offsets[l], &mut basis[l]);
        counts[l] = if view.is_some() { sh_coeff_count(degree) } else { 1 };
    }
    // (`L = 0`: nothing to evaluate; the loops below are empty.)
    let n = counts.first().copied().unwrap_or(1);
    if counts.iter().any(|&m| m != n) {
        return std::array::from_fn(|l| clamp_colour(raw_colour(counts[l], coeffs[l], &basis[l])));
    }
    raw_colours(n, coeffs, &basis).map(clamp_colour)
}

/// Vector-Jacobian product of [`sh_colour`] for `d_rgb = ∂L/∂rgb`: **adds** `∂L/∂coeffs` into
/// `d_coeffs` (same layout, at least `3·(degree + 1)²` values) and returns `∂L/∂view_offset`
/// (= `∂L/∂position`) through the normalised view direction. (`∂L/∂camera_centre` is its negative.) Clamped
/// channels contribute nothing; a degenerate direction gives a zero position gradient and
/// gradients for the degree-0 coefficients only.
///
/// # Panics
/// If `degree > 3` or `coeffs`/`d_coeffs` are too short.
///
/// ```
/// use bbsplat::stages::sh::{sh_colour_vjp, SH_C0, SH_FLOATS};
/// use glam::Vec3;
/// let coeffs = [0.1f32; SH_FLOATS];
/// let mut d = [0.0f32; SH_FLOATS];
/// let dp = sh_colour_vjp(0, &coeffs, Vec3::X, Vec3::new(1.0, 0.0, 2.0), &mut d);
/// assert_eq!(dp, Vec3::ZERO); // degree 0 is view-independent
/// assert_eq!(&d[..3], &[SH_C0, 0.0, 2.0 * SH_C0]);
/// ```
pub fn sh_colour_vjp(degree: u32, coeffs: &[f32], view_offset: Vec3, d_rgb: Vec3, d_coeffs: &mut [f32]) -> Vec3 {
    let mut basis = [0.0; 16];
    let view = basis_for(degree, view_offset, &mut basis);
    let n = if view.is_some() { sh_coeff_count(degree) } else { 1 };
    let raw = raw_colour(n, coeffs, &basis);
    colour_vjp(degree, coeffs, &basis, view, raw.map(|r| r < 0.0), d_rgb, d_coeffs)
}

/// [`sh_colour_vjp`] given the forward's clamp flags ([`ShColour::clamped`] of the same
/// arguments) instead of re-evaluating the colour: the same values bit for bit, one pass over the
/// coefficients fewer. The rasterizer's backward calls it with the flags its forward kept.
///
/// # Panics
/// If `degree > 3` or `coeffs`/`d_coeffs` are too short.
///
/// ```
/// use bbsplat::stages::sh::{sh_colour, sh_colour_vjp, sh_colour_vjp_clamped, SH_FLOATS};
/// use glam::Vec3;
/// let coeffs: Vec<f32> = (0..SH_FLOATS).map(|k| ((k * 7) % 11) as f32 * 0.1 - 0.5).collect();
/// let (p, eye, d_rgb) = (Vec3::new(0.3, -0.2, 1.0), Vec3::ZERO, Vec3::new(1.0, -2.0, 0.5));
/// let (mut a, mut b) = ([0.0f32; SH_FLOATS], [0.0f32; SH_FLOATS]);
/// let clamped = sh_colour(3, &coeffs, p - eye).clamped;
/// let dp = sh_colour_vjp_clamped(3, &coeffs, p - eye, clamped, d_rgb, &mut a);
/// assert_eq!(dp, sh_colour_vjp(3, &coeffs, p - eye, d_rgb, &mut b));
/// assert_eq!(a, b);
/// ```
pub fn sh_colour_vjp_clamped(
    degree: u32,
    coeffs: &[f32],
    view_offset: Vec3,
    clamped: [bool; 3],
    d_rgb: Vec3,
    d_coeffs: &mut [f32],
) -> Vec3 {
    let mut basis = [0.0; 16];
    let view = basis_for(degree, view_offset, &mut basis);
    colour_vjp(degree, coeffs, &basis, view, clamped, d_rgb, d_coeffs)
}

// The coefficient part of `colour_vjp` and the batched raw colours of `sh_colour_batch`: on
// x86-64 the SSE kernels of `sh_sse` (bit-identical to the scalar references below, tested),
// elsewhere those references.
#[cfg(target_arch = "x86_64")]
pub(crate) use super::sh_sse::{coefficient_pass, raw_colours};
#[cfg(not(target_arch = "x86_64"))]
pub(crate) use {coefficient_pass_scalar as coefficient_pass, raw_colours_scalar as raw_colours};

/// The plain scalar reference of the batched raw colours (the SSE `raw_colours` on x86-64): per
/// primitive and channel `0.5 + Σₖ basis[k]·coeffs[3k + c]`, in increasing `k`, the primitives'
/// sums advancing together.
#[cfg_attr(target_arch = "x86_64", allow(dead_code))]
pub(crate) fn raw_colours_scalar<const L: usize>(
    n: usize,
    coeffs: [&[f32]; L],
    basis: &[[f32; 16]; L],
) -> [[f32; 3]; L] {
    for c in &coeffs {
        assert!(c.len() >= 3 * n, "need 3·(degree + 1)² coefficients");
    }
    let mut raw = [[0.5f32; 3]; L];
    for k in 0..n {
        for l in 0..L {
            let c = &coeffs[l][3 * k..3 * k + 3];
            let b = basis[l][k];
            raw[l][0] += b * c[0];
            raw[l][1] += b * c[1];
            raw[l][2] += b * c[2];
        }
    }
    raw
}

/// The plain scalar reference of the VJP's coefficient pass (the SSE `coefficient_pass` on
/// x86-64, which also uses it for the basis functions left over after its groups of four):
/// adds `Yₖ·g_c` to `d_coeffs[3k + c]` and sets `d_basis[k] = (g₀·coeffs[3k] +
/// g₁·coeffs[3k + 1]) + g₂·coeffs[3k + 2]` for `k < n`.
pub(crate) fn coefficient_pass_scalar(
    n: usize,
    coeffs: &[f32],
    basis: &[f32],
    g: [f32; 3],
    d_coeffs: &mut [f32],
    d_basis: &mut [f32],
) {
    let rows = coeffs[..3 * n]
        .chunks_exact(3)
        .zip(d_coeffs[..3 * n].chunks_exact_mut(3));
    for (((c, d), &b), db) in rows.zip(&basis[..n]).zip(&mut d_basis[..n]) {
        d[0] += b * g[0];
        d[1] += b * g[1];
        d[2] += b * g[2];
        *db = g[0] * c[0] + g[1] * c[1] + g[2] * c[2];
    }
}

/// The chain of [`sh_colour_vjp`] after the basis and the clamp flags are known.
#[inline]
fn colour_vjp(
    degree: u32,
    coeffs: &[f32],
    basis: &[f32; 16],
    view: Option<(Vec3, f32)>,
    clamped: [bool; 3],
    d_rgb: Vec3,
    d_coeffs: &mut [f32],
) -> Vec3 {
    let n = if view.is_some() { sh_coeff_count(degree) } else { 1 };
    assert!(coeffs.len() >= 3 * n, "need 3·(degree + 1)² coefficients");
    assert!(d_coeffs.len() >= 3 * n, "need 3·(degree + 1)² coefficient gradients");
    let g = [0, 1, 2].map(|c| if clamped[c] { 0.0 } else { d_rgb[c] });
    // One pass over the coefficients: `∂L/∂coeffs[3k + c] += Yₖ·g_c` and
    // `∂L/∂Yₖ = Σ_c g_c·coeffs[3k + c]`.
    let mut d_basis = [0.0f32; 16];
    coefficient_pass(n, coeffs, basis, g, d_coeffs, &mut d_basis);
    let Some((dir, len)) = view else {
        return Vec3::ZERO;
    };
    if degree == 0 {
        return Vec3::ZERO;
    }
    let d_dir = sh_basis_vjp(degree, dir, &d_basis);
    // dir = d/|d|: ∂dir/∂d = (I − dir dirᵀ)/|d|.
    (d_dir - dir * dir.dot(d_dir)) / len
}
