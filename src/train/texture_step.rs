//! The optimiser step of one texture group (alpha or colour logits), parallel over billboards.
//!
//! Textures are 1024 of a billboard's 1081 floats at TS = 16, so their Adam update, the sigmoid
//! chain into the logits and the re-activation dominate the optimiser's cost. Every row is
//! independent of every other, so the rows are split into chunks that rayon steps in parallel;
//! each row does exactly the arithmetic of the serial per-row loop, in the same order, so the
//! result is bit-identical for any thread count. The row's gradient is zeroed after use.

use super::adam::{AdamGroup, AdamParams, update_row};
use crate::model::sigmoid;
use rayon::prelude::*;
use std::ops::Range;

/// Which rows take an optimiser step.
#[derive(Clone, Copy, Debug)]
pub enum RowSelection<'a> {
    /// Every row, with PyTorch-`Adam` bias correction at the group's global step.
    Dense,
    /// Only the rows flagged `true` (row-sparse Adam, per-row bias correction).
    Sparse(&'a [bool]),
}

/// Rows per rayon task.
const CHUNK_ROWS: usize = 64;

/// One Adam step of the texture group `group` on the logits, for the selected rows, then
/// refreshes their activated values (`sigmoid`, masked texels 0) and zeroes the group's channels
/// of every row of `grads`.
///
/// * `logits`: planar rows, `group.row_len = channels.len() · TS²` values per billboard,
///   `[channel][texel]` (the model's layout);
/// * `activated`, `grads`: the rasterizer's RGBA texels, `TS²` per billboard; the group owns the
///   channels `channels` of each texel (`0..3` colour, `3..4` alpha), logit `c · TS² + k` being
///   channel `channels.start + c` of texel `k`. `grads` is the gradient with respect to the
///   **activated** values, chained here through the sigmoid (`∂L/∂x = ∂L/∂y · y(1 − y)`, masked
///   texels 0).
/// * `mask`: per texel, `false` for the texels that stay at alpha 0; `None` keeps every texel.
/// * `update`: `false` (textures frozen or before the window when the moments should not move)
///   skips the step and only zeroes the gradients.
///
/// # Panics
/// When the slices do not hold `group.rows()` rows, `channels` is empty or not inside `0..4`,
/// or `mask` does not hold `TS²` flags.
#[allow(clippy::too_many_arguments)]
pub fn step_texture_group(
    group: &mut AdamGroup,
    logits: &mut [f32],
    activated: &mut [[f32; 4]],
    grads: &mut [[f32; 4]],
    channels: Range<usize>,
    mask: Option<&[bool]>,
    selection: RowSelection<'_>,
    lr: f32,
    hp: &AdamParams,
    update: bool,
) {
    let n = group.row_len;
    let rows = group.rows();
    assert!(!channels.is_empty() && channels.end <= 4, "channels must lie in 0..4");
    let texels = n / channels.len();
    assert_eq!(texels * channels.len(), n, "a row holds every channel's texels");
    assert_eq!(logits.len(), rows * n, "one logit row per billboard");
    assert_eq!(activated.len(), rows * texels, "one activated row per billboard");
    assert_eq!(grads.len(), rows * texels, "one gradient row per billboard");
    assert!(mask.is_none_or(|m| m.len() == texels), "one mask flag per texel");
    // Fixed trip count with a per-channel test: a `fill` of the variable channel range would be
    // a `memset` call per texel.
    let owned: [bool; 4] = std::array::from_fn(|c| channels.contains(&c));
    let clear = |g: &mut [[f32; 4]]| {
        for texel in g {
            for c in 0..4 {
                if owned[c] {
                    texel[c] = 0.0;
                }
            }
        }
    };
    if !update {
        grads.par_chunks_mut(CHUNK_ROWS * texels.max(1)).for_each(clear);
        return;
    }
    let global_step = group.global_step;
    let keep = |k: usize| mask.is_none_or(|m| m[k]);
    let AdamGroup { m, v, steps, .. } = group;
    let chunk = CHUNK_ROWS * n.max(1);
    let texel_chunk = CHUNK_ROWS * texels.max(1);
    m.par_chunks_mut(chunk)
        .zip(v.par_chunks_mut(chunk))
        .zip(steps.par_chunks_mut(CHUNK_ROWS))
        .zip(logits.par_chunks_mut(chunk))
        .zip(activated.par_chunks_mut(texel_chunk))
        .zip(grads.par_chunks_mut(texel_chunk))
        .enumerate()
        .for_each(|(c, (((((m, v), steps), logits), activated), grads))| {
            let mut d_logit = vec![0.0f32; n];
            for r in 0..steps.len() {
                let row = c * CHUNK_ROWS + r;
                let span = r * n..(r + 1) * n;
                let texel_span = r * texels..(r + 1) * texels;
                let t = match selection {
                    RowSelection::Dense => {
                        steps[r] = steps[r].saturating_add(1);
                        global_step
                    }
                    RowSelection::Sparse(selected) => {
                        if !selected[row] {
                            clear(&mut grads[texel_span]);
                            continue;
                        }
                        steps[r] = steps[r].saturating_add(1);
                        u64::from(steps[r])
                    }
                };
                let (y, g) = (&mut activated[texel_span.clone()], &mut grads[texel_span]);
                // Chain through the sigmoid, consuming (zeroing) the gradient as it is read.
                for (ci, ch) in channels.clone().enumerate() {
                    for k in 0..texels {
                        let y = y[k][ch];
                        let g = std::mem::take(&mut g[k][ch]);
                        d_logit[ci * texels + k] = if keep(k) { g * y * (1.0 - y) } else { 0.0 };
                    }
                }
                let x = &mut logits[span.clone()];
                update_row(&mut m[span.clone()], &mut v[span], x, &d_logit, lr, hp, t);
                for (ci, ch) in channels.clone().enumerate() {
                    for k in 0..texels {
                        y[k][ch] = if keep(k) { sigmoid(x[ci * texels + k]) } else { 0.0 };
                    }
                }
            }
        });
}
