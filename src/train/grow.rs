//! Growth of the billboard set toward a cap (the BBSplat spec, §6, step 2: "add new").
//!
//! When growth is on ([`super::TrainConfig::growth_cap`] above the current count), every
//! relocation step (after relocating the dead) also grows the set from `N` to
//! [`growth_target`]`(N, cap) = min(cap, ⌊1.05·N⌋)` billboards: the new rows are copies of
//! sources drawn with replacement from **all** billboards with probability ∝ mean alpha
//! ([`draw_sources`], the sampler relocation uses), appended at the end in draw order; each
//! source drawn `n` times and its `n` new copies get the texel-wise split alpha
//! `1 − (1 − a)^{1/(n+1)}` ([`apply_relocation`], the one copy of the relocation math), so the
//! render is unchanged up to rounding. The trainer zeroes the Adam moments of the sources and
//! gives the new rows zero moments (spec: "new rows appended with zero Adam state; sources'
//! moments zeroed").

use super::adam::AdamGroup;
use super::relocate::{RelocationPlan, apply_relocation, draw_sources, plan_from_moves};
use crate::billboards::ActivatedBillboards;
use crate::model::RawBillboards;
use crate::raster::{RenderGradients, SH_FLOATS};
use crate::rng::Rng;
use glam::{Vec2, Vec3};

/// Growth factor per growth step (spec §6: +5 %).
pub const GROWTH_FACTOR: f64 = 1.05;

/// The count after one growth step from `n` toward `cap`: `min(cap, ⌊1.05·n⌋)`, never below `n`.
///
/// ```
/// use bbsplat::train::grow::growth_target;
/// assert_eq!(growth_target(1000, 5000), 1050);
/// assert_eq!(growth_target(1000, 1020), 1020);
/// assert_eq!(growth_target(1000, 0), 1000);
/// assert_eq!(growth_target(10, 100), 10); // ⌊10.5⌋ = 10: small sets do not grow
/// ```
pub fn growth_target(n: usize, cap: usize) -> usize {
    let grown = (n as f64 * GROWTH_FACTOR).floor() as usize;
    grown.min(cap).max(n)
}

/// Chooses the sources of `new_rows` billboards appended after the `mean_alpha.len()` existing
/// ones: moves `(n + k, source)` for `k < new_rows`, sources drawn ∝ mean alpha over every
/// billboard. Empty (nothing drawn) when `new_rows` is 0 or no billboard has a positive mean
/// alpha.
pub fn plan_growth(mean_alpha: &[f32], new_rows: usize, rng: &mut Rng) -> RelocationPlan {
    if new_rows == 0 {
        return RelocationPlan::default();
    }
    let n = mean_alpha.len();
    let all: Vec<usize> = (0..n).collect();
    let sources = draw_sources(mean_alpha, &all, new_rows, rng);
    let moves = sources.into_iter().enumerate().map(|(k, s)| (n + k, s)).collect();
    plan_from_moves(moves, n)
}

/// Appends `plan`'s new rows to `model` (zeroed, then filled by [`apply_relocation`]: split
/// sources, copied rows). The plan's destinations must be `len..len + moves`.
pub fn apply_growth(model: &mut RawBillboards, plan: &RelocationPlan) {
    let n = model.len();
    let added = plan.moves.len();
    debug_assert!(plan.moves.iter().enumerate().all(|(k, &(d, _))| d == n + k));
    let t = model.texture_size * model.texture_size;
    let total = n + added;
    model.positions.resize(total, Vec3::ZERO);
    model.quaternions.resize(total, [1.0, 0.0, 0.0, 0.0]);
    model.log_scales.resize(total, Vec2::ZERO);
    model.sh.resize(total * SH_FLOATS, 0.0);
    model.alpha_logits.resize(total * t, 0.0);
    model.colour_logits.resize(total * 3 * t, 0.0);
    apply_relocation(model, plan);
}

/// Appends the rows of `rows` (same texture size and alpha mask) to `model`.
///
/// # Panics
/// When the texture sizes differ.
pub fn append_rows(model: &mut RawBillboards, rows: &RawBillboards) {
    assert_eq!(
        model.texture_size, rows.texture_size,
        "rows of the model's texture size"
    );
    model.positions.extend_from_slice(&rows.positions);
    model.quaternions.extend_from_slice(&rows.quaternions);
    model.log_scales.extend_from_slice(&rows.log_scales);
    model.sh.extend_from_slice(&rows.sh);
    model.alpha_logits.extend_from_slice(&rows.alpha_logits);
    model.colour_logits.extend_from_slice(&rows.colour_logits);
}

/// Extends the activated copy to `n` rows (zeroed; the caller refreshes them from the model).
pub(crate) fn extend_activated(activated: &mut ActivatedBillboards, n: usize) {
    let t = activated.texture_size * activated.texture_size;
    activated.positions.resize(n, Vec3::ZERO);
    activated.quaternions.resize(n, [1.0, 0.0, 0.0, 0.0]);
    activated.log_scales.resize(n, Vec2::ZERO);
    activated.sh.resize(n * SH_FLOATS, 0.0);
    activated.textures.resize(n * t, [0.0; 4]);
}

/// Extends the gradient buffers to `n` rows of zeros.
pub(crate) fn extend_gradients(grads: &mut RenderGradients, n: usize, texture_size: usize) {
    grads.positions.resize(n, Vec3::ZERO);
    grads.quaternions.resize(n, [0.0; 4]);
    grads.log_scales.resize(n, Vec2::ZERO);
    grads.sh.resize(n * SH_FLOATS, 0.0);
    grads.textures.resize(n * texture_size * texture_size, [0.0; 4]);
}

/// Extends an Adam group to `n` rows with zero moments and update counts (the global step is
/// shared and unchanged).
pub(crate) fn extend_adam(group: &mut AdamGroup, n: usize) {
    group.m.resize(n * group.row_len, 0.0);
    group.v.resize(n * group.row_len, 0.0);
    group.steps.resize(n, 0);
}
