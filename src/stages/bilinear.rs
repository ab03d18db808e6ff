//! Bilinear texture sampling with zero padding, and its vector-Jacobian product.
//!
//! Conventions (see `docs/numerics-appearance.md`):
//! - A texture is `ts × ts` texels per channel (`ts ≥ 2`), stored `[channel][row][column]`
//!   (channel-major, then row-major). The row index comes from `v`, the column index from `u`.
//! - Align-corners mapping from billboard coordinates `(u, v) ∈ [−1, 1]²` to continuous texel
//!   coordinates: `X = (u + 1)/2 · (ts − 1)` (column), `Y = (v + 1)/2 · (ts − 1)` (row), so that
//!   texel 0 is centred at `u = −1` and texel `ts − 1` at `u = +1`.
//! - Zero padding: of the four taps `(⌊X⌋ + {0,1}, ⌊Y⌋ + {0,1})` only those inside
//!   `[0, ts − 1]²` contribute. The sampled value therefore fades linearly to 0 over one texel
//!   spacing outside the square and is exactly 0 for `|u|` or `|v| ≥ 1 + 2/(ts − 1)`.
//! - Exact texel borders (`X` or `Y` an integer) are where the interpolant's derivative jumps.
//!   The derivative returned there is that of the cell `[⌊X⌋, ⌊X⌋ + 1)`, i.e. the **right
//!   derivative** (one-sided, from increasing `u` or `v`). This holds at the zero-padded edges
//!   too: at `X = −1` the value is 0 but the derivative is that of the fade-in ramp.
//! - `X`, `Y` are computed in f64 (exactly, for `|u| ≥ 1` and `ts` up to 2²⁰) before the cell
//!   is chosen, so the support test is exact and no float-to-integer cast can see an
//!   out-of-range value: non-finite or huge `(u, v)` simply give no taps.
//!
//! The hot loop of the rasterizer computes [`BilinearTaps`] once per (billboard, pixel) and samples
//! the billboard's RGBA texture with them ([`BilinearTaps::sample_rgba`]): texels interleaved
//! `[r, g, b, alpha]`, so that the two taps of a texture row share one or two cache lines instead
//! of one line per channel. The planar functions (`[channel][row][column]`) are the reference the
//! RGBA ones are tested against.
//!
//! ```
//! use bbsplat::stages::bilinear;
//! // A 2×2 single-channel texture: [row 0: 0, 1; row 1: 2, 3].
//! let tex = [0.0, 1.0, 2.0, 3.0];
//! let mut out = [0.0];
//! bilinear::sample(&tex, 2, 1, 0.0, 0.0, &mut out); // the centre: mean of the four texels
//! assert!((out[0] - 1.5).abs() < 1e-6);
//! bilinear::sample(&tex, 2, 1, 1.0, -1.0, &mut out); // column 1, row 0
//! assert_eq!(out[0], 1.0);
//! // At the centre ∂/∂u = (ts − 1)/2 · mean column difference = 0.5 · 1 and ∂/∂v = 0.5 · 2.
//! let mut d_tex = [0.0; 4];
//! let (du, dv) = bilinear::sample_vjp(&tex, 2, 1, 0.0, 0.0, &[1.0], &mut d_tex);
//! assert!((du - 0.5).abs() < 1e-6 && (dv - 1.0).abs() < 1e-6);
//! assert_eq!(d_tex, [0.25; 4]);
//! ```

use crate::stages::ray_plane::LANES;
use glam::Vec4;

/// The (at most four) texels that contribute to a bilinear sample at one `(u, v)`, with their
/// weights and the derivatives of the weights with respect to `u` and `v`.
///
/// Only taps inside the texture are stored (zero padding), so [`BilinearTaps::len`] is 1, 2 or 4.
/// The indices are offsets inside one channel plane (`row · ts + column`); the same taps serve
/// every channel and every texture of the same size sampled at the same `(u, v)`.
/// `Σ weights = 1` whenever `|u|, |v| ≤ 1` (partition of unity, up to f32 rounding).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BilinearTaps {
    ts: u32,
    len: u32,
    index: [u32; 4],
    weight: [f32; 4],
    d_weight_du: [f32; 4],
    d_weight_dv: [f32; 4],
}

/// The part of [`BilinearTaps`] that sampling reads: the taps and their weights, without the
/// weight derivatives (40 bytes instead of 72). The rasterizer's forward pass keeps its
/// candidates in this form between finding them and sampling them
/// ([`BilinearTaps::for_sampling`]); [`BilinearTaps::sample_rgba`] is this type's
/// [`SampleTaps::sample_rgba`], so both forms sample with the same arithmetic.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SampleTaps {
    ts: u32,
    len: u32,
    index: [u32; 4],
    weight: [f32; 4],
}

impl SampleTaps {
    /// Texel offsets inside one channel plane (`row · ts + column`).
    #[inline]
    pub fn indices(&self) -> &[u32] {
        &self.index[..self.len as usize]
    }

    /// Samples an RGBA texture (see [`BilinearTaps::sample_rgba`], which calls this).
    ///
    /// # Panics
    /// If `texels.len() != ts²`.
    #[inline]
    pub fn sample_rgba(&self, texels: &[[f32; 4]]) -> [f32; 4] {
        check_rgba_texels(texels.len(), self.ts);
        let n = self.len as usize;
        if n == 4 {
            return sample_four(|i| texels[i as usize], self.index, self.weight, [KEEP; 4]);
        }
        let mut acc = Vec4::ZERO;
        for k in 0..n {
            acc += self.weight[k] * Vec4::from_array(texels[self.index[k] as usize]);
        }
        acc.to_array()
    }
}

/// Panics unless an RGBA texture of `texels` texels has side `ts` (`texels = ts²`).
#[inline(always)]
fn check_rgba_texels(texels: usize, ts: u32) {
    assert_eq!(
        texels,
        ts as usize * ts as usize,
        "texels must hold ts × ts RGBA values"
    );
}

/// The tap mask of a tap inside the texture (see [`sample_four`]): all bits set.
const KEEP: u32 = u32::MAX;

/// Texel `index` of `texels`, for the indices of a [`RowTaps`] only: [`taps_row`] clamps every
/// index's row and column into `0..ts`, so it is below `ts²`, and the callers check
/// `texels.len() == ts²` first ([`check_rgba_texels`]); the read skips the bounds check that
/// the compiler cannot prove away (two instructions per tap in the tile loops).
#[inline(always)]
fn rgba_texel(texels: &[[f32; 4]], index: u32) -> [f32; 4] {
    debug_assert!(
        (index as usize) < texels.len(),
        "a row tap's index is inside the texture"
    );
    // SAFETY: see above; `RowTaps` has private fields and `taps_row` is its only constructor.
    unsafe { *texels.get_unchecked(index as usize) }
}

/// The four-tap RGBA sample `Σ wₖ·texel[iₖ]` over the taps whose mask `masks[k]` is [`KEEP`],
/// summed in tap order from zero, each outside tap's product replaced by zero (mask 0; the one
/// copy of the sampling arithmetic: [`SampleTaps::sample_rgba`] and [`RowTaps::sample_rgba`]).
/// Replacing the product, not the weight, keeps an outside tap from adding `0 · ∞ = NaN`.
#[inline(always)]
fn sample_four(texel: impl Fn(u32) -> [f32; 4], index: [u32; 4], w: [f32; 4], masks: [u32; 4]) -> [f32; 4] {
    let (t0, t1, t2, t3) = (
        Vec4::from_array(texel(index[0])),
        Vec4::from_array(texel(index[1])),
        Vec4::from_array(texel(index[2])),
        Vec4::from_array(texel(index[3])),
    );
    // A bitwise and with the tap's mask: the product, or +0 for an outside tap.
    let keep = |k: usize, x: Vec4| Vec4::from_array(x.to_array().map(|c| f32::from_bits(c.to_bits() & masks[k])));
    (Vec4::ZERO + keep(0, w[0] * t0) + keep(1, w[1] * t1) + keep(2, w[2] * t2) + keep(3, w[3] * t3)).to_array()
}

/// The backward of [`sample_four`]: with the four taps' `(texel index, weight, ∂weight/∂u,
/// ∂weight/∂v)` and masks as there, calls `emit(texel, weight · d_rgba)` per inside tap (mask
/// [`KEEP`]) in tap order and returns `(∂L/∂u, ∂L/∂v)` (behind [`BilinearTaps::vjp_rgba`] and
/// [`RowTaps::vjp_rgba`]; its three pieces, [`seen_four`], [`masked_term`] and [`emit_four`],
/// are the one copy of this arithmetic, which [`RowTaps::vjp_rgba_lanes`] arranges lane-wise).
/// Every tap's texel is read, an outside tap's too (its index is clamped into the texture, or
/// 0), so that the four taps' values seen through the upstream gradient are computed side by
/// side; each is the sum a tap-by-tap loop forms, in its order, and an outside tap's terms are
/// replaced by +0 before they are added.
/// That changes no bit: a sum that starts at +0 is never −0, so adding +0 leaves it as it is,
/// and an outside tap never adds `0 · ∞ = NaN`.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn vjp_four(
    texel: impl Fn(u32) -> [f32; 4],
    index: [u32; 4],
    weight: [f32; 4],
    d_weight_du: [f32; 4],
    d_weight_dv: [f32; 4],
    masks: [u32; 4],
    d_rgba: [f32; 4],
    mut emit: impl FnMut(u32, [f32; 4]),
) -> (f32, f32) {
    let seen = seen_four(index.map(texel), d_rgba).to_array();
    let (mut du, mut dv) = (0.0f32, 0.0f32);
    for k in 0..4 {
        du += masked_term(d_weight_du[k], seen[k], masks[k]);
        dv += masked_term(d_weight_dv[k], seen[k], masks[k]);
    }
    emit_four(index, weight, masks, d_rgba, &mut emit);
    (du, dv)
}

/// Each of four taps' texels `t` seen through the upstream gradient `d_rgba` (lane `k` of the
/// result is tap `k`): `t·d` summed alpha first, then r, g, b (part of [`vjp_four`]).
#[inline(always)]
fn seen_four(t: [[f32; 4]; 4], d_rgba: [f32; 4]) -> Vec4 {
    // Lane k is tap k: its texel's channel c.
    let channel = |c: usize| Vec4::new(t[0][c], t[1][c], t[2][c], t[3][c]);
    channel(3) * d_rgba[3] + channel(0) * d_rgba[0] + channel(1) * d_rgba[1] + channel(2) * d_rgba[2]
}

/// One tap's term `∂weight · seen` of `∂L/∂u` or `∂L/∂v`, or +0 for an outside tap (mask 0;
/// part of [`vjp_four`]).
#[inline(always)]
fn masked_term(d_weight: f32, seen: f32, mask: u32) -> f32 {
    f32::from_bits((d_weight * seen).to_bits() & mask)
}

/// `emit(texel, weight · d_rgba)` per inside tap (mask [`KEEP`]), in tap order (part of
/// [`vjp_four`]).
#[inline(always)]
fn emit_four(
    index: [u32; 4],
    weight: [f32; 4],
    masks: [u32; 4],
    d_rgba: [f32; 4],
    emit: &mut impl FnMut(u32, [f32; 4]),
) {
    let d = Vec4::from_array(d_rgba);
    for k in 0..4 {
        if masks[k] == KEEP {
            emit(index[k], (weight[k] * d).to_array());
        }
    }
}

/// Continuous texel coordinate of a billboard coordinate: `(c + 1)/2 · (ts − 1)`, in f64.
///
/// In f64 the sum `c + 1` and the product are exact for `|c| ≥ 1` and `ts ≤ 2²⁰`, so the zero
/// support `|c| ≥ 1 + 2/(ts − 1)` maps to `X ≥ ts` or `X ≤ −1` exactly.
#[inline]
pub fn texel_coordinate(c: f32, ts: usize) -> f64 {
    (c as f64 + 1.0) * (0.5 * (ts - 1) as f64)
}

/// `⌊x⌋` for `x ∈ [−1, 65536]`, without `f64::floor` (a libm call on baseline x86-64): the
/// truncating cast is in range and exact there, then corrected for negative non-integers.
#[inline]
fn floor_in_range(x: f64) -> i64 {
    let t = x as i64;
    if (t as f64) > x { t - 1 } else { t }
}

/// The bilinear taps at `(u, v)` for a `ts × ts` texture, or `None` when no tap lies inside the
/// texture (`X ∉ [−1, ts)` or `Y ∉ [−1, ts)`, which includes NaN and infinite coordinates).
///
/// The half-open support matches the right-derivative convention: at `X = −1` the column-0 tap
/// is present with weight 0 (value 0, derivative of the fade-in ramp); at `X = ts` there is none.
///
/// # Panics
/// If `ts < 2` or `ts > 65536`.
///
/// ```
/// use bbsplat::stages::bilinear::taps;
/// let t = taps(0.3, -0.2, 16).unwrap();
/// assert_eq!(t.len(), 4);
/// assert!((t.weights().iter().sum::<f32>() - 1.0).abs() < 1e-6);
/// assert!(taps(f32::NAN, 0.0, 16).is_none());
/// assert!(taps(1.14, 0.0, 16).is_none()); // beyond 1 + 2/15: no support
/// // The f32 nearest to 1 + 2/15 lies just below it: still taps, with weights ~1e-7.
/// let edge = taps(1.0 + 2.0 / 15.0, 0.0, 16).unwrap();
/// assert!(edge.weights().iter().all(|&w| w < 1e-6));
/// assert!(taps(1e30, f32::NEG_INFINITY, 16).is_none());
/// ```
#[inline(always)]
pub fn taps(u: f32, v: f32, ts: usize) -> Option<BilinearTaps> {
    assert!((2..=65536).contains(&ts), "texture size must be in 2..=65536, got {ts}");
    let x = texel_coordinate(u, ts);
    let y = texel_coordinate(v, ts);
    let limit = ts as f64;
    // Written positively so that NaN fails the test. After it, x and y are in [−1, ts).
    if !(x >= -1.0 && x < limit && y >= -1.0 && y < limit) {
        return None;
    }
    let ix = floor_in_range(x);
    let iy = floor_in_range(y);
    let fx = (x - ix as f64) as f32;
    let fy = (y - iy as f64) as f32;
    let s = (0.5 * (ts - 1) as f64) as f32; // dX/du = dY/dv
    let gx = [1.0 - fx, fx];
    let gy = [1.0 - fy, fy];
    let dg = [-s, s];
    let n = ts as i64;
    if ix >= 0 && iy >= 0 && ix + 1 < n && iy + 1 < n {
        // Interior cell (the common case): all four taps, same order and arithmetic as below.
        let base = (iy * n + ix) as u32;
        let row = ts as u32;
        return Some(BilinearTaps {
            ts: ts as u32,
            len: 4,
            index: [base, base + 1, base + row, base + row + 1],
            weight: [gx[0] * gy[0], gx[1] * gy[0], gx[0] * gy[1], gx[1] * gy[1]],
            d_weight_du: [dg[0] * gy[0], dg[1] * gy[0], dg[0] * gy[1], dg[1] * gy[1]],
            d_weight_dv: [gx[0] * dg[0], gx[1] * dg[0], gx[0] * dg[1], gx[1] * dg[1]],
        });
    }
    let mut t = BilinearTaps {
        ts: ts as u32,
        len: 0,
        index: [0; 4],
        weight: [0.0; 4],
        d_weight_du: [0.0; 4],
        d_weight_dv: [0.0; 4],
    };
    for dy in 0..2 {
        let row = iy + dy as i64;
        if row < 0 || row >= n {
            continue;
        }
        for dx in 0..2 {
            let col = ix + dx as i64;
            if col < 0 || col >= n {
                continue;
            }
            let k = t.len as usize;
            t.index[k] = (row * n + col) as u32;
            t.weight[k] = gx[dx] * gy[dy];
            t.d_weight_du[k] = dg[dx] * gy[dy];
            t.d_weight_dv[k] = gx[dx] * dg[dy];
            t.len += 1;
        }
    }
    // x ∈ [−1, ts) guarantees at least one column (and one row) inside.
    debug_assert!(t.len > 0);
    Some(t)
}

impl BilinearTaps {
    /// Number of taps inside the texture (1, 2 or 4).
    #[inline]
    pub fn len(&self) -> usize {
        self.len as usize
    }

    /// Always false: a `BilinearTaps` is only built when at least one tap is inside.
    #[inline]
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The texture size `ts` the taps were computed for.
    #[inline]
    pub fn texture_size(&self) -> usize {
        self.ts as usize
    }

    /// Texel offsets inside one channel plane (`row · ts + column`).
    #[inline]
    pub fn indices(&self) -> &[u32] {
        &self.index[..self.len as usize]
    }

    /// Bilinear weights of the taps, in the order of [`BilinearTaps::indices`].
    #[inline]
    pub fn weights(&self) -> &[f32] {
        &self.weight[..self.len as usize]
    }

    /// `∂weight/∂u` of each tap (includes the factor `dX/du = (ts − 1)/2`; right derivative at
    /// texel borders).
    #[inline]
    pub fn weight_derivatives_u(&self) -> &[f32] {
        &self.d_weight_du[..self.len as usize]
    }

    /// `∂weight/∂v` of each tap (includes the factor `dY/dv = (ts − 1)/2`; right derivative at
    /// texel borders).
    #[inline]
    pub fn weight_derivatives_v(&self) -> &[f32] {
        &self.d_weight_dv[..self.len as usize]
    }

    /// Interior fast path (4 taps): fixed trip count, same summation order as the general loops.
    #[inline]
    fn dot4(&self, tex: &[f32]) -> f32 {
        let [i0, i1, i2, i3] = self.index.map(|i| i as usize);
        let w = self.weight;
        0.0 + w[0] * tex[i0] + w[1] * tex[i1] + w[2] * tex[i2] + w[3] * tex[i3]
    }

    #[inline]
    fn check_lengths(&self, texels: &[f32], channels: usize) -> usize {
        let plane = self.ts as usize * self.ts as usize;
        assert_eq!(
            texels.len(),
            plane * channels,
            "texels must hold channels × ts × ts values"
        );
        plane
    }

    /// Samples `channels` channels of `texels` (layout `[channel][row][column]`, `ts × ts` per
    /// channel) into `out[..channels]`.
    ///
    /// # Panics
    /// If `texels.len() != channels · ts²` or `out.len() < channels`.
    #[inline]
    pub fn sample(&self, texels: &[f32], channels: usize, out: &mut [f32]) {
        let plane = self.check_lengths(texels, channels);
        let out = &mut out[..channels];
        let n = self.len as usize;
        if n == 4 {
            for (tex, o) in texels.chunks_exact(plane).zip(out.iter_mut()) {
                *o = self.dot4(tex);
            }
            return;
        }
        for (c, o) in out.iter_mut().enumerate() {
            let tex = &texels[c * plane..(c + 1) * plane];
            let mut acc = 0.0;
            for k in 0..n {
                acc += self.weight[k] * tex[self.index[k] as usize];
            }
            *o = acc;
        }
    }

    /// Samples a single-channel texture (`ts × ts` values): the alpha texture's fast path.
    ///
    /// # Panics
    /// If `texels.len() != ts²`.
    #[inline]
    pub fn sample_one(&self, texels: &[f32]) -> f32 {
        self.check_lengths(texels, 1);
        let n = self.len as usize;
        if n == 4 {
            return self.dot4(texels);
        }
        let mut acc = 0.0;
        for k in 0..n {
            acc += self.weight[k] * texels[self.index[k] as usize];
        }
        acc
    }

    /// Backward of [`BilinearTaps::sample`]: given `d_out = ∂L/∂out[..channels]`, **adds**
    /// `∂L/∂texels` into `d_texels` (same layout as `texels`) and returns `(∂L/∂u, ∂L/∂v)`
    /// (right derivatives at texel borders).
    ///
    /// # Panics
    /// If `texels` or `d_texels` do not hold `channels · ts²` values or `d_out.len() < channels`.
    #[inline]
    pub fn accumulate_vjp(&self, texels: &[f32], channels: usize, d_out: &[f32], d_texels: &mut [f32]) -> (f32, f32) {
        let plane = self.check_lengths(texels, channels);
        assert_eq!(d_texels.len(), texels.len(), "d_texels must have the layout of texels");
        let n = self.len as usize;
        let (mut du, mut dv) = (0.0f32, 0.0f32);
        for (c, &g) in d_out[..channels].iter().enumerate() {
            let tex = &texels[c * plane..(c + 1) * plane];
            let d_tex = &mut d_texels[c * plane..(c + 1) * plane];
            let (mut su, mut sv) = (0.0f32, 0.0f32);
            for k in 0..n {
                let i = self.index[k] as usize;
                let t = tex[i];
                su += self.d_weight_du[k] * t;
                sv += self.d_weight_dv[k] * t;
                d_tex[i] += self.weight[k] * g;
            }
            du += su * g;
            dv += sv * g;
        }
        (du, dv)
    }

    /// Backward of [`BilinearTaps::sample_one`]: adds `g · weights` into `d_texels` and returns
    /// `(∂L/∂u, ∂L/∂v)` for the upstream gradient `g`.
    ///
    /// # Panics
    /// If `texels` or `d_texels` do not hold `ts²` values.
    #[inline]
    pub fn accumulate_vjp_one(&self, texels: &[f32], g: f32, d_texels: &mut [f32]) -> (f32, f32) {
        self.accumulate_vjp(texels, 1, &[g], d_texels)
    }

    /// Samples an RGBA texture: `ts × ts` texels `[r, g, b, alpha]`, row-major (the rasterizer's
    /// layout, see [`crate::raster::ActivatedRef::textures`]). Each channel is exactly what
    /// [`BilinearTaps::sample`] gives on that channel's plane (same products, same order).
    ///
    /// # Panics
    /// If `texels.len() != ts²`.
    #[inline]
    pub fn sample_rgba(&self, texels: &[[f32; 4]]) -> [f32; 4] {
        self.for_sampling().sample_rgba(texels)
    }

    /// The taps and weights alone (what [`SampleTaps::sample_rgba`] reads).
    #[inline(always)]
    pub fn for_sampling(&self) -> SampleTaps {
        SampleTaps {
            ts: self.ts,
            len: self.len,
            index: self.index,
            weight: self.weight,
        }
    }

    /// Backward of [`BilinearTaps::sample_rgba`] without a dense gradient buffer: calls
    /// `emit(texel_index, weight · d_rgba)` once per tap, in tap order, and returns
    /// `(∂L/∂u, ∂L/∂v)` for the upstream gradient `d_rgba = [∂L/∂r, ∂L/∂g, ∂L/∂b, ∂L/∂alpha]`.
    /// Equals [`BilinearTaps::accumulate_vjp`] on the four channel planes, up to the order of
    /// float additions (tested).
    ///
    /// # Panics
    /// If `texels.len() != ts²`.
    #[inline]
    pub fn vjp_rgba(&self, texels: &[[f32; 4]], d_rgba: [f32; 4], emit: impl FnMut(u32, [f32; 4])) -> (f32, f32) {
        check_rgba_texels(texels.len(), self.ts);
        // The taps past `len` are unused: index 0, masked out.
        let masks = std::array::from_fn(|k| if k < self.len as usize { KEEP } else { 0 });
        vjp_four(
            |i| texels[i as usize],
            self.index,
            self.weight,
            self.d_weight_du,
            self.d_weight_dv,
            masks,
            d_rgba,
            emit,
        )
    }
}

/// Bilinear sample of `channels` channels of a `ts × ts` texture at `(u, v)` into
/// `out[..channels]`; zeros when no tap is inside the texture (including non-finite `(u, v)`).
///
/// # Panics
/// If `ts` is out of `2..=65536`, `texels.len() != channels · ts²` or `out.len() < channels`.
pub fn sample(texels: &[f32], ts: usize, channels: usize, u: f32, v: f32, out: &mut [f32]) {
    match taps(u, v, ts) {
        Some(t) => t.sample(texels, channels, out),
        None => out[..channels].fill(0.0),
    }
}

/// Vector-Jacobian product of [`sample`]: **adds** `∂L/∂texels` into `d_texels` and returns
/// `(∂L/∂u, ∂L/∂v)`, given `d_out = ∂L/∂out[..channels]`. Both are zero when no tap is inside.
/// At exact texel borders the `(u, v)` derivative is the right derivative (see the module docs).
///
/// # Panics
/// As [`sample`], and if `d_texels.len() != texels.len()`.
pub fn sample_vjp(
    texels: &[f32],
    ts: usize,
    channels: usize,
    u: f32,
    v: f32,
    d_out: &[f32],
    d_texels: &mut [f32],
) -> (f32, f32) {
    match taps(u, v, ts) {
        Some(t) => t.accumulate_vjp(texels, channels, d_out, d_texels),
        None => (0.0, 0.0),
    }
}

/// The bilinear taps of [`LANES`] `(u, v)` pairs ([`taps_row`]), lane-wise. Every lane with
/// taps keeps all four of its cell's taps, in [`BilinearTaps`] order: a tap outside the texture
/// (zero padding, on the border ring `X` or `Y ∈ [−1, 0) ∪ [ts − 1, ts)`) has its row and column
/// clamped into the texture, so that it reads a texel the lane's inside taps read too, and a
/// zero mask in `keep`, so that its product is replaced by zero and it emits no gradient. Over
/// the inside taps this is [`taps`] exactly; the zeros added in between change no bit (a sum
/// that starts at +0 is never −0, and adding ±0 to anything else is exact).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RowTaps {
    ts: u32,
    /// The derivative arrays were computed (see [`taps_row_with`]).
    derivatives: bool,
    /// Texel index (`row · ts + column`, clamped into the texture) per tap and lane.
    index: [[u32; LANES]; 4],
    /// Weights per tap (`[tap][lane]`, taps in [`BilinearTaps`] order).
    weight: [[f32; LANES]; 4],
    /// `∂weight/∂u` per tap.
    d_weight_du: [[f32; LANES]; 4],
    /// `∂weight/∂v` per tap.
    d_weight_dv: [[f32; LANES]; 4],
    /// Per tap and lane: [`KEEP`] (all bits set) when the tap lies inside the texture, else 0;
    /// a mask so that sampling keeps or zeroes the tap's product with one bitwise and.
    keep: [[u32; LANES]; 4],
    /// The lane has taps: `X, Y ∈ [−1, ts)` (false for non-finite coordinates).
    has_taps: [bool; LANES],
}

/// [`taps`] for [`LANES`] coordinate pairs at once, computed lane by lane with no branch so that
/// the lanes run side by side in vector registers; [`RowTaps::lane`] gives lane `l`'s taps,
/// equal to `taps(u[l], v[l], ts)` bit for bit (the same operations in the same order: the f64
/// texel coordinates, the floor, the f32 fractions and products; tested in
/// `tests/suite/stage_lanes.rs`). The rasterizer's tile loops call this form.
///
/// # Panics
/// If `ts` is out of `2..=65536`.
#[inline(always)]
pub fn taps_row(u: &[f32; LANES], v: &[f32; LANES], ts: usize) -> RowTaps {
    taps_row_with::<true>(u, v, ts)
}

/// [`taps_row`] with the weights' derivatives only when `DERIVATIVES` (else they are left zero
/// and the taps are for sampling only: [`RowTaps::vjp_rgba`] must not be called on them, which
/// debug builds check). The forward pass, which only samples, skips their 32 products.
#[inline(always)]
pub(crate) fn taps_row_with<const DERIVATIVES: bool>(u: &[f32; LANES], v: &[f32; LANES], ts: usize) -> RowTaps {
    // Every value written once, in place: a zeroed `RowTaps` filled in afterwards was a
    // `memset` call per row of taps (4 % of a forward + backward's instructions).
    let mut taps = std::mem::MaybeUninit::<RowTaps>::uninit();
    let out = taps.as_mut_ptr();
    // SAFETY: `out` points into `taps`, which nothing reads before `assume_init`.
    unsafe {
        if !DERIVATIVES {
            (&raw mut (*out).d_weight_du).write([[0.0; LANES]; 4]);
            (&raw mut (*out).d_weight_dv).write([[0.0; LANES]; 4]);
        }
        write_taps_row::<DERIVATIVES>(out, u, v, ts);
    }
    // SAFETY: every field was written: the derivative arrays above (without `DERIVATIVES`),
    // and every other field by `write_taps_row`.
    unsafe { taps.assume_init() }
}

impl RowTaps {
    /// Overwrites `self` with `taps_row_with::<DERIVATIVES>(u, v, ts)` in place: the same
    /// values, except that without `DERIVATIVES` the derivative arrays keep their old values
    /// (which nothing may read: such taps are for sampling only). The tile loops keep one
    /// `RowTaps` and refill it per row of lanes, so that the 400 to 650 bytes of taps are
    /// neither zeroed nor copied into place each time.
    #[inline(always)]
    pub(crate) fn refill<const DERIVATIVES: bool>(&mut self, u: &[f32; LANES], v: &[f32; LANES], ts: usize) {
        // SAFETY: `self` is a valid, exclusively borrowed `RowTaps`; plain values are written
        // into its fields.
        unsafe { write_taps_row::<DERIVATIVES>(self, u, v, ts) }
    }
}

/// Writes every field of the [`RowTaps`] at `out` for `(u, v)`, except the derivative arrays
/// when not `DERIVATIVES`: the body of [`taps_row_with`] and [`RowTaps::refill`].
///
/// # Safety
/// `out` must be valid for writes of a `RowTaps` and not aliased while this runs.
#[inline(always)]
unsafe fn write_taps_row<const DERIVATIVES: bool>(out: *mut RowTaps, u: &[f32; LANES], v: &[f32; LANES], ts: usize) {
    assert!((2..=65536).contains(&ts), "texture size must be in 2..=65536, got {ts}");
    let n = ts as i32;
    let limit = ts as f64;
    let s = (0.5 * (ts - 1) as f64) as f32;
    // SAFETY: `out` is valid for writes (the caller's contract).
    unsafe {
        (&raw mut (*out).ts).write(ts as u32);
        (&raw mut (*out).derivatives).write(DERIVATIVES);
    }
    for lane in 0..LANES {
        let x = texel_coordinate(u[lane], ts);
        let y = texel_coordinate(v[lane], ts);
        // `floor_in_range` in i32, exact for the range with taps (other lanes are not used):
        // clamped first (`max` maps NaN to the bound), so the truncation needs no saturation.
        #[allow(clippy::manual_clamp)] // `clamp` would keep NaN, which the cast must not see.
        // SAFETY: the clamped values are finite and within i32.
        let (tx, ty) = unsafe {
            (
                x.max(-2.0).min(65_537.0).to_int_unchecked::<i32>(),
                y.max(-2.0).min(65_537.0).to_int_unchecked::<i32>(),
            )
        };
        let ix = if (tx as f64) > x { tx - 1 } else { tx };
        let iy = if (ty as f64) > y { ty - 1 } else { ty };
        let fx = (x - ix as f64) as f32;
        let fy = (y - iy as f64) as f32;
        let gx = [1.0 - fx, fx];
        let gy = [1.0 - fy, fy];
        let dg = [-s, s];
        // Written positively so that NaN fails the test, as in `taps`.
        let has_taps = x >= -1.0 && x < limit && y >= -1.0 && y < limit;
        let col_inside = [ix >= 0, ix + 1 < n];
        let row_inside = [iy >= 0, iy + 1 < n];
        let col = [ix.clamp(0, n - 1) as u32, (ix + 1).clamp(0, n - 1) as u32];
        let row = [iy.clamp(0, n - 1) as u32, (iy + 1).clamp(0, n - 1) as u32];
        // SAFETY: as above (the caller's contract); each (tap, lane) element is written once
        // by this loop.
        unsafe {
            (&raw mut (*out).has_taps[lane]).write(has_taps);
            for (k, (dy, dx)) in [(0, 0), (0, 1), (1, 0), (1, 1)].into_iter().enumerate() {
                (&raw mut (*out).index[k][lane]).write(row[dy] * ts as u32 + col[dx]);
                (&raw mut (*out).keep[k][lane]).write(if row_inside[dy] & col_inside[dx] { KEEP } else { 0 });
                (&raw mut (*out).weight[k][lane]).write(gx[dx] * gy[dy]);
                if DERIVATIVES {
                    (&raw mut (*out).d_weight_du[k][lane]).write(dg[dx] * gy[dy]);
                    (&raw mut (*out).d_weight_dv[k][lane]).write(gx[dx] * dg[dy]);
                }
            }
        }
    }
}

impl RowTaps {
    /// The taps of lane `lane`: `taps(u, v, ts)` for its coordinates `(u, v)`, bit for bit (its
    /// inside taps, in order), or `None` without taps.
    pub fn lane(&self, lane: usize) -> Option<BilinearTaps> {
        debug_assert!(self.derivatives, "taps for sampling only have no derivatives");
        if !self.has_taps[lane] {
            return None;
        }
        let mut t = BilinearTaps {
            ts: self.ts,
            len: 0,
            index: [0; 4],
            weight: [0.0; 4],
            d_weight_du: [0.0; 4],
            d_weight_dv: [0.0; 4],
        };
        for k in (0..4).filter(|&k| self.keep[k][lane] == KEEP) {
            let at = t.len as usize;
            t.index[at] = self.index[k][lane];
            t.weight[at] = self.weight[k][lane];
            t.d_weight_du[at] = self.d_weight_du[k][lane];
            t.d_weight_dv[at] = self.d_weight_dv[k][lane];
            t.len += 1;
        }
        Some(t)
    }

    /// Lane `lane`'s RGBA sample of `texels` (`ts²` RGBA texels): [`RowTaps::lane`] followed by
    /// [`BilinearTaps::sample_rgba`], bit for bit, or `None` without taps. The weights are read
    /// from the lanes directly (building a [`BilinearTaps`] by scalar stores and reading it back
    /// whole stalls the CPU).
    ///
    /// # Panics
    /// If `texels.len() != ts²`.
    #[inline(always)]
    pub fn sample_rgba(&self, lane: usize, texels: &[[f32; 4]]) -> Option<[f32; 4]> {
        if !self.has_taps[lane] {
            return None;
        }
        check_rgba_texels(texels.len(), self.ts);
        Some(sample_four(
            |i| rgba_texel(texels, i),
            std::array::from_fn(|k| self.index[k][lane]),
            std::array::from_fn(|k| self.weight[k][lane]),
            std::array::from_fn(|k| self.keep[k][lane]),
        ))
    }

    /// The lane arrays of the taps, for explicit vector code: per tap (in [`BilinearTaps`]
    /// order) and lane the texel index (clamped into the texture, so always below `ts²`), the
    /// weight and the keep mask (all bits set for a tap inside the texture, else 0), and per
    /// lane whether it has taps. [`RowTaps::sample_rgba`] is, for a lane with taps,
    /// `Σ_k (weight[k] · texel[index[k]]) & keep[k]`, summed from +0 in tap order.
    #[inline(always)]
    #[allow(clippy::type_complexity)]
    pub(crate) fn lane_arrays(
        &self,
    ) -> (
        &[[u32; LANES]; 4],
        &[[f32; LANES]; 4],
        &[[u32; LANES]; 4],
        &[bool; LANES],
    ) {
        (&self.index, &self.weight, &self.keep, &self.has_taps)
    }

    /// The weights' derivative arrays `(∂weight/∂u, ∂weight/∂v)` per tap and lane, for explicit
    /// vector code (taps made with derivatives only).
    #[inline(always)]
    #[allow(clippy::type_complexity)]
    pub(crate) fn derivative_arrays(&self) -> (&[[f32; LANES]; 4], &[[f32; LANES]; 4]) {
        debug_assert!(self.derivatives, "taps for sampling only have no derivatives");
        (&self.d_weight_du, &self.d_weight_dv)
    }

    /// The texture side the taps were computed for.
    #[inline(always)]
    pub(crate) fn texture_side(&self) -> usize {
        self.ts as usize
    }

    /// Lane `lane`'s [`BilinearTaps::vjp_rgba`], bit for bit, reading the lanes directly;
    /// `None` without taps.
    ///
    /// # Panics
    /// If `texels.len() != ts²`.
    #[inline(always)]
    pub fn vjp_rgba(
        &self,
        lane: usize,
        texels: &[[f32; 4]],
        d_rgba: [f32; 4],
        emit: impl FnMut(u32, [f32; 4]),
    ) -> Option<(f32, f32)> {
        debug_assert!(self.derivatives, "taps for sampling only have no derivatives");
        if !self.has_taps[lane] {
            return None;
        }
        check_rgba_texels(texels.len(), self.ts);
        Some(vjp_four(
            |i| rgba_texel(texels, i),
            std::array::from_fn(|k| self.index[k][lane]),
            std::array::from_fn(|k| self.weight[k][lane]),
            std::array::from_fn(|k| self.d_weight_du[k][lane]),
            std::array::from_fn(|k| self.d_weight_dv[k][lane]),
            std::array::from_fn(|k| self.keep[k][lane]),
            d_rgba,
            emit,
        ))
    }

    /// [`RowTaps::vjp_rgba`] of every lane `l` with `active[l]`, in lane order, with upstream
    /// gradient `d_rgba[l]`: the same calls of `emit`, in the same order, and per lane the same
    /// `(∂L/∂u, ∂L/∂v)` bit for bit, or `(0, 0)` for a lane that is not active or has no taps
    /// (where [`RowTaps::vjp_rgba`] gives `None`). The tile backward's form: the texel reads and
    /// emits go lane by lane, but the `∂weight · seen` sums run for the eight lanes side by side
    /// on the tap-major arrays, instead of each lane gathering its taps' derivatives one by one.
    ///
    /// # Panics
    /// If `texels.len() != ts²`.
    #[inline(always)]
    pub(crate) fn vjp_rgba_lanes(
        &self,
        texels: &[[f32; 4]],
        d_rgba: &[[f32; 4]; LANES],
        active: &[bool; LANES],
        mut emit: impl FnMut(u32, [f32; 4]),
    ) -> ([f32; LANES], [f32; LANES]) {
        debug_assert!(self.derivatives, "taps for sampling only have no derivatives");
        check_rgba_texels(texels.len(), self.ts);
        // Per tap and lane: the tap's texel seen through the lane's upstream gradient.
        let mut seen = [[0.0f32; LANES]; 4];
        // Set in the loop: the same flags derived up front cost 1.5 % more instructions per
        // object forward + backward (measured; the compiler lays the loop out worse).
        let mut used = [false; LANES];
        for lane in 0..LANES {
            if !(active[lane] && self.has_taps[lane]) {
                continue;
            }
            used[lane] = true;
            let index: [u32; 4] = std::array::from_fn(|k| self.index[k][lane]);
            let lane_seen = seen_four(index.map(|i| rgba_texel(texels, i)), d_rgba[lane]).to_array();
            for k in 0..4 {
                seen[k][lane] = lane_seen[k];
            }
            emit_four(
                index,
                std::array::from_fn(|k| self.weight[k][lane]),
                std::array::from_fn(|k| self.keep[k][lane]),
                d_rgba[lane],
                &mut emit,
            );
        }
        let (mut du, mut dv) = ([0.0f32; LANES], [0.0f32; LANES]);
        for k in 0..4 {
            for l in 0..LANES {
                du[l] += masked_term(self.d_weight_du[k][l], seen[k][l], self.keep[k][l]);
                dv[l] += masked_term(self.d_weight_dv[k][l], seen[k][l], self.keep[k][l]);
            }
        }
        // A lane that read no texels has no gradient (its derivative arrays may hold anything).
        for l in 0..LANES {
            if !used[l] {
                (du[l], dv[l]) = (0.0, 0.0);
            }
        }
        (du, dv)
    }

    /// The taps and weights of lane `lane` (what sampling reads): [`RowTaps::lane`] followed by
    /// [`BilinearTaps::for_sampling`].
    pub fn lane_for_sampling(&self, lane: usize) -> Option<SampleTaps> {
        self.lane(lane).map(|t| t.for_sampling())
    }
}
