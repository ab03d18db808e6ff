//! Relocation of dead billboards (the BBSplat spec, §6, "MCMC-style").
//!
//! A billboard is *dead* when its mean alpha over all `TS²` texels (masked texels count as 0) is
//! at most [`DEAD_ALPHA`]. Each dead slot receives a copy of a source drawn, with replacement,
//! from the alive billboards with probability proportional to their mean alpha. A source drawn
//! `n` times ends up with `n + 1` identical copies (itself included), and every copy's alpha is
//! split texel-wise: `a' = 1 − (1 − a)^{1/(n+1)}`, so that compositing the `n + 1` copies on top
//! of each other gives back `1 − (1 − a')^{n+1} = a`. Position, rotation, scale (unchanged, no
//! scale correction), SH and colour texture are copied exactly. No position noise (the
//! reference's noise is exactly zero, spec §6).
//!
//! The split is computed in logit space in f64 (`logit a' = ln(−expm1(−p·sp)) + p·sp` with
//! `sp = softplus(x) = −ln(1 − a)`, `p = 1/(n+1)`), which is exact for tiny and near-one alphas,
//! and the result is clamped to `±`[`LOGIT_CLAMP`] (alpha kept away from 0 and 1). Texels outside
//! the alpha mask are left as they are (they render as 0 anyway).
//!
//! The optimiser-state side (zeroing moments) is done by the trainer.

#[cfg(doc)]
use crate::model::DEAD_ALPHA;
use crate::model::{RawBillboards, is_alive};
use crate::raster::SH_FLOATS;
use crate::rng::Rng;

/// Relocated alpha logits are clamped to `[−LOGIT_CLAMP, LOGIT_CLAMP]` (alpha within
/// `[9.4e-14, 1 − 9.4e-14]` in f64).
pub const LOGIT_CLAMP: f64 = 30.0;

/// Which dead slot receives a copy of which source.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct RelocationPlan {
    /// `(dead slot, source)` pairs, dead slots in increasing order.
    pub moves: Vec<(usize, usize)>,
    /// `(source, n)`: each distinct source with the number of times it was drawn, increasing
    /// source order.
    pub multiplicity: Vec<(usize, u32)>,
}

impl RelocationPlan {
    /// True when nothing moves.
    pub fn is_empty(&self) -> bool {
        self.moves.is_empty()
    }
}

/// Chooses sources for the dead billboards. `mean_alpha[i]` is billboard `i`'s mean alpha.
///
/// Draws `dead.len()` uniforms from `rng` (one per dead slot, in slot order) and picks the alive
/// billboard whose cumulative-weight interval contains `u · Σ weights` (f64 sums, binary search).
/// Returns an empty plan (and draws nothing) when no billboard is dead or none is alive.
pub fn plan_relocation(mean_alpha: &[f32], rng: &mut Rng) -> RelocationPlan {
    // A NaN mean alpha counts as dead (it is not above the threshold).
    let is_alive = |i: usize| is_alive(mean_alpha[i]);
    let dead: Vec<usize> = (0..mean_alpha.len()).filter(|&i| !is_alive(i)).collect();
    let alive: Vec<usize> = (0..mean_alpha.len()).filter(|&i| is_alive(i)).collect();
    if dead.is_empty() || alive.is_empty() {
        return RelocationPlan::default();
    }
    let moves = dead
        .iter()
        .copied()
        .zip(draw_sources(mean_alpha, &alive, dead.len(), rng))
        .collect();
    plan_from_moves(moves, mean_alpha.len())
}

/// Draws `count` sources from `candidates` with replacement, with probability ∝
/// `weight[candidate]`: one uniform from `rng` per draw, in order, and the candidate whose
/// cumulative-weight interval (f64 sums in candidate order) contains `u · Σ weights` (binary
/// search). The one sampler of relocation and growth ([`crate::train::grow`]). Draws nothing
/// and returns nothing when `candidates` is empty or the weights do not sum to a positive
/// finite number.
pub fn draw_sources(weight: &[f32], candidates: &[usize], count: usize, rng: &mut Rng) -> Vec<usize> {
    let mut cumulative = Vec::with_capacity(candidates.len());
    let mut total = 0.0f64;
    for &i in candidates {
        let w = weight[i] as f64;
        total += if w.is_finite() && w > 0.0 { w } else { 0.0 };
        cumulative.push(total);
    }
    if candidates.is_empty() || !(total > 0.0 && total.is_finite()) {
        return Vec::new();
    }
    (0..count)
        .map(|_| {
            let target = rng.uniform_f64() * total;
            // First index whose cumulative weight exceeds the target.
            let k = cumulative.partition_point(|&c| c <= target).min(candidates.len() - 1);
            candidates[k]
        })
        .collect()
}

/// The plan of `(destination, source)` moves over `n` billboards: the moves as given and each
/// distinct source with its count, in increasing source order.
pub fn plan_from_moves(moves: Vec<(usize, usize)>, n: usize) -> RelocationPlan {
    let mut counts = vec![0u32; n];
    for &(_, s) in &moves {
        counts[s] += 1;
    }
    let multiplicity = counts
        .iter()
        .enumerate()
        .filter(|&(_, &c)| c > 0)
        .map(|(i, &c)| (i, c))
        .collect();
    RelocationPlan { moves, multiplicity }
}

/// The split alpha of one of `copies` stacked copies, in logit space: `logit(1 − (1 − a)^{1/copies})`
/// with `a = sigmoid(x)`, computed stably in f64 and clamped to `±LOGIT_CLAMP`.
pub fn split_alpha_logit(x: f32, copies: u32) -> f32 {
    let x = x as f64;
    let p = 1.0 / copies.max(1) as f64;
    // softplus(x) = −ln(1 − sigmoid(x)), stable for both signs.
    let sp = x.max(0.0) + (-x.abs()).exp().ln_1p();
    let logit = (-(-p * sp).exp_m1()).ln() + p * sp;
    logit.clamp(-LOGIT_CLAMP, LOGIT_CLAMP) as f32
}

/// Applies `plan` to the raw parameters: splits the alpha logits of every source (texels inside
/// `alpha_mask` only) and copies all parameters of the source into its dead slots.
pub fn apply_relocation(model: &mut RawBillboards, plan: &RelocationPlan) {
    let t = model.texture_size * model.texture_size;
    for &(s, n) in &plan.multiplicity {
        for k in 0..t {
            if model.alpha_mask[k] {
                let x = &mut model.alpha_logits[s * t + k];
                *x = split_alpha_logit(*x, n + 1);
            }
        }
    }
    for &(d, s) in &plan.moves {
        copy_row(model, s, d);
    }
}

/// Copies every parameter of billboard `src` into billboard `dst`.
pub fn copy_row(model: &mut RawBillboards, src: usize, dst: usize) {
    let t = model.texture_size * model.texture_size;
    model.positions[dst] = model.positions[src];
    model.quaternions[dst] = model.quaternions[src];
    model.log_scales[dst] = model.log_scales[src];
    model
        .sh
        .copy_within(src * SH_FLOATS..(src + 1) * SH_FLOATS, dst * SH_FLOATS);
    model.alpha_logits.copy_within(src * t..(src + 1) * t, dst * t);
    model
        .colour_logits
        .copy_within(src * 3 * t..(src + 1) * 3 * t, dst * 3 * t);
}
