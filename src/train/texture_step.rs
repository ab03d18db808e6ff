//! The optimiser step of one texture group (alpha or colour logits), parallel over billboards.
//!
//! Textures are 1024 of a billboard's 1081 floats at TS = 16, so their Adam update, the sigmoid
//! chain into the logits and the re-activation dominate the optimiser's cost. Every row is
//! independent of every other, so the rows are split into chunks that rayon steps in parallel;
//! each row does exactly the arithmetic of the serial per-row loop, in the same order, so the
//! result is bit-identical for any thread count. The row's gradient is zeroed after use.
//!
//! The loops are written to vectorise (zipped Adam slices, the sigmoids computed over the
//! contiguous logits with the vectorisable [`crate::exp_f32`], then scattered into the texels) and
//! compiled for AVX2 when the CPU has it, the same bits as the baseline build. The trainer steps
//! its two groups with [`step_texture_pair`]: chunk by chunk, each chunk of 64 rows through the
//! alpha group and then the colour group while the chunk's RGBA texels are in cache (criterion,
//! four alternating rounds: `texture_step/dense/10000` 19.7-22.6 ms, `texture_step/pair/10000`
//! 19.5-20.6 ms, faster in every round). Both groups row by row in one loop was measured slower.

use super::adam::{AdamGroup, AdamParams, StepFactors, update_row_with};
use super::finite::{EXPONENT, max_exponent_field};
use super::regularise::RowGradient;
use crate::cpu::Simd;
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
    /// Only the rows flagged `true`, with the bias correction of the group's global step, each
    /// marked up to date through live step `now` (lazy Adam, [`super::lazy_adam`]: the caller
    /// brought them up to date first). The other rows are not read or written, their gradients
    /// included (they must be zero).
    Lazy {
        /// The rows to step.
        selected: &'a [bool],
        /// The live step this update is, stored in each stepped row's `steps`.
        now: u32,
    },
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
/// * `added`: per row, the regularisers' gradient ([`RowGradient`]), added to each texel's
///   gradient as it is read (the bits of [`super::regularise::regularise`] adding it in place
///   first), so that the regulariser pass need not write the gradients; `None` adds nothing.
/// * `update`: `false` (textures frozen or before the window when the moments should not move)
///   skips the step and only zeroes the gradients.
/// * `simd`: the instruction set of the lane-wise loop (the same bits whatever it is).
///
/// Returns true when every logit the step wrote (those of the selected rows; none without
/// `update`) is finite: the parameter check of those logits, done while they are in cache.
///
/// # Panics
/// When the slices do not hold `group.rows()` rows, `channels` is empty or not inside `0..4`,
/// `mask` does not hold `TS²` flags, or `added` does not hold one gradient per row.
#[allow(clippy::too_many_arguments)]
pub fn step_texture_group(
    group: &mut AdamGroup,
    logits: &mut [f32],
    activated: &mut [[f32; 4]],
    grads: &mut [[f32; 4]],
    channels: Range<usize>,
    mask: Option<&[bool]>,
    selection: RowSelection<'_>,
    added: Option<&[RowGradient]>,
    lr: f32,
    hp: &AdamParams,
    update: bool,
    simd: Simd,
) -> bool {
    let texels = check_group(group, logits, activated, grads, &channels, mask, added);
    let n = group.row_len;
    let owned: [bool; 4] = std::array::from_fn(|c| channels.contains(&c));
    if !update {
        grads
            .par_chunks_mut(CHUNK_ROWS * texels.max(1))
            .for_each(|g| clear_channels(g, owned));
        return true;
    }
    let global_step = group.global_step;
    let AdamGroup { m, v, steps, .. } = group;
    let chunk = CHUNK_ROWS * n.max(1);
    let texel_chunk = CHUNK_ROWS * texels.max(1);
    let wide = simd.avx2_fma();
    m.par_chunks_mut(chunk)
        .zip(v.par_chunks_mut(chunk))
        .zip(steps.par_chunks_mut(CHUNK_ROWS))
        .zip(logits.par_chunks_mut(chunk))
        .zip(activated.par_chunks_mut(texel_chunk))
        .zip(grads.par_chunks_mut(texel_chunk))
        .enumerate()
        .map(|(c, (((((m, v), steps), logits), activated), grads))| {
            let rows = ChunkRows {
                first_row: c * CHUNK_ROWS,
                m,
                v,
                steps,
                logits,
                activated,
                grads,
            };
            let how = RowStep {
                channels: channels.clone(),
                texels,
                mask,
                selection,
                added,
                global_step,
                lr,
                hp,
            };
            step_rows_dispatch(rows, &how, wide)
        })
        .reduce(|| 0, u32::max)
        != EXPONENT
}

/// One texture group's share of [`step_texture_pair`]: its optimiser state, its logits, the
/// texel channels it owns, its texel mask and its learning rate (as the arguments of the same
/// names of [`step_texture_group`]).
pub struct GroupStep<'a> {
    /// The group's Adam moments and step counts.
    pub group: &'a mut AdamGroup,
    /// The group's logits, planar rows (`channels.len() · TS²` values per billboard).
    pub logits: &'a mut [f32],
    /// The texel channels the group owns (`0..3` colour, `3..4` alpha).
    pub channels: Range<usize>,
    /// Per texel, `false` for the texels that stay at alpha 0; `None` keeps every texel.
    pub mask: Option<&'a [bool]>,
    /// The group's learning rate.
    pub lr: f32,
}

/// [`step_texture_group`] of two groups that own different channels of the same texels, chunk
/// by chunk: each rayon chunk of rows steps the first group and then the second, while the
/// chunk's texels are in cache. Every row does the arithmetic of the two calls one after the
/// other (the groups touch different channels, so the order between them changes nothing): the
/// same bits. Returns each group's finiteness report.
///
/// # Panics
/// As [`step_texture_group`], for either group; and when the groups' channels overlap or their
/// row counts differ.
#[allow(clippy::too_many_arguments)]
pub fn step_texture_pair(
    first: GroupStep<'_>,
    second: GroupStep<'_>,
    activated: &mut [[f32; 4]],
    grads: &mut [[f32; 4]],
    selection: RowSelection<'_>,
    added: Option<&[RowGradient]>,
    hp: &AdamParams,
    update: bool,
    simd: Simd,
) -> [bool; 2] {
    assert!(
        first.channels.end <= second.channels.start || second.channels.end <= first.channels.start,
        "the two groups own different channels"
    );
    assert_eq!(
        first.group.rows(),
        second.group.rows(),
        "both groups have one row per billboard"
    );
    let texels =
        [&first, &second].map(|g| check_group(g.group, g.logits, activated, grads, &g.channels, g.mask, added));
    if !update {
        let owned: [bool; 4] = std::array::from_fn(|c| first.channels.contains(&c) || second.channels.contains(&c));
        grads
            .par_chunks_mut(CHUNK_ROWS * texels[0].max(1))
            .for_each(|g| clear_channels(g, owned));
        return [true; 2];
    }
    let texel_chunk = CHUNK_ROWS * texels[0].max(1);
    let how = [&first, &second].map(|g| RowStep {
        channels: g.channels.clone(),
        texels: texels[0],
        mask: g.mask,
        selection,
        added,
        global_step: g.group.global_step,
        lr: g.lr,
        hp,
    });
    let (n1, n2) = (first.group.row_len, second.group.row_len);
    let (c1, c2) = (CHUNK_ROWS * n1.max(1), CHUNK_ROWS * n2.max(1));
    let wide = simd.avx2_fma();
    let AdamGroup {
        m: m1,
        v: v1,
        steps: s1,
        ..
    } = first.group;
    let AdamGroup {
        m: m2,
        v: v2,
        steps: s2,
        ..
    } = second.group;
    let firsts = m1
        .par_chunks_mut(c1)
        .zip(v1.par_chunks_mut(c1))
        .zip(s1.par_chunks_mut(CHUNK_ROWS))
        .zip(first.logits.par_chunks_mut(c1));
    let seconds = m2
        .par_chunks_mut(c2)
        .zip(v2.par_chunks_mut(c2))
        .zip(s2.par_chunks_mut(CHUNK_ROWS))
        .zip(second.logits.par_chunks_mut(c2));
    let written = firsts
        .zip(seconds)
        .zip(activated.par_chunks_mut(texel_chunk))
        .zip(grads.par_chunks_mut(texel_chunk))
        .enumerate()
        .map(
            |(c, ((((((m1, v1), s1), l1), (((m2, v2), s2), l2)), activated), grads))| {
                let first_row = c * CHUNK_ROWS;
                let one = ChunkRows {
                    first_row,
                    m: m1,
                    v: v1,
                    steps: s1,
                    logits: l1,
                    activated: &mut *activated,
                    grads: &mut *grads,
                };
                let w1 = step_rows_dispatch(one, &how[0], wide);
                let two = ChunkRows {
                    first_row,
                    m: m2,
                    v: v2,
                    steps: s2,
                    logits: l2,
                    activated,
                    grads,
                };
                (w1, step_rows_dispatch(two, &how[1], wide))
            },
        )
        .reduce(|| (0, 0), |a, b| (a.0.max(b.0), a.1.max(b.1)));
    [written.0 != EXPONENT, written.1 != EXPONENT]
}

/// The argument checks of [`step_texture_group`]; returns the texels per row.
fn check_group(
    group: &AdamGroup,
    logits: &[f32],
    activated: &[[f32; 4]],
    grads: &[[f32; 4]],
    channels: &Range<usize>,
    mask: Option<&[bool]>,
    added: Option<&[RowGradient]>,
) -> usize {
    let n = group.row_len;
    let rows = group.rows();
    assert!(!channels.is_empty() && channels.end <= 4, "channels must lie in 0..4");
    let texels = n / channels.len();
    assert_eq!(texels * channels.len(), n, "a row holds every channel's texels");
    assert_eq!(logits.len(), rows * n, "one logit row per billboard");
    assert_eq!(activated.len(), rows * texels, "one activated row per billboard");
    assert_eq!(grads.len(), rows * texels, "one gradient row per billboard");
    assert!(mask.is_none_or(|m| m.len() == texels), "one mask flag per texel");
    assert!(
        added.is_none_or(|a| a.len() == rows),
        "one regulariser gradient per row"
    );
    texels
}

/// [`step_rows`] in the AVX2 build when `wide` ([`Simd::avx2_fma`]: the CPU has AVX2 and FMA),
/// else the baseline.
#[inline]
fn step_rows_dispatch(rows: ChunkRows<'_>, how: &RowStep<'_, '_>, wide: bool) -> u32 {
    #[cfg(target_arch = "x86_64")]
    if wide {
        // SAFETY: `wide` is `Simd::avx2_fma`: the CPU has AVX2 and FMA.
        return unsafe { step_rows_avx2(rows, how) };
    }
    let _ = wide;
    step_rows(rows, how)
}

/// One rayon chunk of the texture step: `steps.len()` rows starting at billboard `first_row`.
struct ChunkRows<'a> {
    first_row: usize,
    m: &'a mut [f32],
    v: &'a mut [f32],
    steps: &'a mut [u32],
    logits: &'a mut [f32],
    activated: &'a mut [[f32; 4]],
    grads: &'a mut [[f32; 4]],
}

/// What every row of the step shares.
struct RowStep<'a, 'h> {
    channels: Range<usize>,
    texels: usize,
    mask: Option<&'a [bool]>,
    selection: RowSelection<'a>,
    /// Per row, the regularisers' gradient to add to the texels' gradients as they are read.
    added: Option<&'a [RowGradient]>,
    global_step: u64,
    lr: f32,
    hp: &'h AdamParams,
}

/// [`step_rows`] compiled for AVX2 and FMA (the same operations, eight lanes a register: the same
/// bits as the baseline build, which [`Simd::BASELINE`] selects).
///
/// # Safety
/// The CPU must support AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn step_rows_avx2(rows: ChunkRows<'_>, how: &RowStep<'_, '_>) -> u32 {
    step_rows(rows, how)
}

/// The rows of one chunk, one after the other: chain through the sigmoid (consuming the
/// gradient), Adam, re-activation. Returns the largest exponent field of the logits it wrote
/// (their finiteness check, while they are in cache).
#[inline(always)]
fn step_rows(rows: ChunkRows<'_>, how: &RowStep<'_, '_>) -> u32 {
    let ChunkRows {
        first_row,
        m,
        v,
        steps,
        logits,
        activated,
        grads,
    } = rows;
    let (texels, n) = (how.texels, how.texels * how.channels.len());
    let keep = |k: usize| how.mask.is_none_or(|m| m[k]);
    let owned: [bool; 4] = std::array::from_fn(|c| how.channels.contains(&c));
    // `d_logit` holds the logit gradient, then the row's sigmoids before they are scattered.
    let mut d_logit = vec![0.0f32; n];
    // Dense rows share the group's step count, so its Adam factors are computed once.
    let dense_factors = StepFactors::new(how.lr, how.hp, how.global_step);
    let mut written = 0u32;
    for r in 0..steps.len() {
        let span = r * n..(r + 1) * n;
        let texel_span = r * texels..(r + 1) * texels;
        let factors = match how.selection {
            RowSelection::Dense => {
                steps[r] = steps[r].saturating_add(1);
                dense_factors
            }
            RowSelection::Sparse(selected) => {
                if !selected[first_row + r] {
                    clear_channels(&mut grads[texel_span], owned);
                    continue;
                }
                steps[r] = steps[r].saturating_add(1);
                StepFactors::new(how.lr, how.hp, u64::from(steps[r]))
            }
            RowSelection::Lazy { selected, now } => {
                if !selected[first_row + r] {
                    continue;
                }
                steps[r] = now;
                dense_factors
            }
        };
        let (y, g) = (&mut activated[texel_span.clone()], &mut grads[texel_span]);
        // Chain through the sigmoid, consuming (zeroing) the gradient as it is read, with the
        // regularisers' gradient added first (as `regularise` would have added it in place).
        let added = how.added.map(|a| a[first_row + r]);
        for (ci, ch) in how.channels.clone().enumerate() {
            // `RowGradient::add`'s two addends, `−0.0` (no change) without regularisers.
            let addends = added.map_or([-0.0; 2], |a| a.addends(ch));
            for k in 0..texels {
                let y = y[k][ch];
                let g = RowGradient::add_addends(addends, std::mem::take(&mut g[k][ch]));
                d_logit[ci * texels + k] = if keep(k) { g * y * (1.0 - y) } else { 0.0 };
            }
        }
        let x = &mut logits[span.clone()];
        update_row_with(&mut m[span.clone()], &mut v[span], x, &d_logit, factors, how.hp);
        written = written.max(max_exponent_field(x));
        // Sigmoids over the contiguous logits (vectorised), then scattered into the texels.
        for (s, &x) in d_logit.iter_mut().zip(x.iter()) {
            *s = sigmoid(x);
        }
        for (ci, ch) in how.channels.clone().enumerate() {
            for k in 0..texels {
                y[k][ch] = if keep(k) { d_logit[ci * texels + k] } else { 0.0 };
            }
        }
    }
    written
}

/// Zeroes the channels flagged in `owned` of every texel. A fixed trip count with a per-channel
/// test: a `fill` of a variable channel range would be a `memset` call per texel.
fn clear_channels(g: &mut [[f32; 4]], owned: [bool; 4]) {
    for texel in g {
        for c in 0..4 {
            if owned[c] {
                texel[c] = 0.0;
            }
        }
    }
}
