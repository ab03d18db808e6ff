//! Lazy Adam: dense Adam's zero-gradient steps of a row, applied in one go when the row is next
//! needed.
//!
//! In dense Adam ([`super::AdamMode::Dense`]) a row that receives no gradient at step `s` still
//! steps: `m ← β₁m`, `v ← β₂v`, `p −= (lr_s/(1−β₁ˢ)) · m/(√v/√(1−β₂ˢ) + ε)`. After `k` such steps
//! from moments `m₀, v₀` (those right after the row's last real update, at live step `a`), the
//! moments are `β₁ᵏm₀` and `β₂ᵏv₀`, and with `ε` left out the parameter has moved by
//!
//! `Δp = −(m₀/√v₀) · Σ_{i=1..k} c_{a+i} · rⁱ`,   `c_s = (lr_s/(1−β₁ˢ)) · √(1−β₂ˢ)`,   `r = β₁/√β₂`.
//!
//! The sum is one scalar per row and group; [`LazyLog`] keeps the Adam factors of every live step
//! of a group, so that a row last updated at live step `a` is brought to the present by
//! [`catch_up_rows`]. `r ≈ 0.9005` for the reference's β, so the sum is cut after [`MAX_TERMS`]
//! terms (`r²⁵⁶ ≈ 2e-12` of the first). Values whose second moment is below [`V_EXACT`] (where
//! `ε` is more than 1e-5 of `√v`: coefficients that almost never get a gradient, such as high SH
//! degrees) take the skipped steps one by one with `ε` instead (in f64), so that the catch-up is
//! dense Adam up to rounding for every value. A row's update count `steps[row]` holds, in this
//! mode, the live step through which the row is up to date.
//!
//! Tested against `k` dense zero-gradient steps in `tests/suite/train_lazy_adam.rs` (tolerance
//! there, with the measured worst case).

use super::adam::{AdamGroup, AdamParams, StepFactors};
use super::finite::{EXPONENT, max_exponent_field};
use crate::cpu::Simd;
use crate::model::sigmoid;
use rayon::prelude::*;
use std::ops::Range;

/// Terms of the catch-up sum after which it is cut (`r²⁵⁶ ≈ 2.3e-12` for β₁ 0.9, β₂ 0.999).
pub const MAX_TERMS: usize = 256;

/// Second moments below which the catch-up takes the skipped steps one by one with `ε`
/// (`√1e-20 = 1e-10 = 10⁵ ε`).
pub const V_EXACT: f32 = 1e-20;

/// Rows per rayon task of [`catch_up_rows`].
const CHUNK_ROWS: usize = 64;

/// The Adam factors of one parameter group's live steps (the steps at which the group updates):
/// entry `j − 1` belongs to live step `j`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LazyLog {
    /// The factors of each live step, in order (`c_s` is the product of their two values).
    pub factors: Vec<StepFactors>,
}

/// What a row last brought up to date at live step `a` owes: the step size of its parameter
/// move (`Σ c_{a+i} rⁱ`), its moments' decays `β₁ᵏ`, `β₂ᵏ`, and for the values that take them
/// one by one ([`V_EXACT`]) the skipped steps' factors.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pending<'a> {
    /// `Σ_{i=1..min(k, MAX_TERMS)} c_{a+i} rⁱ`: the parameter moves by `−move_size · m/√v`.
    pub move_size: f32,
    /// `β₁ᵏ`.
    pub decay1: f32,
    /// `β₂ᵏ`.
    pub decay2: f32,
    /// The factors of the skipped steps (the first [`MAX_TERMS`]), in order.
    pub skipped: &'a [StepFactors],
    /// The Adam parameters.
    pub hp: AdamParams,
}

impl LazyLog {
    /// Live steps recorded.
    pub fn live_steps(&self) -> u64 {
        self.factors.len() as u64
    }

    /// Records a live step taken with `factors` (those of [`StepFactors::new`] at the group's
    /// step count and learning rate).
    pub fn record(&mut self, factors: StepFactors) {
        self.factors.push(factors);
    }

    /// What a row up to date through live step `synced` owes now; `None` when nothing (it is up
    /// to date).
    pub fn pending(&self, synced: u64, hp: &AdamParams) -> Option<Pending<'_>> {
        let now = self.live_steps();
        if synced >= now {
            return None;
        }
        let k = now - synced;
        let r = hp.beta1 as f64 / (hp.beta2 as f64).sqrt();
        let first = synced as usize;
        let skipped = &self.factors[first..first + (k as usize).min(MAX_TERMS)];
        let mut power = 1.0f64;
        let mut sum = 0.0f64;
        for f in skipped {
            power *= r;
            sum += f.step_size() as f64 * f.bc2_sqrt() as f64 * power;
        }
        let k = k.min(i32::MAX as u64) as i32;
        Some(Pending {
            move_size: sum as f32,
            decay1: (hp.beta1 as f64).powi(k) as f32,
            decay2: (hp.beta2 as f64).powi(k) as f32,
            skipped,
            hp: *hp,
        })
    }
}

impl LazyLog {
    /// [`LazyLog::pending`] of a row up to date through `synced`, reusing `memo` (the previous
    /// answer) when its step is the same: rows seen together share their last step, and the sum
    /// is up to [`MAX_TERMS`] terms.
    pub fn pending_memo<'a>(
        &'a self,
        synced: u32,
        hp: &AdamParams,
        memo: &mut Option<(u32, Option<Pending<'a>>)>,
    ) -> Option<Pending<'a>> {
        match *memo {
            Some((s, p)) if s == synced => p,
            _ => {
                let p = self.pending(u64::from(synced), hp);
                *memo = Some((synced, p));
                p
            }
        }
    }
}

/// Brings one row's parameters `params` and moments `m`, `v` up to date with `pending`:
/// [`move_row`], then the moments' decays.
#[inline(always)]
pub fn catch_up_row(m: &mut [f32], v: &mut [f32], params: &mut [f32], pending: Pending<'_>) {
    move_row(m, v, params, &pending);
    for (m, v) in m.iter_mut().zip(v.iter_mut()) {
        *m *= pending.decay1;
        *v *= pending.decay2;
    }
}

/// The pending move of one row's parameters `params`, whose moments are `m`, `v` (left as they
/// are): the closed form, and the skipped steps one by one for the values below [`V_EXACT`].
#[inline(always)]
pub fn move_row(m: &[f32], v: &[f32], params: &mut [f32], pending: &Pending<'_>) {
    let mut small = false;
    // Zipped slices (no bounds checks), so that the loop vectorises.
    for (p, (&m, &v)) in params.iter_mut().zip(m.iter().zip(v.iter())) {
        *p = caught_up(*p, m, v, pending.move_size);
        small |= v < V_EXACT && m != 0.0;
    }
    if small {
        // A value with `m = 0` never moves (its first moment stays 0).
        for (p, (&m, &v)) in params.iter_mut().zip(m.iter().zip(v.iter())) {
            if v < V_EXACT && m != 0.0 {
                *p = stepped_one_by_one(*p, m, v, pending);
            }
        }
    }
}

/// A parameter `p` with moments `m`, `v ≥` [`V_EXACT`] after the pending move of step size
/// `move_size`; smaller `v` are left as they are, for [`stepped_one_by_one`].
#[inline(always)]
fn caught_up(p: f32, m: f32, v: f32, move_size: f32) -> f32 {
    // The step is selected, not the result: the parameter is then stored whatever `v` is (a
    // selected result is compiled to a masked store, slow on AMD Zen: docs/perf.md). `p − 0`
    // is `p`, bit for bit; the quotient of a small `v` is discarded.
    let step = if v >= V_EXACT { move_size * m / v.sqrt() } else { 0.0 };
    p - step
}

/// `p` after the skipped zero-gradient steps taken one by one with `ε` (in f64; at most
/// [`MAX_TERMS`] of them): the catch-up of a value whose `√v` is too close to `ε` for the closed
/// form.
#[cold]
fn stepped_one_by_one(p: f32, m: f32, v: f32, pending: &Pending<'_>) -> f32 {
    let hp = &pending.hp;
    let (mut m, mut v, mut p) = (m as f64, v as f64, p as f64);
    for f in pending.skipped {
        m *= hp.beta1 as f64;
        v *= hp.beta2 as f64;
        p -= f.step_size() as f64 * m / (v.sqrt() / f.bc2_sqrt() as f64 + hp.eps as f64);
    }
    p as f32
}

/// One texture group's rows to bring up to date: the group, its planar logits and the texel
/// channels it owns (as [`super::texture_step::GroupStep`]).
pub struct CatchUpGroup<'a> {
    /// The group's moments; `steps[row]` is the live step the row is up to date through.
    pub group: &'a mut AdamGroup,
    /// The group's live steps.
    pub log: &'a LazyLog,
    /// Planar logits, `channels.len() · TS²` per row.
    pub logits: &'a mut [f32],
    /// The texel channels the group owns (`0..3` colour, `3..4` alpha).
    pub channels: Range<usize>,
    /// Per texel, `false` for the texels that stay at alpha 0.
    pub mask: Option<&'a [bool]>,
}

/// Brings the rows flagged in `selected` (every row when `None`) of `target` up to date
/// ([`catch_up_row`]), refreshes their activated texels (`sigmoid` of the logits, masked texels
/// 0) and marks them up to date. Parallel over chunks of rows; each row's arithmetic is fixed,
/// so the bits do not depend on the thread count, nor on `simd` (the instruction set of the
/// loops). Returns false when a logit it wrote is not finite.
///
/// # Panics
/// When the slices do not hold `group.rows()` rows.
pub fn catch_up_rows(
    target: CatchUpGroup<'_>,
    activated: &mut [[f32; 4]],
    selected: Option<&[bool]>,
    hp: &AdamParams,
    simd: Simd,
) -> bool {
    let CatchUpGroup {
        group,
        log,
        logits,
        channels,
        mask,
    } = target;
    let n = group.row_len;
    let rows = group.rows();
    let texels = n / channels.len().max(1);
    assert_eq!(logits.len(), rows * n, "one logit row per billboard");
    assert_eq!(activated.len(), rows * texels, "one activated row per billboard");
    assert!(selected.is_none_or(|s| s.len() == rows), "one flag per row");
    let how = Rows {
        log,
        hp,
        channels,
        mask,
        texels,
        now: log.live_steps().min(u64::from(u32::MAX)) as u32,
    };
    let AdamGroup { m, v, steps, .. } = group;
    let (cn, ct) = (CHUNK_ROWS * n.max(1), CHUNK_ROWS * texels.max(1));
    let wide = simd.avx2_fma();
    let written = m
        .par_chunks_mut(cn)
        .zip(v.par_chunks_mut(cn))
        .zip(logits.par_chunks_mut(cn))
        .zip(steps.par_chunks_mut(CHUNK_ROWS))
        .zip(activated.par_chunks_mut(ct))
        .enumerate()
        .map(|(c, ((((m, v), x), steps), y))| {
            let flags = selected.map(|s| &s[c * CHUNK_ROWS..c * CHUNK_ROWS + steps.len()]);
            let chunk = Chunk {
                m,
                v,
                x,
                steps,
                y,
                flags,
            };
            #[cfg(target_arch = "x86_64")]
            if wide {
                // SAFETY: `wide` is `Simd::avx2_fma`: the CPU has AVX2 and FMA.
                return unsafe { catch_up_chunk_avx2(chunk, &how) };
            }
            let _ = wide;
            catch_up_chunk(chunk, &how)
        })
        .reduce(|| 0, u32::max);
    written != EXPONENT
}

/// What every row of [`catch_up_rows`] shares.
struct Rows<'a> {
    log: &'a LazyLog,
    hp: &'a AdamParams,
    channels: Range<usize>,
    mask: Option<&'a [bool]>,
    texels: usize,
    now: u32,
}

/// One rayon chunk of [`catch_up_rows`]: its rows' moments, logits, counts, activated texels and
/// selection flags.
struct Chunk<'a> {
    m: &'a mut [f32],
    v: &'a mut [f32],
    x: &'a mut [f32],
    steps: &'a mut [u32],
    y: &'a mut [[f32; 4]],
    flags: Option<&'a [bool]>,
}

/// [`catch_up_chunk`] compiled for AVX2 and FMA (the same operations: the same bits).
///
/// # Safety
/// The CPU must support AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn catch_up_chunk_avx2(chunk: Chunk<'_>, how: &Rows<'_>) -> u32 {
    catch_up_chunk(chunk, how)
}

/// The rows of one chunk; returns the largest exponent field of the logits written. Rows seen
/// together share their last step, so the pending scalars of the previous row are reused when
/// its step is the same.
#[inline(always)]
fn catch_up_chunk(chunk: Chunk<'_>, how: &Rows<'_>) -> u32 {
    let Chunk {
        m,
        v,
        x,
        steps,
        y,
        flags,
    } = chunk;
    let texels = how.texels;
    let n = texels * how.channels.len();
    let mut sigmoids = vec![0.0f32; n];
    let mut memo: Option<(u32, Option<Pending<'_>>)> = None;
    let mut written = 0u32;
    for (r, synced) in steps.iter_mut().enumerate() {
        if flags.is_some_and(|f| !f[r]) {
            continue;
        }
        let Some(pending) = how.log.pending_memo(*synced, how.hp, &mut memo) else {
            continue;
        };
        let span = r * n..(r + 1) * n;
        let x = &mut x[span.clone()];
        catch_up_row(&mut m[span.clone()], &mut v[span], x, pending);
        written = written.max(max_exponent_field(x));
        // Sigmoids over the contiguous logits, then scattered into the texels (as the texture
        // step does after its update).
        for (s, &x) in sigmoids.iter_mut().zip(x.iter()) {
            *s = sigmoid(x);
        }
        let y = &mut y[r * texels..(r + 1) * texels];
        for (ci, ch) in how.channels.clone().enumerate() {
            for k in 0..texels {
                y[k][ch] = if how.mask.is_none_or(|m| m[k]) {
                    sigmoids[ci * texels + k]
                } else {
                    0.0
                };
            }
        }
        *synced = how.now;
    }
    written
}

/// `logits` (one group's planar row) after the pending moves of rows up to date through
/// `steps[row]`, without changing the optimiser state: what [`catch_up_rows`] would write, for a
/// model exported between steps.
pub fn caught_up_values(group: &AdamGroup, log: &LazyLog, logits: &mut [f32], hp: &AdamParams) {
    let n = group.row_len;
    let mut memo = None;
    for (row, &synced) in group.steps.iter().enumerate() {
        if let Some(pending) = log.pending_memo(synced, hp, &mut memo) {
            let span = row * n..(row + 1) * n;
            move_row(
                &group.m[span.clone()],
                &group.v[span.clone()],
                &mut logits[span],
                &pending,
            );
        }
    }
}
