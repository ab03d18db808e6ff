//! The compositing backward of a chunk of up to eight blended pairs of one entry
//! ([`super::tile_backward`]), written in explicit AVX2 instructions: the pairs' samples, their
//! decisions, the back-to-front step of each pair's pixel and the texels seen through the
//! upstream gradients run side by side in vector registers; the texel gradients are then made
//! tap by tap as channel vectors and added lane by lane in the scalar code's order, with −0.0
//! added (no bit of any sum changes) for the taps the scalar code skips, so that no branch
//! depends on the data.
//!
//! A second implementation of the scalar chunk of `tile_backward.rs` (the stages' own code:
//! [`crate::stages::composite::classify`], [`crate::stages::composite::CompositeBackState::pop`]
//! and [`crate::stages::bilinear::RowTaps::vjp_rgba_lanes`]), with the same IEEE operations in
//! the same order per lane, none fused, so the same bits:
//! - the sample as in [`super::tile_forward_avx2`];
//! - the pop: with features `f = (r, g, b, 1, depth)`, the colour behind `B` and the upstream
//!   gradient `g`, `dot = ((((0 + (f₀−B₀)g₀) + (f₁−B₁)g₁) + (f₂−B₂)g₂) + (f₃−B₃)g₃) + (f₄−B₄)g₄`,
//!   `∂f = w·g`, `B ← α·f + (1 − α)·B`, `∂α = T·dot` (0 where the clamp was active, unless the
//!   clamp gradient passes through);
//! - each tap's texel seen through `∂rgba`: `((t_α·∂α + t_r·∂r) + t_g·∂g) + t_b·∂b`, and
//!   `∂u = Σ_k (∂w_k/∂u · seen_k) & keep_k` from +0 in tap order (likewise `∂v`).
//!
//! `tests/suite/raster_lanes.rs` compares every gradient bit with the baseline build.

#![cfg(target_arch = "x86_64")]

use super::tile_forward_avx2::{Thresholds, decide, sample_lanes_with_texels, store, transpose_four};
use super::tile_gradients::{CHANNELS, PixelBack, TexelTarget};
use super::tile_types::EntryPair;
use crate::stages::bilinear::RowTaps;
use crate::stages::composite::{ClampGradient, CompositeParams};
use crate::stages::ray_plane::{LANES, LaneTransforms, RowHits};
use crate::stages::splat_transform::SplatTransform;
use glam::Vec3;
use std::arch::x86_64::*;

/// What the compositing backward leaves for the lanes of a chunk.
pub(super) struct ChunkGrads {
    /// Some lane is one of the chunk's blended pairs.
    pub(super) blended: bool,
    /// `∂L/∂depth` of the hit.
    pub(super) d_depth: [f32; LANES],
    /// `∂L/∂u`, `∂L/∂v` of the hit (zero where not `blended`).
    pub(super) d_u: [f32; LANES],
    pub(super) d_v: [f32; LANES],
}

/// Eight 4-vectors (one per lane) as four vectors of eight lanes (their first, second, third
/// and fourth floats).
#[inline(always)]
unsafe fn lanes4(v: &[__m128; LANES]) -> [__m256; 4] {
    // SAFETY: register operations of AVX, enabled by every caller.
    unsafe {
        transpose_four(
            _mm256_set_m128(v[4], v[0]),
            _mm256_set_m128(v[5], v[1]),
            _mm256_set_m128(v[6], v[2]),
            _mm256_set_m128(v[7], v[3]),
        )
    }
}

/// The first four floats of `v` as one vector, and `v[4]`.
#[inline(always)]
unsafe fn split(v: &[f32; CHANNELS]) -> (__m128, f32) {
    // SAFETY: `v` holds five floats; the load reads the first four.
    (unsafe { _mm_loadu_ps(v.as_ptr()) }, v[4])
}

/// The pairs of a chunk lane by lane (lanes past the chunk repeat its last pair): their pixel
/// centres, the transmittances in front and the tile-local pixels, and how many lanes hold the
/// chunk's own pairs.
pub(super) struct ChunkLanes {
    /// `(i0 + x) as f32 + 0.5` and `(j0 + y) as f32 + 0.5` of each lane's pair.
    pub(super) px: [f32; LANES],
    pub(super) py: [f32; LANES],
    transmittance: __m256,
    pixel: [u32; LANES],
    /// The chunk's pairs (1 to [`LANES`]): lanes `0..len`.
    len: usize,
}

/// [`ChunkLanes`] of `chunk` (1 to [`LANES`] pairs) in the tile whose first pixel is `(i0, j0)`:
/// the pairs read as two vectors and split into their fields (the pixel, column and row packed
/// in one 32-bit word per pair, see [`EntryPair`]), instead of lane by lane. The centres are the
/// scalar code's, bit for bit: the integer `i0 + x` converted to f32 (exact conversion of the same
/// integer for `i0 + x < 2³¹`), plus 0.5.
///
/// # Safety
/// The CPU must support AVX2 (the caller is compiled with it).
#[inline(always)]
pub(super) unsafe fn chunk_lanes(chunk: &[EntryPair], (i0, j0): (u32, u32)) -> ChunkLanes {
    let n = chunk.len();
    assert!(
        (1..=LANES).contains(&n) && i0 < 1 << 31 && j0 < 1 << 31,
        "a chunk holds 1 to 8 pairs of a tile inside the i32 range"
    );
    let mut padded = [EntryPair::default(); LANES];
    let pairs: &[EntryPair; LANES] = match chunk.try_into() {
        Ok(full) => full,
        Err(_) => {
            padded[..n].copy_from_slice(chunk);
            padded[n..].fill(chunk[n - 1]);
            &padded
        }
    };
    // SAFETY: the two loads read the eight pairs (64 bytes) of `pairs`; the rest are register
    // operations of AVX2.
    unsafe {
        let base = pairs.as_ptr().cast::<__m256i>();
        // Pairs 0-3 and 4-7, each as (word, transmittance) 32-bit pairs.
        let (first, second) = (_mm256_loadu_si256(base), _mm256_loadu_si256(base.add(1)));
        let field = |order: __m256i| {
            _mm256_blend_epi32::<0xF0>(
                _mm256_permutevar8x32_epi32(first, order),
                _mm256_permutevar8x32_epi32(second, order),
            )
        };
        let words = field(_mm256_setr_epi32(0, 2, 4, 6, 0, 2, 4, 6));
        let transmittance = _mm256_castsi256_ps(field(_mm256_setr_epi32(1, 3, 5, 7, 1, 3, 5, 7)));
        let x = _mm256_and_si256(_mm256_srli_epi32::<16>(words), _mm256_set1_epi32(0xff));
        let y = _mm256_srli_epi32::<24>(words);
        let centre = |origin: u32, c: __m256i| {
            store(_mm256_add_ps(
                _mm256_cvtepi32_ps(_mm256_add_epi32(c, _mm256_set1_epi32(origin as i32))),
                _mm256_set1_ps(0.5),
            ))
        };
        let mut pixel = [0u32; LANES];
        _mm256_storeu_si256(
            pixel.as_mut_ptr().cast(),
            _mm256_and_si256(words, _mm256_set1_epi32(0xffff)),
        );
        ChunkLanes {
            px: centre(i0, x),
            py: centre(j0, y),
            transmittance,
            pixel,
            len: n,
        }
    }
}

/// The compositing backward of a chunk of at most [`LANES`] blended pairs of one entry, in pixel
/// order, given as its [`ChunkLanes`] `lanes`, with the taps `taps` and hits `hits` of its
/// pairs' pixels: see the module docs. `pixels[pair.pixel]` is the pair's pixel recursion
/// (behind, upstream), updated in place; `rgb` is the billboard's SH colour; `record_rgb`
/// receives each blended lane's `(∂r, ∂g, ∂b)` in pixel order; `target` each texel gradient,
/// lane by lane and tap by tap.
///
/// # Safety
/// The CPU must support AVX2 and FMA (the caller is compiled with them).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub(super) unsafe fn chunk_backward(
    lanes: &ChunkLanes,
    taps: &RowTaps,
    hits: &RowHits,
    texture: &[[f32; 4]],
    rgb: Vec3,
    params: &CompositeParams,
    pixels: &mut [PixelBack],
    record_rgb: &mut Vec3,
    target: &mut TexelTarget<'_>,
) -> ChunkGrads {
    let n = lanes.len;
    debug_assert!((1..=LANES).contains(&n));
    // SAFETY: AVX2 and FMA are enabled (the caller's contract); every memory access below is
    // through bounds-checked slices and arrays, or a helper whose contract is met.
    unsafe {
        let ([r, g, bl, a], texels) = sample_lanes_with_texels(taps, texture);
        let transmittance = lanes.transmittance;
        let d = decide(transmittance, a, &Thresholds::of(params));
        let in_chunk = _mm256_castsi256_ps(_mm256_cmpgt_epi32(
            _mm256_set1_epi32(n as i32),
            _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7),
        ));
        // A replayed pair blends again (the forward blended it with these values); a lane that
        // did not (never in practice) is left out, as the scalar chunk leaves it out.
        let sampled = _mm256_castsi256_ps(_mm256_cmpgt_epi32(
            _mm256_cvtepu8_epi32(_mm_loadl_epi64(taps.lane_arrays().3.as_ptr().cast())),
            _mm256_setzero_si256(),
        ));
        let blended_mask = _mm256_and_ps(_mm256_and_ps(in_chunk, sampled), _mm256_andnot_ps(d.stop, d.kept));
        let blended_bits = _mm256_movemask_ps(blended_mask) as u32;
        // The pixels' recursions: four channels of each lane's colour behind and upstream
        // gradient transposed into lanes, the fifth gathered.
        let mut behind4 = [_mm_setzero_ps(); LANES];
        let mut upstream4 = [_mm_setzero_ps(); LANES];
        let mut behind_depth = [0.0f32; LANES];
        let mut upstream_depth = [0.0f32; LANES];
        for l in 0..LANES {
            let pixel = &pixels[lanes.pixel[l] as usize];
            (behind4[l], behind_depth[l]) = split(&pixel.back.behind);
            (upstream4[l], upstream_depth[l]) = split(&pixel.d_out);
        }
        let [b0, b1, b2, b3] = lanes4(&behind4);
        let [g0, g1, g2, g3] = lanes4(&upstream4);
        let b4 = _mm256_loadu_ps(behind_depth.as_ptr());
        let g4 = _mm256_loadu_ps(upstream_depth.as_ptr());
        let features = [
            _mm256_add_ps(r, _mm256_set1_ps(rgb.x)),
            _mm256_add_ps(g, _mm256_set1_ps(rgb.y)),
            _mm256_add_ps(bl, _mm256_set1_ps(rgb.z)),
            _mm256_set1_ps(1.0),
            _mm256_loadu_ps(hits.depth.as_ptr()),
        ];
        let behind = [b0, b1, b2, b3, b4];
        let upstream = [g0, g1, g2, g3, g4];
        let mut dot = _mm256_setzero_ps();
        let mut d_features = [_mm256_setzero_ps(); CHANNELS];
        let mut next_behind = [_mm256_setzero_ps(); CHANNELS];
        let keep = _mm256_sub_ps(_mm256_set1_ps(1.0), d.alpha);
        for ch in 0..CHANNELS {
            let (f, b, u) = (features[ch], behind[ch], upstream[ch]);
            dot = _mm256_add_ps(dot, _mm256_mul_ps(_mm256_sub_ps(f, b), u));
            d_features[ch] = _mm256_mul_ps(d.weight, u);
            next_behind[ch] = _mm256_add_ps(_mm256_mul_ps(d.alpha, f), _mm256_mul_ps(keep, b));
        }
        let d_alpha = _mm256_mul_ps(transmittance, dot);
        let d_alpha = if params.clamp_gradient == ClampGradient::PassThrough {
            d_alpha
        } else {
            _mm256_andnot_ps(d.clamped, d_alpha)
        };
        // Lanes past the chunk or not blended get no gradient.
        let d_alpha = _mm256_and_ps(d_alpha, blended_mask);
        let d_r = _mm256_and_ps(d_features[0], blended_mask);
        let d_g = _mm256_and_ps(d_features[1], blended_mask);
        let d_b = _mm256_and_ps(d_features[2], blended_mask);
        let d_z = _mm256_and_ps(d_features[4], blended_mask);
        // Per lane: its new colour behind (four channels, and the fifth; a lane that did not
        // blend keeps its old one), transposed back from lanes to one 4-vector per lane.
        let next_behind: [__m256; CHANNELS] =
            std::array::from_fn(|ch| _mm256_blendv_ps(behind[ch], next_behind[ch], blended_mask));
        let mut behind_rows = [[0.0f32; 4]; LANES];
        let behind_depth = store(next_behind[4]);
        let rows = |v: [__m256; 4], out: &mut [[f32; 4]; LANES]| {
            for (l, v) in v.into_iter().enumerate() {
                _mm_storeu_ps(out[l].as_mut_ptr(), _mm256_castps256_ps128(v));
                _mm_storeu_ps(out[l + 4].as_mut_ptr(), _mm256_extractf128_ps::<1>(v));
            }
        };
        rows(
            transpose_four(next_behind[0], next_behind[1], next_behind[2], next_behind[3]),
            &mut behind_rows,
        );
        for l in 0..n {
            let [b0, b1, b2, b3] = behind_rows[l];
            pixels[lanes.pixel[l] as usize].back.behind = [b0, b1, b2, b3, behind_depth[l]];
        }
        // The colour gradients added to the entry's in pixel order, every lane adding its own
        // or +0 (which changes no bit: a sum that starts at +0 is never −0), as one 4-vector
        // per lane whose fourth channel is not kept.
        let mut d_rgba_rows = [[0.0f32; 4]; LANES];
        rows(transpose_four(d_r, d_g, d_b, d_alpha), &mut d_rgba_rows);
        let mut rgb_sum = _mm_setr_ps(record_rgb.x, record_rgb.y, record_rgb.z, 0.0);
        for row in &d_rgba_rows {
            rgb_sum = _mm_add_ps(rgb_sum, _mm_loadu_ps(row.as_ptr()));
        }
        let mut rgb_out = [0.0f32; 4];
        _mm_storeu_ps(rgb_out.as_mut_ptr(), rgb_sum);
        *record_rgb = Vec3::new(rgb_out[0], rgb_out[1], rgb_out[2]);
        // Each tap's texel seen through the upstream gradient, then ∂u and ∂v.
        let (index, weight, keep_masks, _) = taps.lane_arrays();
        let (d_weight_du, d_weight_dv) = taps.derivative_arrays();
        let (mut du, mut dv) = (_mm256_setzero_ps(), _mm256_setzero_ps());
        for k in 0..4 {
            let [tr, tg, tb, ta] = texels[k];
            let seen = _mm256_add_ps(
                _mm256_add_ps(
                    _mm256_add_ps(_mm256_mul_ps(ta, d_alpha), _mm256_mul_ps(tr, d_r)),
                    _mm256_mul_ps(tg, d_g),
                ),
                _mm256_mul_ps(tb, d_b),
            );
            let m = _mm256_castsi256_ps(_mm256_loadu_si256(keep_masks[k].as_ptr().cast()));
            let wu = _mm256_loadu_ps(d_weight_du[k].as_ptr());
            let wv = _mm256_loadu_ps(d_weight_dv[k].as_ptr());
            du = _mm256_add_ps(du, _mm256_and_ps(_mm256_mul_ps(wu, seen), m));
            dv = _mm256_add_ps(dv, _mm256_and_ps(_mm256_mul_ps(wv, seen), m));
        }
        // The texel gradients: per tap, `weight · ∂rgba` of every lane in four channel vectors,
        // −0.0 in every channel where the lane did not blend or the tap is outside the texture
        // (which changes no sum it is added to: `x + (−0) = x` for every `x`, −0 and +0
        // included), transposed to one 4-vector per lane. Then every one of the chunk's 32
        // (lane, tap) slots is added to its cell, lane by lane in pixel order, taps in order,
        // without a branch. A tap outside the texture has its index clamped into it and a lane
        // past the chunk repeats the last pair's taps, so every index is one the chunk's taps
        // read. (Which taps are outside depends on the data: a branch on it cost more than the
        // adds of −0.0, docs/perf.md.)
        let negative_zero = _mm256_set1_ps(-0.0);
        let mut tap_grads = [[[0.0f32; 4]; LANES]; 4];
        for k in 0..4 {
            let w = _mm256_loadu_ps(weight[k].as_ptr());
            let on = _mm256_and_ps(
                _mm256_castsi256_ps(_mm256_loadu_si256(keep_masks[k].as_ptr().cast())),
                blended_mask,
            );
            let channel = |d: __m256| _mm256_blendv_ps(negative_zero, _mm256_mul_ps(w, d), on);
            rows(
                transpose_four(channel(d_r), channel(d_g), channel(d_b), channel(d_alpha)),
                &mut tap_grads[k],
            );
        }
        let (cells, flags) = (&mut *target.cells, &mut *target.flags);
        let ts = taps.texture_side();
        assert!(
            cells.len() == ts * ts && flags.len() == ts * ts,
            "a texel target holds one cell and one flag per texel"
        );
        for l in 0..LANES {
            for k in 0..4 {
                let t = index[k][l] as usize;
                debug_assert!(t < cells.len(), "tap indices are clamped into the texture");
                // SAFETY: `RowTaps` clamps every index into the texture, whose `ts²` texels
                // match the target's cells and flags (asserted above).
                let (cell, flag) = (cells.get_unchecked_mut(t), flags.get_unchecked_mut(t));
                let sum = _mm_add_ps(_mm_loadu_ps(cell.as_ptr()), _mm_loadu_ps(tap_grads[k][l].as_ptr()));
                _mm_storeu_ps(cell.as_mut_ptr(), sum);
                *flag = 1;
            }
        }
        ChunkGrads {
            blended: blended_bits != 0,
            d_depth: store(d_z),
            d_u: store(_mm256_and_ps(du, blended_mask)),
            d_v: store(_mm256_and_ps(dv, blended_mask)),
        }
    }
}

/// `acc += d.lane(l)` for the lanes `l = 0..n` in order ([`super::tile_gradients::add_transform`]
/// lane after lane, the same bits): the first eight of the nine components of every lane are
/// turned from one vector per component into one vector per lane by an 8×8 transpose (24
/// shuffles, where reading each lane's components one by one took 56 inserts) and added to
/// the running sum one lane after another; the ninth is added as a scalar.
///
/// # Safety
/// The CPU must support AVX2 (the caller is compiled with it).
#[inline(always)]
pub(super) unsafe fn add_lanes_in_order(acc: &mut SplatTransform, d: &LaneTransforms, n: usize) {
    debug_assert!(n <= LANES);
    // SAFETY: every array read holds LANES floats; the rest are register operations of AVX.
    unsafe {
        let row = |r: &[f32; LANES]| _mm256_loadu_ps(r.as_ptr());
        let rows = [
            row(&d.tu[0]),
            row(&d.tu[1]),
            row(&d.tu[2]),
            row(&d.tv[0]),
            row(&d.tv[1]),
            row(&d.tv[2]),
            row(&d.tw[0]),
            row(&d.tw[1]),
        ];
        let lanes = transpose_eight(rows);
        let mut sum = _mm256_setr_ps(
            acc.tu.x, acc.tu.y, acc.tu.z, acc.tv.x, acc.tv.y, acc.tv.z, acc.tw.x, acc.tw.y,
        );
        let mut last = acc.tw.z;
        for (lane, v) in lanes.iter().enumerate().take(n) {
            sum = _mm256_add_ps(sum, *v);
            last += d.tw[2][lane];
        }
        let s = store(sum);
        acc.tu = Vec3::new(s[0], s[1], s[2]);
        acc.tv = Vec3::new(s[3], s[4], s[5]);
        acc.tw = Vec3::new(s[6], s[7], last);
    }
}

/// The 8×8 transpose: element `l` of `rows[c]` becomes element `c` of the result's vector `l`.
#[inline(always)]
unsafe fn transpose_eight(rows: [__m256; 8]) -> [__m256; 8] {
    // SAFETY: register operations of AVX, enabled by every caller.
    unsafe {
        let [r0, r1, r2, r3, r4, r5, r6, r7] = rows;
        // Pairs of rows interleaved, then quadruples, within each 128-bit half.
        let t0 = _mm256_unpacklo_ps(r0, r1);
        let t1 = _mm256_unpackhi_ps(r0, r1);
        let t2 = _mm256_unpacklo_ps(r2, r3);
        let t3 = _mm256_unpackhi_ps(r2, r3);
        let t4 = _mm256_unpacklo_ps(r4, r5);
        let t5 = _mm256_unpackhi_ps(r4, r5);
        let t6 = _mm256_unpacklo_ps(r6, r7);
        let t7 = _mm256_unpackhi_ps(r6, r7);
        let q0 = _mm256_shuffle_ps::<0x44>(t0, t2);
        let q1 = _mm256_shuffle_ps::<0xEE>(t0, t2);
        let q2 = _mm256_shuffle_ps::<0x44>(t1, t3);
        let q3 = _mm256_shuffle_ps::<0xEE>(t1, t3);
        let q4 = _mm256_shuffle_ps::<0x44>(t4, t6);
        let q5 = _mm256_shuffle_ps::<0xEE>(t4, t6);
        let q6 = _mm256_shuffle_ps::<0x44>(t5, t7);
        let q7 = _mm256_shuffle_ps::<0xEE>(t5, t7);
        // Lanes 0-3 from the low halves, 4-7 from the high halves.
        [
            _mm256_permute2f128_ps::<0x20>(q0, q4),
            _mm256_permute2f128_ps::<0x20>(q1, q5),
            _mm256_permute2f128_ps::<0x20>(q2, q6),
            _mm256_permute2f128_ps::<0x20>(q3, q7),
            _mm256_permute2f128_ps::<0x31>(q0, q4),
            _mm256_permute2f128_ps::<0x31>(q1, q5),
            _mm256_permute2f128_ps::<0x31>(q2, q6),
            _mm256_permute2f128_ps::<0x31>(q3, q7),
        ]
    }
}
