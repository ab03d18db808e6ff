//! Detection of NaN and infinite values in a training step: the loss, the gradients (before the
//! optimiser uses them) and the parameters (after it wrote them).
//!
//! A value is non-finite when its exponent bits are all ones (NaN or ±∞). The scans take the
//! maximum of the masked exponent bits, an integer reduction that the compiler vectorises, so a
//! pass over the gradient or parameter arrays costs about as much as reading them once (measured
//! in `docs/training.md`, "Non-finite values"). The large texture arrays are split across the
//! rayon pool; the answer (which group, checked in a fixed order) does not depend on the thread
//! count.

use super::regularise::RowGradient;
use crate::model::RawBillboards;
use crate::raster::RenderGradients;
use glam::{Vec2, Vec3};
use rayon::prelude::*;

/// A group of trained values, as named by [`NonFinite`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum ParamGroup {
    /// Billboard centres.
    Positions,
    /// Rotation quaternions.
    Quaternions,
    /// Log-scales.
    LogScales,
    /// SH coefficients (all degrees).
    Sh,
    /// Alpha textures: the alpha logits (parameters) or the activated alpha texels (gradients).
    AlphaTextures,
    /// Colour textures: the colour logits (parameters) or the activated colour texels
    /// (gradients).
    ColourTextures,
    /// The per-billboard opacity logits of [`super::TextureMode::Gaussian`].
    Opacity,
}

impl std::fmt::Display for ParamGroup {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            ParamGroup::Positions => "positions",
            ParamGroup::Quaternions => "quaternions",
            ParamGroup::LogScales => "log-scales",
            ParamGroup::Sh => "SH coefficients",
            ParamGroup::AlphaTextures => "alpha textures",
            ParamGroup::ColourTextures => "colour textures",
            ParamGroup::Opacity => "opacity logits",
        })
    }
}

/// Which value of a step was NaN or infinite.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum NonFinite {
    /// The step's total loss (photometric + regularisers), e.g. from a NaN pixel in the view.
    /// Found before the optimiser step: nothing was applied.
    Loss,
    /// The gradient of a group. Found before the optimiser step: nothing was applied.
    Gradient(ParamGroup),
    /// A parameter of a group, found after the optimiser step (which was applied), or by
    /// [`super::Trainer::non_finite_parameter`].
    Parameter(ParamGroup),
}

impl std::fmt::Display for NonFinite {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            NonFinite::Loss => f.write_str("the loss"),
            NonFinite::Gradient(g) => write!(f, "the gradient of the {g}"),
            NonFinite::Parameter(g) => write!(f, "a parameter of the {g}"),
        }
    }
}

/// Exponent bits of an `f32`: all ones exactly for NaN and the infinities.
pub(crate) const EXPONENT: u32 = 0x7f80_0000;

/// Elements per parallel task of the large scans.
pub(crate) const CHUNK: usize = 1 << 16;

/// True when every value of `xs` is finite (serial).
fn finite_serial(xs: &[f32]) -> bool {
    max_exponent_field(xs) != EXPONENT
}

/// The largest exponent field (`bits & EXPONENT`) of `xs` (0 when empty), also for scans folded
/// into other loops: some value is non-finite exactly when it is [`EXPONENT`].
#[inline(always)]
pub(crate) fn max_exponent_field(xs: &[f32]) -> u32 {
    xs.iter().fold(0u32, |m, x| m.max(x.to_bits() & EXPONENT))
}

/// True when every value of `xs` is finite (split across the rayon pool when large).
pub fn all_finite(xs: &[f32]) -> bool {
    if xs.len() <= CHUNK {
        finite_serial(xs)
    } else {
        xs.par_chunks(CHUNK).all(finite_serial)
    }
}

fn finite_vec3(xs: &[Vec3]) -> bool {
    xs.iter().fold(0u32, |m, p| {
        m.max(p.x.to_bits() & EXPONENT)
            .max(p.y.to_bits() & EXPONENT)
            .max(p.z.to_bits() & EXPONENT)
    }) != EXPONENT
}

fn finite_vec2(xs: &[Vec2]) -> bool {
    xs.iter().fold(0u32, |m, p| {
        m.max(p.x.to_bits() & EXPONENT).max(p.y.to_bits() & EXPONENT)
    }) != EXPONENT
}

/// The first group (in the order of [`ParamGroup`]) whose gradient holds a non-finite value.
/// The texture gradients are checked as one array first; only when that fails are the alpha and
/// colour lanes told apart.
pub fn non_finite_gradient(g: &RenderGradients) -> Option<ParamGroup> {
    non_finite_gradient_with(g, None)
}

/// [`non_finite_gradient`] of the gradients `g` with, per billboard, the regularisers'
/// gradient `added[row]` added to its texels (as [`RowGradient::add`] adds it, the values the
/// texture step will read): the answer `regularise` followed by [`non_finite_gradient`] gives,
/// without writing the sums. `None` adds nothing.
///
/// # Panics
/// When `added` does not hold one gradient per billboard.
pub fn non_finite_gradient_with(g: &RenderGradients, added: Option<&[RowGradient]>) -> Option<ParamGroup> {
    non_finite_gradient_of(g, added, None)
}

/// [`non_finite_gradient_with`] reading the texture gradients of the rows flagged in `only`
/// (every row when `None`): lazy Adam's check ([`super::AdamMode::Lazy`]), whose other rows have
/// no gradient (the view does not keep them) and no regulariser gradient.
///
/// # Panics
/// When `added` does not hold one gradient per billboard or `only` one flag per billboard.
pub fn non_finite_gradient_of(
    g: &RenderGradients,
    added: Option<&[RowGradient]>,
    only: Option<&[bool]>,
) -> Option<ParamGroup> {
    let rows = g.positions.len();
    if added.is_none() && only.is_none() {
        return non_finite_gradient_plain(g);
    }
    assert!(
        added.is_none_or(|a| a.len() == rows),
        "one regulariser gradient per billboard"
    );
    if let Some(group) = non_finite_geometry_gradient(g) {
        return Some(group);
    }
    let texels = g.textures.len() / rows.max(1);
    // Per row: the largest exponent field of its colour and of its alpha gradients.
    assert!(only.is_none_or(|o| o.len() == rows), "one flag per billboard");
    let (colour, alpha) = g
        .textures
        .par_chunks(texels.max(1))
        .enumerate()
        .map(|(i, row)| {
            if only.is_some_and(|o| !o[i]) {
                return (0, 0);
            }
            // No regulariser gradient: the identity addends (`RowGradient::default`).
            let a = added.map_or_else(RowGradient::default, |a| a[i]);
            let addends: [[f32; 2]; 4] = std::array::from_fn(|ch| a.addends(ch));
            // Per channel (four lanes of one register), then the colour lanes together.
            let fields = row.iter().fold([0u32; 4], |m, x| {
                std::array::from_fn(|ch| m[ch].max(RowGradient::add_addends(addends[ch], x[ch]).to_bits() & EXPONENT))
            });
            (fields[0].max(fields[1]).max(fields[2]), fields[3])
        })
        .reduce(|| (0, 0), |x, y| (x.0.max(y.0), x.1.max(y.1)));
    if alpha == EXPONENT {
        return Some(ParamGroup::AlphaTextures);
    }
    if colour == EXPONENT {
        return Some(ParamGroup::ColourTextures);
    }
    None
}

/// [`non_finite_gradient`] with nothing added.
fn non_finite_gradient_plain(g: &RenderGradients) -> Option<ParamGroup> {
    if let Some(group) = non_finite_geometry_gradient(g) {
        return Some(group);
    }
    if !all_finite(g.textures.as_flattened()) {
        let alpha_ok = g.textures.iter().all(|t| t[3].is_finite());
        return Some(if alpha_ok {
            ParamGroup::ColourTextures
        } else {
            ParamGroup::AlphaTextures
        });
    }
    None
}

/// The first group of the gradients before the textures (positions, quaternions, log-scales,
/// SH) holding a non-finite value.
fn non_finite_geometry_gradient(g: &RenderGradients) -> Option<ParamGroup> {
    if !finite_vec3(&g.positions) {
        return Some(ParamGroup::Positions);
    }
    if !finite_serial(g.quaternions.as_flattened()) {
        return Some(ParamGroup::Quaternions);
    }
    if !finite_vec2(&g.log_scales) {
        return Some(ParamGroup::LogScales);
    }
    if !all_finite(&g.sh) {
        return Some(ParamGroup::Sh);
    }
    None
}

/// The first group (in the order of [`ParamGroup`]) of `model` and `opacity_logits` holding a
/// non-finite value.
pub fn non_finite_parameter(model: &RawBillboards, opacity_logits: &[f32]) -> Option<ParamGroup> {
    non_finite_parameter_with(model, opacity_logits, false)
}

/// [`non_finite_parameter`], skipping the alpha and colour logits when `textures_known_finite`
/// (the trainer's texture step has just checked every one of them as it wrote it): the same
/// answer whenever that is true.
pub fn non_finite_parameter_with(
    model: &RawBillboards,
    opacity_logits: &[f32],
    textures_known_finite: bool,
) -> Option<ParamGroup> {
    if !finite_vec3(&model.positions) {
        return Some(ParamGroup::Positions);
    }
    if !finite_serial(model.quaternions.as_flattened()) {
        return Some(ParamGroup::Quaternions);
    }
    if !finite_vec2(&model.log_scales) {
        return Some(ParamGroup::LogScales);
    }
    if !all_finite(&model.sh) {
        return Some(ParamGroup::Sh);
    }
    if !textures_known_finite && !all_finite(&model.alpha_logits) {
        return Some(ParamGroup::AlphaTextures);
    }
    if !textures_known_finite && !all_finite(&model.colour_logits) {
        return Some(ParamGroup::ColourTextures);
    }
    if !all_finite(opacity_logits) {
        return Some(ParamGroup::Opacity);
    }
    None
}
