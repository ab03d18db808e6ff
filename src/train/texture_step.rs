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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::train::regularise::chain_sigmoid;

    /// The parallel step equals the serial per-row loop (chain, `AdamGroup` step, activation)
    /// bit for bit, dense and sparse, with a mask, for the colour and the alpha channels of RGBA
    /// texels, on 2 and 1 threads; the other channels are left alone.
    #[test]
    fn matches_the_serial_row_loop_bit_for_bit() {
        let (rows, texels) = (150usize, 4usize);
        let mask: Vec<bool> = (0..texels).map(|k| k != 2).collect();
        let mut state = 0x9e3779b97f4a7c15u64;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state % 20001) as f32 / 10000.0 - 1.0
        };
        let rgba0: Vec<[f32; 4]> = (0..rows * texels).map(|_| [0.0; 4].map(|_| next())).collect();
        let selected: Vec<bool> = (0..rows).map(|r| r % 3 != 1).collect();
        let hp = AdamParams::default();
        for channels in [0..3, 3..4] {
            let n = channels.len() * texels;
            let logits0: Vec<f32> = (0..rows * n).map(|_| 3.0 * next()).collect();
            // Planar gradients `[row][channel][texel]`, the same values as in the RGBA buffer.
            let grads_rgba0: Vec<[f32; 4]> = (0..rows * texels).map(|_| [0.0; 4].map(|_| next())).collect();
            let planar = |x: &[[f32; 4]]| -> Vec<f32> {
                (0..rows)
                    .flat_map(|r| {
                        let channels = channels.clone();
                        channels.flat_map(move |ch| (0..texels).map(move |k| x[r * texels + k][ch]))
                    })
                    .collect()
            };
            let grads0 = planar(&grads_rgba0);
            let activate = |x: &[f32]| -> Vec<f32> {
                x.iter()
                    .enumerate()
                    .map(|(k, &x)| if mask[(k % n) % texels] { sigmoid(x) } else { 0.0 })
                    .collect()
            };
            let row_mask: Vec<bool> = (0..n).map(|k| mask[k % texels]).collect();
            for dense in [true, false] {
                // Serial reference on planar rows: two steps.
                let mut group = AdamGroup::new(rows, n);
                let mut logits = logits0.clone();
                let mut act = activate(&logits);
                for _ in 0..2 {
                    group.global_step += 1;
                    for r in 0..rows {
                        if !dense && !selected[r] {
                            continue;
                        }
                        let span = r * n..(r + 1) * n;
                        let mut d = vec![0.0; n];
                        chain_sigmoid(&act[span.clone()], &grads0[span.clone()], Some(&row_mask), &mut d);
                        if dense {
                            let t = group.global_step;
                            group.step_row_global(r, &mut logits[span.clone()], &d, 0.01, &hp, t);
                        } else {
                            group.step_row(r, &mut logits[span.clone()], &d, 0.01, &hp);
                        }
                        act.splice(span.clone(), activate(&logits)[span].iter().copied());
                    }
                }
                for threads in [1, 2] {
                    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
                    let mut g2 = AdamGroup::new(rows, n);
                    let mut logits2 = logits0.clone();
                    // The group's channels activated from the logits, the others arbitrary.
                    let mut act2 = rgba0.clone();
                    let planar_act = activate(&logits2);
                    for r in 0..rows {
                        for (ci, ch) in channels.clone().enumerate() {
                            for k in 0..texels {
                                act2[r * texels + k][ch] = planar_act[r * n + ci * texels + k];
                            }
                        }
                    }
                    pool.install(|| {
                        for _ in 0..2 {
                            g2.global_step += 1;
                            let mut grads = grads_rgba0.clone();
                            let sel = if dense {
                                RowSelection::Dense
                            } else {
                                RowSelection::Sparse(&selected)
                            };
                            step_texture_group(
                                &mut g2,
                                &mut logits2,
                                &mut act2,
                                &mut grads,
                                channels.clone(),
                                Some(&mask),
                                sel,
                                0.01,
                                &hp,
                                true,
                            );
                            for (g, g0) in grads.iter().zip(&grads_rgba0) {
                                for ch in 0..4 {
                                    let want = if channels.contains(&ch) { 0.0 } else { g0[ch] };
                                    assert_eq!(g[ch], want, "the group's gradients are consumed, no others");
                                }
                            }
                        }
                    });
                    let bits = |x: &[f32]| x.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
                    let tag = format!("channels {channels:?}, dense {dense}, {threads} threads");
                    assert_eq!(bits(&logits2), bits(&logits), "{tag}");
                    assert_eq!(bits(&planar(&act2)), bits(&act), "{tag}");
                    for (a, a0) in act2.iter().zip(&rgba0) {
                        for ch in (0..4).filter(|c| !channels.contains(c)) {
                            assert_eq!(a[ch], a0[ch], "{tag}: other channels untouched");
                        }
                    }
                    assert_eq!(bits(&g2.m), bits(&group.m));
                    assert_eq!(bits(&g2.v), bits(&group.v));
                    assert_eq!(g2.steps, group.steps);
                }
            }
        }
    }
}
