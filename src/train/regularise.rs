//! Regularisers of the training loss (the BBSplat spec, §5.4-5.5), as pure functions.
//!
//! Conventions: textures are *activated* values (sigmoid of the logits) laid out as in
//! [`crate::raster::ActivatedRef::textures`]: `T = TS²` RGBA texels `[r, g, b, alpha]` per
//! billboard. Every function returns the value in f64 and *adds* its gradient with respect to the
//! activated textures into a buffer of the same layout; [`chain_sigmoid`] carries an
//! activated-space gradient (planar, as the model's logits) to the logits and applies the alpha
//! mask.
//!
//! Impact: `impact[i]` is the raster's per-view `Σ α·T` of billboard `i` over the view's pixels
//! ([`crate::raster::RenderOutput::impact`], the post-2025 "fixed" definition). The paper-era
//! threshold σ = 500 is our default (see `docs/training.md` for the choice).

use super::row_sums::{RowSums, row_sums};
use crate::cpu::Simd;
use rayon::prelude::*;

/// Weight of the texture regulariser in the reference (`1e-4`).
pub const TEXTURE_REG_WEIGHT: f32 = 1e-4;
/// Weight of the global opacity regulariser in the reference (`0.01`).
pub const OPACITY_REG_WEIGHT: f32 = 0.01;
/// Impact threshold σ of the texture regulariser (paper-era value; current reference code: 100).
pub const IMPACT_THRESHOLD: f32 = 500.0;

/// What the texture regulariser of [`regularise()`] reads besides the textures: the reference alpha
/// `alpha0` (`T` values), the view's per-billboard `impact`, the threshold σ and the weight λ.
#[derive(Clone, Copy, Debug)]
pub struct TextureTerm<'a> {
    /// The reference alpha texture `A0` (`T = TS²` values, shared by all billboards).
    pub alpha0: &'a [f32],
    /// Per billboard: the view's `Σ α·T`.
    pub impact: &'a [f32],
    /// σ.
    pub threshold: f32,
    /// λ.
    pub weight: f32,
}

/// The values of the two regularisers (0 for one that is off).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RegulariserValues {
    /// [`texture_regulariser`]'s value.
    pub texture: f64,
    /// [`opacity_regulariser`]'s value.
    pub opacity: f64,
}

/// The texture regulariser (`texture`, when given) and the opacity regulariser (`opacity_weight`,
/// when given) in one pass over the billboards: each row of `textures` is read once and each row
/// of `d_textures` updated once, in parallel over billboards. Per texel the gradient additions
/// are those of [`texture_regulariser`] followed by those of [`opacity_regulariser`], in that
/// order, so the gradients are the bits of the two calls one after the other; each value is
/// summed row by row and the rows' sums added in billboard order (the same for any thread
/// count). See the two functions for the formulas. [`regulariser_rows`] followed by
/// [`RowGradient::add_to`] on every row. `simd` is the instruction set of the row sums (the same
/// bits whatever it is).
///
/// # Panics
/// When `d_textures` and `textures` differ in length, `textures` is not whole rows of
/// `texels_per_row` (`TS²`; 0 only for an empty set) texels, or `texture` is given with `alpha0` not of
/// `texels_per_row` values or `impact` not one per row.
pub fn regularise(
    textures: &[[f32; 4]],
    texels_per_row: usize,
    texture: Option<TextureTerm<'_>>,
    opacity_weight: Option<f32>,
    d_textures: &mut [[f32; 4]],
    simd: Simd,
) -> RegulariserValues {
    assert_eq!(d_textures.len(), textures.len(), "texture gradient buffer");
    let mut rows = Vec::new();
    let values = regulariser_rows(textures, texels_per_row, texture, opacity_weight, &mut rows, simd);
    if !rows.is_empty() {
        d_textures
            .par_chunks_mut(texels_per_row)
            .zip(&rows)
            .for_each(|(d_tex, row)| row.add_to(d_tex));
    }
    values
}

/// What the regularisers add to the gradient of every texel of one billboard: the texture
/// term's `(∂/∂colour, ∂/∂alpha)` when it weighs the billboard (the colour gradient to each
/// colour channel, the alpha gradient only when non-zero), then the opacity term's `∂/∂alpha`
/// when that term is on.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RowGradient {
    /// The texture term's `(∂/∂colour, ∂/∂alpha)`.
    pub texture: Option<(f32, f32)>,
    /// The opacity term's `∂/∂alpha`.
    pub opacity: Option<f32>,
}

impl RowGradient {
    /// Channel `channel` of a texel's gradient `g` with the row's regulariser gradient added:
    /// `(g + first) + second` with the two [`RowGradient::addends`] of the channel (the one copy
    /// of these additions, for [`regularise`], the trainer's texture step and its finiteness
    /// check).
    #[inline(always)]
    pub fn add(&self, channel: usize, g: f32) -> f32 {
        Self::add_addends(self.addends(channel), g)
    }

    /// `(g + first) + second`: [`RowGradient::add`] with the channel's addends already read
    /// (for loops over a row's texels).
    #[inline(always)]
    pub fn add_addends([first, second]: [f32; 2], g: f32) -> f32 {
        (g + first) + second
    }

    /// The two numbers [`RowGradient::add`] adds to a gradient of channel `channel`, in order:
    /// the texture term's (its colour gradient for channels 0-2, its alpha gradient for channel
    /// 3 when non-zero), then the opacity term's (channel 3). A term that adds nothing there
    /// gives `−0.0`, which leaves every value's bits as they are (`x + (−0.0)` is `x`, `−0.0`
    /// included; only a signalling NaN comes out quiet, still a NaN), so a loop over texels
    /// adds both without a branch.
    #[inline(always)]
    pub fn addends(&self, channel: usize) -> [f32; 2] {
        let first = match self.texture {
            Some((gc, _)) if channel < 3 => gc,
            Some((_, ga)) if ga != 0.0 => ga,
            _ => -0.0,
        };
        let second = match self.opacity {
            Some(go) if channel == 3 => go,
            _ => -0.0,
        };
        [first, second]
    }

    /// Adds the row's regulariser gradient to every texel of `d_tex`.
    pub fn add_to(&self, d_tex: &mut [[f32; 4]]) {
        if *self == Self::default() {
            return;
        }
        for g in d_tex {
            *g = std::array::from_fn(|c| self.add(c, g[c]));
        }
    }
}

/// The values of the regularisers of [`regularise`] and, in `rows` (resized to one per
/// billboard, or cleared when both terms are off or the set is empty), what they add to each
/// billboard's texel gradients, without touching a gradient: a pass that only reads `textures`.
/// The values are the bits of [`regularise`]'s.
///
/// # Panics
/// As [`regularise`].
pub fn regulariser_rows(
    textures: &[[f32; 4]],
    texels_per_row: usize,
    texture: Option<TextureTerm<'_>>,
    opacity_weight: Option<f32>,
    rows: &mut Vec<RowGradient>,
    simd: Simd,
) -> RegulariserValues {
    regulariser_rows_of(textures, texels_per_row, texture, opacity_weight, None, rows, simd)
}

/// [`regulariser_rows`] on the billboards flagged in `only` (every billboard when `None`): the
/// others get no gradient and add nothing to the values (they are not read). The opacity term
/// keeps its per-texel gradient `weight / (all texels)`; the texture term reaches only visible
/// billboards anyway. What lazy Adam ([`super::AdamMode::Lazy`]) runs, `only` being the rows the
/// view keeps; with `None` the bits of [`regulariser_rows`].
///
/// # Panics
/// As [`regularise`]; and when `only` does not hold one flag per billboard.
#[allow(clippy::too_many_arguments)]
pub fn regulariser_rows_of(
    textures: &[[f32; 4]],
    texels_per_row: usize,
    texture: Option<TextureTerm<'_>>,
    opacity_weight: Option<f32>,
    only: Option<&[bool]>,
    rows: &mut Vec<RowGradient>,
    simd: Simd,
) -> RegulariserValues {
    let t = texels_per_row;
    rows.clear();
    // Rows of no texels hold nothing: only an empty set has them.
    if t == 0 {
        assert!(textures.is_empty(), "whole rows of TS² texels");
        return RegulariserValues::default();
    }
    assert!(textures.len().is_multiple_of(t), "whole rows of TS² texels");
    // The texture term with |vis|; off when no billboard is visible (the reference divides by
    // zero there).
    let texture = texture.and_then(|term| {
        assert_eq!(term.alpha0.len(), t, "one reference alpha per texel");
        assert_eq!(textures.len(), term.impact.len() * t, "TS² RGBA texels per billboard");
        let vis = term.impact.iter().filter(|&&x| x > 0.0).count();
        (vis > 0).then_some((term, vis as f64))
    });
    let opacity = opacity_weight.filter(|_| !textures.is_empty());
    if texture.is_none() && opacity.is_none() {
        return RegulariserValues::default();
    }
    let g_opacity = opacity.map(|w| (w as f64 / textures.len() as f64) as f32);
    assert!(
        only.is_none_or(|o| o.len() * t == textures.len()),
        "one flag per billboard"
    );
    // Per row: its gradient, the texture term's contribution and the row's alpha sum (f64).
    let per_row: Vec<(RowGradient, f64, f64)> = textures
        .par_chunks(t)
        .enumerate()
        .map(|(i, tex)| {
            if only.is_some_and(|o| !o[i]) {
                return (RowGradient::default(), 0.0, 0.0);
            }
            // The row's sums, read once for both terms (only the alpha sum without the texture
            // term, or for a row the term skips).
            let texture_row = texture.and_then(|(term, vis)| Some((term, vis, term_weight(term, i)?)));
            let sums = (texture_row.is_some() || g_opacity.is_some())
                .then(|| row_sums(tex, texture_row.map(|(term, _, _)| term.alpha0), simd));
            let term = texture_row.and_then(|(term, vis, w)| Some(row_texture_term(term, vis, w, tex.len(), sums?)));
            let alpha_sum = match g_opacity {
                Some(_) => sums.map_or(0.0, |s| s.alpha),
                None => 0.0,
            };
            let gradient = RowGradient {
                texture: term.map(|(_, gc, ga)| (gc, ga)),
                opacity: g_opacity,
            };
            (gradient, term.map_or(0.0, |(value, _, _)| value), alpha_sum)
        })
        .collect();
    rows.extend(per_row.iter().map(|r| r.0));
    // Skipped billboards contribute an exact 0.0, which leaves the running sums unchanged.
    let (terms, alpha) = per_row.iter().fold((0.0, 0.0), |(a, b), &(_, x, y)| (a + x, b + y));
    RegulariserValues {
        texture: texture.map_or(0.0, |(term, vis)| term.weight as f64 * terms / vis),
        opacity: opacity.map_or(0.0, |w| w as f64 * alpha / textures.len() as f64),
    }
}

/// The weight `w_i = σ − clamp(impact_i, 0, σ)` of billboard `i` in the texture regulariser, or
/// `None` when the billboard is not visible or at or above the threshold (weight 0).
fn term_weight(term: TextureTerm<'_>, i: usize) -> Option<f64> {
    let imp = term.impact[i] as f64;
    if imp <= 0.0 {
        return None;
    }
    let threshold = term.threshold as f64;
    let w = threshold - imp.clamp(0.0, threshold);
    (w != 0.0).then_some(w)
}

/// The texture regulariser on a billboard of weight `w` ([`term_weight`]; `t` texels, whose
/// [`RowSums`] with the reference alpha are `sums`) given `|vis|`: `(w · (mean colour + |m|),
/// ∂/∂colour, ∂/∂alpha)`.
fn row_texture_term(term: TextureTerm<'_>, vis: f64, w: f64, t: usize, sums: RowSums) -> (f64, f32, f32) {
    let lambda = term.weight as f64;
    // The colour sum runs channel by channel (r, g, b), each over the texels in order; the
    // alpha offset over the texels in order (`RowSums`, the same bits in any order it uses).
    let mean_c = sums.colour / (3 * t) as f64;
    let m = sums.alpha_offset / t as f64;
    let gc = (lambda * w / (vis * (3 * t) as f64)) as f32;
    let sign = if m > 0.0 {
        1.0
    } else if m < 0.0 {
        -1.0
    } else {
        0.0
    };
    let ga = (lambda * w * sign / (vis * t as f64)) as f32;
    ((mean_c + m.abs()) * w, gc, ga)
}

/// Texture regulariser of paper Eq. 9.
///
/// With `vis = {i : impact_i > 0}` and the constant weights `w_i = σ − clamp(impact_i, 0, σ)`:
///
/// `L = λ · mean_{i∈vis}( mean_k colour_{i,k} · w_i ) + λ · mean_{i∈vis}( |mean_k (alpha_{i,k} − a0_k)| · w_i )`
///
/// where the inner means run over all texels (and the 3 channels for colour). Gradients:
/// `∂L/∂colour_{i,k} = λ·w_i / (|vis|·3T)` and `∂L/∂alpha_{i,k} = λ·w_i·sign(m_i) / (|vis|·T)` with
/// `m_i` the signed mean alpha difference (`sign(0) = 0`, the subgradient at the kink). When no
/// billboard is visible the value is 0 and nothing is added (the reference divides by zero).
/// `alpha0` is the reference alpha texture `A0` (`T` values, shared by all billboards).
/// [`regularise()`] with only this term.
pub fn texture_regulariser(
    textures: &[[f32; 4]],
    alpha0: &[f32],
    impact: &[f32],
    threshold: f32,
    weight: f32,
    d_textures: &mut [[f32; 4]],
) -> f64 {
    let term = TextureTerm {
        alpha0,
        impact,
        threshold,
        weight,
    };
    regularise(textures, alpha0.len(), Some(term), None, d_textures, Simd::detect()).texture
}

/// Global opacity regulariser: `L = λ · mean over all billboards and texels of alpha`, including
/// texels held at zero by the alpha mask (the reference's mean runs over all `TS²`). Adds
/// `λ / (N·T)` to the alpha channel of every texel of `d_textures`. An empty model gives 0.
/// [`regularise()`] with only this term (`texels_per_row = T`: the value is summed row by row).
pub fn opacity_regulariser(
    textures: &[[f32; 4]],
    texels_per_row: usize,
    weight: f32,
    d_textures: &mut [[f32; 4]],
) -> f64 {
    regularise(textures, texels_per_row, None, Some(weight), d_textures, Simd::detect()).opacity
}

/// The opacity regulariser's value alone (no gradient).
pub fn opacity_value(textures: &[[f32; 4]], weight: f32) -> f64 {
    if textures.is_empty() {
        return 0.0;
    }
    weight as f64 * textures.iter().map(|x| x[3] as f64).sum::<f64>() / textures.len() as f64
}

/// Carries a gradient with respect to activated values `y = sigmoid(x)` to the logits `x`:
/// `∂L/∂x = ∂L/∂y · y·(1 − y)`, multiplied by 0 where `mask` (per texel, repeating every
/// `mask.len()` values) is false. `mask = None` keeps every element.
pub fn chain_sigmoid(activated: &[f32], d_activated: &[f32], mask: Option<&[bool]>, d_logits: &mut [f32]) {
    assert_eq!(activated.len(), d_activated.len());
    assert_eq!(activated.len(), d_logits.len());
    for k in 0..activated.len() {
        let keep = mask.is_none_or(|m| m[k % m.len()]);
        let y = activated[k];
        d_logits[k] = if keep { d_activated[k] * y * (1.0 - y) } else { 0.0 };
    }
}

/// Gaussian-billboard alpha (texture mode [`super::TextureMode::Gaussian`]): texel `k` of billboard
/// `i` is `sigmoid(ω_i) · shape_k`, with `shape` the fixed initial Gaussian (peak ≤ 1).
pub fn gaussian_alpha(opacity_logits: &[f32], shape: &[f32]) -> Vec<f32> {
    let mut out = Vec::with_capacity(opacity_logits.len() * shape.len());
    for &w in opacity_logits {
        let o = crate::model::sigmoid(w);
        out.extend(shape.iter().map(|&s| o * s));
    }
    out
}

/// Gradient of the loss with respect to the opacity logit `ω` of one Gaussian billboard, given
/// the gradient with respect to its RGBA texels (only the alpha channel counts):
/// `∂L/∂ω = o(1 − o) · Σ_k ∂L/∂α_k · shape_k`, `o = sigmoid(ω)`. Summed in f64.
pub fn gaussian_opacity_grad(opacity_logit: f32, d_texels: &[[f32; 4]], shape: &[f32]) -> f32 {
    let o = crate::model::sigmoid(opacity_logit) as f64;
    let s: f64 = d_texels.iter().zip(shape).map(|(g, &s)| g[3] as f64 * s as f64).sum();
    (o * (1.0 - o) * s) as f32
}
