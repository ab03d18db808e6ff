//! The optimiser step of one texture group (alpha or colour logits), parallel over billboards.
//!
//! Textures are 1024 of a billboard's 1081 floats at TS = 16, so their Adam update, the sigmoid
//! chain into the logits and the re-activation dominate the optimiser's cost. Every row is
//! independent of every other, so the rows are split into chunks that rayon steps in parallel;
//! each row does exactly the arithmetic of the serial per-row loop, in the same order, so the
//! result is bit-identical for any thread count. The row's gradient is zeroed after use.

use super::adam::{AdamGroup, AdamParams};
use crate::model::sigmoid;
use rayon::prelude::*;

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
/// refreshes their activated values (`sigmoid`, masked texels 0) and zeroes every row of `grads`.
///
/// * `logits`, `activated`, `grads`: `rows × group.row_len` values; `grads` is the gradient with
///   respect to the **activated** values, chained here through the sigmoid
///   (`∂L/∂x = ∂L/∂y · y(1 − y)`, masked texels 0).
/// * `mask`: per texel of a channel, `false` for the texels that stay at alpha 0 (repeated over
///   the channels of a row); `None` keeps every texel.
/// * `update`: `false` (textures frozen or before the window when the moments should not move)
///   skips the step and only zeroes the gradients.
///
/// # Panics
/// When the slices do not hold `group.rows() × group.row_len` values.
#[allow(clippy::too_many_arguments)]
pub fn step_texture_group(
    group: &mut AdamGroup,
    logits: &mut [f32],
    activated: &mut [f32],
    grads: &mut [f32],
    mask: Option<&[bool]>,
    selection: RowSelection<'_>,
    lr: f32,
    hp: &AdamParams,
    update: bool,
) {
    let n = group.row_len;
    let rows = group.rows();
    assert_eq!(logits.len(), rows * n, "one logit row per billboard");
    assert_eq!(activated.len(), rows * n, "one activated row per billboard");
    assert_eq!(grads.len(), rows * n, "one gradient row per billboard");
    if !update {
        grads.par_chunks_mut(CHUNK_ROWS * n.max(1)).for_each(|g| g.fill(0.0));
        return;
    }
    let global_step = group.global_step;
    let keep = |k: usize| mask.is_none_or(|m| m[k % m.len()]);
    let AdamGroup { m, v, steps, .. } = group;
    let chunk = CHUNK_ROWS * n.max(1);
    m.par_chunks_mut(chunk)
        .zip(v.par_chunks_mut(chunk))
        .zip(steps.par_chunks_mut(CHUNK_ROWS))
        .zip(logits.par_chunks_mut(chunk))
        .zip(activated.par_chunks_mut(chunk))
        .zip(grads.par_chunks_mut(chunk))
        .enumerate()
        .for_each(|(c, (((((m, v), steps), logits), activated), grads))| {
            let mut d_logit = vec![0.0f32; n];
            for r in 0..steps.len() {
                let row = c * CHUNK_ROWS + r;
                let span = r * n..(r + 1) * n;
                let t = match selection {
                    RowSelection::Dense => {
                        steps[r] = steps[r].saturating_add(1);
                        global_step
                    }
                    RowSelection::Sparse(selected) => {
                        if !selected[row] {
                            grads[span].fill(0.0);
                            continue;
                        }
                        steps[r] = steps[r].saturating_add(1);
                        u64::from(steps[r])
                    }
                };
                let (y, g) = (&mut activated[span.clone()], &mut grads[span.clone()]);
                for k in 0..n {
                    d_logit[k] = if keep(k) { g[k] * y[k] * (1.0 - y[k]) } else { 0.0 };
                }
                let x = &mut logits[span.clone()];
                adam_update(&mut m[span.clone()], &mut v[span], x, &d_logit, lr, hp, t);
                for k in 0..n {
                    y[k] = if keep(k) { sigmoid(x[k]) } else { 0.0 };
                }
                g.fill(0.0);
            }
        });
}

/// The Adam update of one row, the same arithmetic as [`AdamGroup::step_row`].
#[inline]
fn adam_update(m: &mut [f32], v: &mut [f32], params: &mut [f32], grads: &[f32], lr: f32, hp: &AdamParams, t: u64) {
    let t = t.min(i32::MAX as u64) as i32;
    let bc1 = 1.0 - hp.beta1.powi(t);
    let bc2_sqrt = (1.0 - hp.beta2.powi(t)).sqrt();
    let step_size = lr / bc1;
    for k in 0..params.len() {
        let g = grads[k];
        m[k] = hp.beta1 * m[k] + (1.0 - hp.beta1) * g;
        v[k] = hp.beta2 * v[k] + (1.0 - hp.beta2) * g * g;
        params[k] -= step_size * m[k] / (v[k].sqrt() / bc2_sqrt + hp.eps);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::train::regularise::chain_sigmoid;

    /// The parallel step equals the serial per-row loop (chain, `AdamGroup` step, activation)
    /// bit for bit, dense and sparse, with a mask, on 2 and 1 threads.
    #[test]
    fn matches_the_serial_row_loop_bit_for_bit() {
        let (rows, n) = (150usize, 12usize);
        let mask: Vec<bool> = (0..4).map(|k| k != 2).collect();
        let mut state = 0x9e3779b97f4a7c15u64;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state % 20001) as f32 / 10000.0 - 1.0
        };
        let logits0: Vec<f32> = (0..rows * n).map(|_| 3.0 * next()).collect();
        let grads0: Vec<f32> = (0..rows * n).map(|_| next()).collect();
        let selected: Vec<bool> = (0..rows).map(|r| r % 3 != 1).collect();
        let hp = AdamParams::default();
        let activate = |x: &[f32]| -> Vec<f32> {
            x.iter()
                .enumerate()
                .map(|(k, &x)| if mask[(k % n) % 4] { sigmoid(x) } else { 0.0 })
                .collect()
        };
        for dense in [true, false] {
            // Serial reference: two steps.
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
                    let row_mask: Vec<bool> = (0..n).map(|k| mask[k % 4]).collect();
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
                let mut act2 = activate(&logits2);
                let row_mask: Vec<bool> = (0..n).map(|k| mask[k % 4]).collect();
                pool.install(|| {
                    for _ in 0..2 {
                        g2.global_step += 1;
                        let mut grads = grads0.clone();
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
                            Some(&row_mask),
                            sel,
                            0.01,
                            &hp,
                            true,
                        );
                        assert!(grads.iter().all(|&g| g == 0.0), "gradients are consumed");
                    }
                });
                let bits = |x: &[f32]| x.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&logits2), bits(&logits), "dense {dense}, {threads} threads");
                assert_eq!(bits(&act2), bits(&act), "dense {dense}, {threads} threads");
                assert_eq!(bits(&g2.m), bits(&group.m));
                assert_eq!(bits(&g2.v), bits(&group.v));
                assert_eq!(g2.steps, group.steps);
            }
        }
    }
}
