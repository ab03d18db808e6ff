//! The forward pass of one tile billboard by billboard ([`super::tile_forward`]), written in
//! explicit AVX2 instructions: the eight pixels of a run are sampled, classified and composited
//! side by side in vector registers, their states kept as one array per value (structure of
//! arrays), instead of one pixel after another.
//!
//! It is a second implementation of the same arithmetic, and gives the same bits as the
//! baseline build of [`super::tile_forward`] (the scalar reference, which runs the stages'
//! own code: [`crate::stages::composite::CompositeState`] and
//! [`crate::stages::bilinear::RowTaps::sample_rgba`]). Per lane every value is made by the
//! same IEEE operations in the same order, none fused (AVX2 has no implicit fusing; every
//! multiply and add below is its own instruction):
//! - the sample: `((((+0 + w₀t₀) + w₁t₁) + w₂t₂) + w₃t₃)` per channel, each product replaced by
//!   +0 where its tap's keep mask is 0 (`sample_four`);
//! - the decision (`classify`): `α = a > max_alpha ? max_alpha : a`; skipped unless
//!   `α ≥ min_alpha` (so NaN is skipped); `T' = T·(1 − α)`; stop when not skipped and
//!   `T' < min_transmittance`; otherwise blended with weight `α·T`;
//! - the blend (`CompositeState::blend`): `acc + f·w` per feature, `T ← T'`;
//! - the median rule, the evaluated and NaN-alpha counts, the impact sum and the pairs, each
//!   as the reference does them: the impact lane by lane in pixel order (a lane that does not
//!   blend adds +0, which changes no bit), the pairs packed in pixel order.
//!
//! `tests/suite/raster_lanes.rs` compares every output and gradient bit with the baseline
//! build on trained-like and random scenes, and the raster tests check the rest.

#![cfg(target_arch = "x86_64")]

use super::TILE_SIZE;
use super::forward::{EntryPair, PairOrder, TileBlended};
use super::tile_forward::{FORWARD_FEATURES, PixelOut, TileInputs, prefetch_ahead};
use crate::stages::bilinear::RowTaps;
#[cfg(feature = "testing")]
use crate::stages::composite::{Blend, Step};
use crate::stages::composite::{CompositeParams, CompositeState};
use crate::stages::depth_distortion::{DistortionState, mapped_depth};
use crate::stages::ray_plane::{LANES, intersect_lanes, row_centres};
use std::arch::x86_64::*;

/// The running state of a tile's pixels, one row per value: pixel `q` (tile-local, row-major)
/// is element `q` of each row. Each row holds `stride` = pixels + [`LANES`] elements, the
/// padding after the last pixel making a run of [`LANES`] from any pixel in bounds (lanes past a
/// span are read and written back unchanged). The rows of one kind share one allocation, so
/// that a chunk checks its bounds once for all of them ([`ChunkStates`]).
#[derive(Default)]
pub(crate) struct LaneStates {
    /// [`FLOAT_ROWS`] rows: the transmittance ([`TRANSMITTANCE`]), the features from
    /// [`FEATURES`], the median depth ([`MEDIAN`]).
    floats: Vec<f32>,
    /// [`WORD_ROWS`] rows: [`DONE`] (all bits set once the pixel has stopped compositing, else
    /// 0), the [`EVALUATED`] and [`NAN_ALPHA`] counts.
    words: Vec<u32>,
    /// Elements per row.
    stride: usize,
    /// Only with the depth distortion (else empty).
    spread: Vec<DistortionState>,
}

const TRANSMITTANCE: usize = 0;
const FEATURES: usize = 1;
const MEDIAN: usize = FEATURES + FORWARD_FEATURES;
const FLOAT_ROWS: usize = MEDIAN + 1;
const DONE: usize = 0;
const EVALUATED: usize = 1;
const NAN_ALPHA: usize = 2;
const WORD_ROWS: usize = 3;

/// `v` as `len` copies of `value`, keeping its allocation.
fn refill<T: Copy>(v: &mut Vec<T>, len: usize, value: T) {
    v.clear();
    v.resize(len, value);
}

impl LaneStates {
    /// Every pixel of a tile of `n` pixels at the start of compositing.
    fn reset(&mut self, n: usize, distortion: bool) {
        let stride = n + LANES;
        self.stride = stride;
        refill(&mut self.floats, FLOAT_ROWS * stride, 0.0);
        self.floats[TRANSMITTANCE * stride..(TRANSMITTANCE + 1) * stride].fill(1.0);
        refill(&mut self.words, WORD_ROWS * stride, 0);
        let start = DistortionState {
            s1: 0.0,
            s2: 0.0,
            distortion: 0.0,
        };
        refill(&mut self.spread, if distortion { stride } else { 0 }, start);
    }

    /// Element `q` of float row `row`.
    fn float(&self, row: usize, q: usize) -> f32 {
        self.floats[row * self.stride + q]
    }

    /// Element `q` of word row `row`.
    fn word(&self, row: usize, q: usize) -> u32 {
        self.words[row * self.stride + q]
    }

    /// The states of the [`LANES`] pixels from `q0` (`q0` below the tile's pixel count), every
    /// row's bounds checked at once.
    #[inline(always)]
    fn chunk(&mut self, q0: usize) -> ChunkStates<'_> {
        let stride = self.stride;
        assert!(
            q0 + LANES <= stride && self.floats.len() == FLOAT_ROWS * stride && self.words.len() == WORD_ROWS * stride,
            "a chunk starts at a pixel of the tile"
        );
        ChunkStates {
            floats: self.floats[q0..].as_mut_ptr(),
            words: self.words[q0..].as_mut_ptr(),
            stride,
            _states: std::marker::PhantomData,
        }
    }
}

/// The [`LANES`] elements from one pixel of every row of a [`LaneStates`]; rows are chosen by
/// constant index, checked at compile time, and the chunk's bounds were checked when it was
/// made ([`LaneStates::chunk`]).
struct ChunkStates<'a> {
    /// Element `q0` of the first float row.
    floats: *mut f32,
    /// Element `q0` of the first word row.
    words: *mut u32,
    stride: usize,
    _states: std::marker::PhantomData<&'a mut LaneStates>,
}

impl ChunkStates<'_> {
    /// Element `q0` of float row `row` (below [`FLOAT_ROWS`]): with the check
    /// `LaneStates::chunk` made, the start of [`LANES`] floats inside the rows. Every access of
    /// a float row goes through here.
    #[inline(always)]
    fn float_row(&self, row: usize) -> *mut f32 {
        assert!(row < FLOAT_ROWS, "a float row of the states");
        self.floats.wrapping_add(row * self.stride)
    }

    /// Element `q0` of word row `row` (below [`WORD_ROWS`]), as [`Self::float_row`].
    #[inline(always)]
    fn word_row(&self, row: usize) -> *mut __m256i {
        assert!(row < WORD_ROWS, "a word row of the states");
        self.words.wrapping_add(row * self.stride).cast()
    }

    /// The eight lanes of float row `ROW`.
    #[inline(always)]
    unsafe fn load_ps<const ROW: usize>(&self) -> __m256 {
        const { assert!(ROW < FLOAT_ROWS) };
        // SAFETY: `LaneStates::chunk` checked `q0 + LANES <= stride` and the length of the
        // rows, so the LANES floats at `float_row` are inside `floats`; AVX is enabled by every
        // caller.
        unsafe { _mm256_loadu_ps(self.float_row(ROW)) }
    }

    /// Float row `ROW` set to `new` where `mask` is set and left at `old` (its lanes as
    /// [`Self::load_ps`] read them) elsewhere ([`store_blend_at`]).
    #[inline(always)]
    unsafe fn store_blend<const ROW: usize>(&mut self, old: __m256, new: __m256, mask: __m256) {
        const { assert!(ROW < FLOAT_ROWS) };
        // SAFETY: as in `load_ps` (eight floats at the pointer); the `LaneStates` is borrowed
        // exclusively; AVX is enabled by every caller.
        unsafe { store_blend_at(self.float_row(ROW), old, new, mask) }
    }

    /// The eight lanes of feature `c` (below [`FORWARD_FEATURES`]).
    #[inline(always)]
    unsafe fn load_feature(&self, c: usize) -> __m256 {
        assert!(c < FORWARD_FEATURES, "a forward feature");
        // SAFETY: as in `load_ps`, for row `FEATURES + c`.
        unsafe { _mm256_loadu_ps(self.float_row(FEATURES + c)) }
    }

    /// [`Self::store_blend`] for feature `c`.
    #[inline(always)]
    unsafe fn store_feature_blend(&mut self, c: usize, old: __m256, new: __m256, mask: __m256) {
        assert!(c < FORWARD_FEATURES, "a forward feature");
        // SAFETY: as in `store_blend`, for row `FEATURES + c`.
        unsafe { store_blend_at(self.float_row(FEATURES + c), old, new, mask) }
    }

    #[inline(always)]
    unsafe fn load_si<const ROW: usize>(&self) -> __m256i {
        const { assert!(ROW < WORD_ROWS) };
        // SAFETY: as in `load_ps`, for `words`.
        unsafe { _mm256_loadu_si256(self.word_row(ROW)) }
    }

    #[inline(always)]
    unsafe fn store_si<const ROW: usize>(&mut self, x: __m256i) {
        const { assert!(ROW < WORD_ROWS) };
        // SAFETY: as in `load_ps`, for `words`; the `LaneStates` is borrowed exclusively.
        unsafe { _mm256_storeu_si256(self.word_row(ROW), x) }
    }
}

/// Writes `blendv(old, new, mask)` to the eight floats at `p` with one plain 32-byte store:
/// `new` in the lanes where `mask` is set, `old` (what the caller loaded from `p`) in the others.
///
/// `old` first passes through an empty assembly block, which leaves its bits as they are but
/// hides from the compiler that it was loaded from `p`. Otherwise the compiler turns "load,
/// blend with what was loaded, store back" into a masked store (`vmaskmovps`), which gives the
/// same bits but is slow on AMD Zen cores: on a Zen 4 host the object scene's forward took 34 ms
/// with the nine masked stores per run and 28 ms with blends and plain stores (docs/perf.md,
/// 2026-11-29). `tools/no_masked_stores.sh`, run by CI, checks the built crate for them.
///
/// # Safety
/// `p` must be valid for reads and writes of eight floats; the CPU must support AVX.
#[inline]
#[target_feature(enable = "avx")]
unsafe fn store_blend_at(p: *mut f32, old: __m256, new: __m256, mask: __m256) {
    let mut old = old;
    // SAFETY: an empty block: it reads and writes no memory, and leaves the register and the
    // flags as they are.
    unsafe {
        std::arch::asm!("/* {old} */", old = inout(ymm_reg) old, options(pure, nomem, nostack, preserves_flags));
    }
    // SAFETY: the caller's contract (eight floats at `p`).
    unsafe { _mm256_storeu_ps(p, _mm256_blendv_ps(old, new, mask)) }
}

/// The eight lanes of `v`.
#[inline(always)]
pub(super) unsafe fn store(v: __m256) -> [f32; LANES] {
    let mut out = [0.0f32; LANES];
    // SAFETY: `out` holds eight floats; AVX is enabled by every caller.
    unsafe { _mm256_storeu_ps(out.as_mut_ptr(), v) };
    out
}

/// A lane mask (all bits set or 0) of eight `bool`s.
#[inline(always)]
unsafe fn bool_mask(b: &[bool; LANES]) -> __m256i {
    // SAFETY: a `bool` is one byte, 0 or 1; eight of them are read as one u64.
    unsafe {
        let bytes = _mm_loadl_epi64(b.as_ptr().cast());
        _mm256_cmpgt_epi32(_mm256_cvtepu8_epi32(bytes), _mm256_setzero_si256())
    }
}

/// The texels of tap `k` of the eight lanes as four vectors (r, g, b, alpha): each lane's
/// 16-byte texel loaded and the eight transposed. The caller has checked that `texture` holds
/// `ts²` texels (every index of `taps` is below `ts²`).
#[inline(always)]
pub(super) unsafe fn tap_channels(index: &[u32; LANES], texture: &[[f32; 4]]) -> [__m256; 4] {
    let base = texture.as_ptr().cast::<f32>();
    // SAFETY: every index is below `texture.len()` (the caller's contract), so each 16-byte load
    // reads one texel of `texture`; the rest are register operations.
    unsafe {
        let texel = |l: usize| _mm_loadu_ps(base.add(4 * index[l] as usize));
        // Lanes 0-3 in the low halves, 4-7 in the high halves.
        let a = _mm256_set_m128(texel(4), texel(0));
        let b = _mm256_set_m128(texel(5), texel(1));
        let c = _mm256_set_m128(texel(6), texel(2));
        let d = _mm256_set_m128(texel(7), texel(3));
        transpose_four(a, b, c, d)
    }
}

/// Four vectors holding `[x₀ y₀ z₀ w₀ | x₄ y₄ z₄ w₄]`, `[x₁ … | x₅ …]`, `[x₂ … | x₆ …]`,
/// `[x₃ … | x₇ …]` (two 4-vectors each) as the eight lanes of x, y, z and w.
#[inline(always)]
pub(super) unsafe fn transpose_four(a: __m256, b: __m256, c: __m256, d: __m256) -> [__m256; 4] {
    // SAFETY: register operations of AVX, enabled by every caller.
    unsafe {
        let ab_lo = _mm256_unpacklo_ps(a, b); // x0 x1 y0 y1
        let ab_hi = _mm256_unpackhi_ps(a, b); // z0 z1 w0 w1
        let cd_lo = _mm256_unpacklo_ps(c, d); // x2 x3 y2 y3
        let cd_hi = _mm256_unpackhi_ps(c, d); // z2 z3 w2 w3
        let pd = _mm256_castps_pd;
        [
            _mm256_castpd_ps(_mm256_unpacklo_pd(pd(ab_lo), pd(cd_lo))),
            _mm256_castpd_ps(_mm256_unpackhi_pd(pd(ab_lo), pd(cd_lo))),
            _mm256_castpd_ps(_mm256_unpacklo_pd(pd(ab_hi), pd(cd_hi))),
            _mm256_castpd_ps(_mm256_unpackhi_pd(pd(ab_hi), pd(cd_hi))),
        ]
    }
}

/// The RGBA samples of the eight lanes, as four vectors (r, g, b, alpha), and the texels of
/// each tap (`[tap][channel]`): see the module docs. Every lane's four texels are read (their
/// indices are clamped into the texture).
#[inline(always)]
pub(super) unsafe fn sample_lanes_with_texels(taps: &RowTaps, texture: &[[f32; 4]]) -> ([__m256; 4], [[__m256; 4]; 4]) {
    let ts = taps.texture_side();
    assert_eq!(texture.len(), ts * ts, "texels must hold ts × ts RGBA values");
    let (index, weight, keep, _) = taps.lane_arrays();
    // SAFETY: the size was checked above; the rest are register operations of AVX.
    unsafe {
        let mut acc = [_mm256_setzero_ps(); 4];
        let mut texels = [[_mm256_setzero_ps(); 4]; 4];
        for k in 0..4 {
            let channels = tap_channels(&index[k], texture);
            let w = _mm256_loadu_ps(weight[k].as_ptr());
            let m = _mm256_castsi256_ps(_mm256_loadu_si256(keep[k].as_ptr().cast()));
            for (sum, t) in acc.iter_mut().zip(channels) {
                *sum = _mm256_add_ps(*sum, _mm256_and_ps(_mm256_mul_ps(w, t), m));
            }
            texels[k] = channels;
        }
        (acc, texels)
    }
}

/// [`sample_lanes_with_texels`] without the texels.
#[inline(always)]
unsafe fn sample_lanes(taps: &RowTaps, texture: &[[f32; 4]]) -> [__m256; 4] {
    // SAFETY: as for `sample_lanes_with_texels` (the caller enabled AVX2).
    unsafe { sample_lanes_with_texels(taps, texture).0 }
}

/// The compositing thresholds broadcast to every lane.
pub(super) struct Thresholds {
    max_alpha: __m256,
    min_alpha: __m256,
    min_transmittance: __m256,
}

impl Thresholds {
    #[inline(always)]
    pub(super) fn of(params: &CompositeParams) -> Self {
        // SAFETY: broadcasts need AVX, which every caller has enabled.
        unsafe {
            Self {
                max_alpha: _mm256_set1_ps(params.max_alpha),
                min_alpha: _mm256_set1_ps(params.min_alpha),
                min_transmittance: _mm256_set1_ps(params.min_transmittance),
            }
        }
    }
}

/// [`crate::stages::composite::classify`] of eight lanes (transmittance in front, raw alpha):
/// the lane is skipped where `kept` is 0, stops where `stop` is set, and is blended (with
/// `alpha`, `weight` and `next`) elsewhere.
pub(super) struct LaneDecision {
    /// Alpha after the clamp.
    pub(super) alpha: __m256,
    /// `T·(1 − α)`.
    pub(super) next: __m256,
    /// `α·T`.
    pub(super) weight: __m256,
    /// Lane mask: `α ≥ min_alpha` (false for NaN): not skipped.
    pub(super) kept: __m256,
    /// Lane mask: not skipped, and `T·(1 − α) < min_transmittance`.
    pub(super) stop: __m256,
    /// Lane mask: the raw alpha was above `max_alpha` (the clamp was active).
    pub(super) clamped: __m256,
}

#[inline(always)]
pub(super) unsafe fn decide(transmittance: __m256, a: __m256, th: &Thresholds) -> LaneDecision {
    // SAFETY: register operations of AVX, enabled by every caller.
    unsafe {
        let clamped = _mm256_cmp_ps::<_CMP_GT_OQ>(a, th.max_alpha);
        let alpha = _mm256_blendv_ps(a, th.max_alpha, clamped);
        let kept = _mm256_cmp_ps::<_CMP_GE_OQ>(alpha, th.min_alpha);
        let next = _mm256_mul_ps(transmittance, _mm256_sub_ps(_mm256_set1_ps(1.0), alpha));
        let stop = _mm256_and_ps(kept, _mm256_cmp_ps::<_CMP_LT_OQ>(next, th.min_transmittance));
        LaneDecision {
            alpha,
            next,
            weight: _mm256_mul_ps(alpha, transmittance),
            kept,
            stop,
            clamped,
        }
    }
}

/// For the tests (`testing_internals`): [`decide`] of eight lanes as the scalar [`Step`]s it
/// stands for, or `None` without AVX2.
#[cfg(feature = "testing")]
pub(crate) fn classify_lanes(
    transmittance: &[f32; LANES],
    a: &[f32; LANES],
    params: &CompositeParams,
) -> Option<[Step; LANES]> {
    if !super::lanes::wide_lanes() {
        return None;
    }
    // SAFETY: the CPU has AVX2 and FMA (checked just above).
    Some(unsafe { classify_lanes_avx2(transmittance, a, params) })
}

#[cfg(feature = "testing")]
#[target_feature(enable = "avx2,fma")]
unsafe fn classify_lanes_avx2(
    transmittance: &[f32; LANES],
    a: &[f32; LANES],
    params: &CompositeParams,
) -> [Step; LANES] {
    // SAFETY: AVX2 is enabled.
    let lanes = |v: __m256| unsafe { store(v) };
    // SAFETY: the arrays hold LANES floats; AVX2 is enabled.
    let d = unsafe {
        decide(
            _mm256_loadu_ps(transmittance.as_ptr()),
            _mm256_loadu_ps(a.as_ptr()),
            &Thresholds::of(params),
        )
    };
    let mask = |v: __m256| _mm256_movemask_ps(v) as u32;
    let (alpha, next, weight, kept, stop) = (
        lanes(d.alpha),
        lanes(d.next),
        lanes(d.weight),
        mask(d.kept),
        mask(d.stop),
    );
    let clamped = mask(d.clamped);
    std::array::from_fn(|l| {
        if stop >> l & 1 == 1 {
            Step::Stop
        } else if kept >> l & 1 == 0 {
            Step::Skip
        } else {
            Step::Blend(Blend {
                alpha: alpha[l],
                transmittance: transmittance[l],
                weight: weight[l],
                next_transmittance: next[l],
                clamped: clamped >> l & 1 == 1,
            })
        }
    })
}

/// For the tests (`testing_internals`): [`sample_lanes`] of every lane as `[r, g, b, alpha]`, or `None` without AVX2.
#[cfg(feature = "testing")]
pub(crate) fn sample_rgba_lanes(taps: &RowTaps, texture: &[[f32; 4]]) -> Option<[[f32; 4]; LANES]> {
    if !super::lanes::wide_lanes() {
        return None;
    }
    // SAFETY: the CPU has AVX2 and FMA (checked just above).
    Some(unsafe { sample_rgba_lanes_avx2(taps, texture) })
}

#[cfg(feature = "testing")]
#[target_feature(enable = "avx2,fma")]
unsafe fn sample_rgba_lanes_avx2(taps: &RowTaps, texture: &[[f32; 4]]) -> [[f32; 4]; LANES] {
    // SAFETY: AVX2 is enabled; `sample_lanes` checks the texture's size.
    let channels = unsafe { sample_lanes(taps, texture) };
    // SAFETY: AVX2 is enabled.
    let out = channels.map(|c| unsafe { store(c) });
    std::array::from_fn(|l| std::array::from_fn(|c| out[c][l]))
}

/// Per 8-bit lane mask: the indices of its set lanes, lowest first, then zeros (the
/// permutation that moves a run's blended lanes to the front, in order).
static LEFT_PACK: [[u32; LANES]; 256] = left_pack_table();

const fn left_pack_table() -> [[u32; LANES]; 256] {
    let mut table = [[0u32; LANES]; 256];
    let mut mask = 0;
    while mask < 256 {
        let (mut n, mut lane) = (0, 0);
        while lane < LANES {
            if mask >> lane & 1 == 1 {
                table[mask][n] = lane as u32;
                n += 1;
            }
            lane += 1;
        }
        mask += 1;
    }
    table
}

// A run's pixels and columns fit their fields with room for the run's lanes, so the packed
// lanes of `push_pairs` never carry into the next field.
const _: () = assert!((TILE_SIZE * TILE_SIZE) as usize + LANES <= 1 << 16 && TILE_SIZE as usize + LANES <= 1 << 8);

/// Appends to `pairs` the [`EntryPair`] of every lane set in `bits` (below `1 << LANES`), in
/// lane order, without a branch on `bits`: the run's first lane is tile-local pixel `q0`, column
/// `x0` and row `y`, and `fronts` holds each lane's transmittance in front. The eight lanes'
/// pairs are made in two vectors (pixel, column and row packed into one `u32` per lane, beside
/// the transmittance's bits), the set lanes moved to the front in order ([`LEFT_PACK`]), and all
/// eight stored; the length then grows by the number of set lanes. The same pairs as pushing
/// them one by one (`tests/suite/raster_lanes.rs`: for every lane mask on its own, and every
/// pair of whole renders against the scalar build's).
///
/// # Safety
/// The CPU must support AVX2 (the caller is compiled with it).
#[inline(always)]
unsafe fn push_pairs(pairs: &mut Vec<EntryPair>, bits: u32, (q0, x0, y): (usize, usize, u8), fronts: __m256) {
    debug_assert!(bits < 1 << LANES && q0 < (TILE_SIZE * TILE_SIZE) as usize && x0 < TILE_SIZE as usize);
    pairs.reserve(LANES);
    let len = pairs.len();
    // SAFETY: register operations of AVX2, enabled by the caller. `reserve` left room for
    // LANES pairs after `len`, which the two 32-byte stores fill: `EntryPair` is `repr(C)`, 8
    // bytes (checked at compile time), with the pixel in bytes 0-1, the column in byte 2, the
    // row in byte 3 and the transmittance in bytes 4-7, as the little-endian lanes below hold
    // them. The first `count_ones` stored pairs are the set lanes' pairs, so the new length
    // covers initialised pairs only.
    unsafe {
        // Lane `l`: pixel `q0 + l` and column `x0 + l` (no carry: see the assertion above),
        // row `y`.
        let step = _mm256_setr_epi32(0, 0x1_0001, 0x2_0002, 0x3_0003, 0x4_0004, 0x5_0005, 0x6_0006, 0x7_0007);
        let first = (q0 as u32 | (x0 as u32) << 16 | u32::from(y) << 24) as i32;
        let place = _mm256_add_epi32(_mm256_set1_epi32(first), step);
        let order = _mm256_loadu_si256(LEFT_PACK[bits as usize & 0xff].as_ptr().cast());
        let place = _mm256_permutevar8x32_epi32(place, order);
        let front = _mm256_permutevar8x32_epi32(_mm256_castps_si256(fronts), order);
        // Pairs 0, 1 | 4, 5 and 2, 3 | 6, 7 of the packed lanes, then pairs 0-3 and 4-7.
        let low = _mm256_unpacklo_epi32(place, front);
        let high = _mm256_unpackhi_epi32(place, front);
        let out = pairs.as_mut_ptr().add(len).cast::<__m256i>();
        _mm256_storeu_si256(out, _mm256_permute2x128_si256::<0x20>(low, high));
        _mm256_storeu_si256(out.add(1), _mm256_permute2x128_si256::<0x31>(low, high));
        pairs.set_len(len + (bits & 0xff).count_ones() as usize);
    }
}

/// For the tests (`testing_internals`): [`push_pairs`] onto `pairs`, each pair returned as
/// (pixel, column, row, transmittance bits), or `None` without AVX2.
#[cfg(feature = "testing")]
pub(crate) fn push_pairs_lanes(
    pairs: &[(u16, u8, u8, u32)],
    bits: u32,
    first: (usize, usize, u8),
    fronts: &[f32; LANES],
) -> Option<Vec<(u16, u8, u8, u32)>> {
    if !super::lanes::wide_lanes() {
        return None;
    }
    let mut out: Vec<EntryPair> = pairs
        .iter()
        .map(|&(pixel, x, y, t)| EntryPair {
            pixel,
            x,
            y,
            transmittance: f32::from_bits(t),
        })
        .collect();
    // Exactly as much room as the pairs need, so that the push must grow the list.
    out.shrink_to_fit();
    // SAFETY: the CPU has AVX2 (checked just above); the array holds LANES floats.
    unsafe { push_pairs_avx2(&mut out, bits, first, fronts) };
    Some(
        out.iter()
            .map(|p| (p.pixel, p.x, p.y, p.transmittance.to_bits()))
            .collect(),
    )
}

#[cfg(feature = "testing")]
#[target_feature(enable = "avx2,fma")]
unsafe fn push_pairs_avx2(pairs: &mut Vec<EntryPair>, bits: u32, first: (usize, usize, u8), fronts: &[f32; LANES]) {
    // SAFETY: AVX2 is enabled; the array holds LANES floats.
    unsafe { push_pairs(pairs, bits, first, _mm256_loadu_ps(fronts.as_ptr())) }
}

/// [`super::tile_forward::composite_tile`] in explicit AVX2 (same outputs, bit for bit).
///
/// # Safety
/// The CPU must support AVX2 and FMA.
#[target_feature(enable = "avx2,fma")]
pub(crate) unsafe fn composite_tile_avx2<const DISTORTION: bool>(
    states: &mut LaneStates,
    inputs: TileInputs<'_, '_>,
    impact: &mut [f32],
    pixels: &mut Vec<PixelOut>,
    out: &mut TileBlended,
) {
    // SAFETY: the caller's contract (AVX2 and FMA).
    unsafe { composite_tile_lanes::<DISTORTION>(states, inputs, impact, pixels, out) }
}

/// [`composite_tile_avx2`] compiled with AVX-512 (F, VL, BW, DQ) enabled as well: the same
/// source and the same bits. The compiler then uses the upper 16 vector registers and mask
/// registers, and the function has 6 % fewer instructions; on a Zen 4 host the forward took
/// 0.94 of the AVX2 build's time (docs/perf.md, 2026-11-29). [`super::lanes::avx512_lanes`]
/// chooses it.
///
/// # Safety
/// The CPU must support AVX2, FMA and AVX-512 F, VL, BW and DQ.
#[target_feature(enable = "avx2,fma,avx512f,avx512vl,avx512bw,avx512dq")]
pub(crate) unsafe fn composite_tile_avx512<const DISTORTION: bool>(
    states: &mut LaneStates,
    inputs: TileInputs<'_, '_>,
    impact: &mut [f32],
    pixels: &mut Vec<PixelOut>,
    out: &mut TileBlended,
) {
    // SAFETY: the caller's contract (AVX-512 comes with what the body needs: AVX2 and FMA).
    unsafe { composite_tile_lanes::<DISTORTION>(states, inputs, impact, pixels, out) }
}

/// The body of [`composite_tile_avx2`] and [`composite_tile_avx512`], inlined into each.
///
/// # Safety
/// The CPU must support AVX2 and FMA, and the caller must be compiled with them.
#[inline(always)]
unsafe fn composite_tile_lanes<const DISTORTION: bool>(
    states: &mut LaneStates,
    (camera, set, settings, prepared, list, (i0, j0, i1, j1), spans): TileInputs<'_, '_>,
    impact: &mut [f32],
    pixels: &mut Vec<PixelOut>,
    out: &mut TileBlended,
) {
    let params = &settings.composite;
    let ts = set.texture_size;
    let tw = (i1 - i0) as usize;
    let n = tw * (j1 - j0) as usize;
    states.reset(n, DISTORTION);
    out.start(PairOrder::ByEntry);
    let TileBlended {
        entry_pairs: blended,
        offsets,
        ..
    } = out;
    // Register operations of AVX, which every caller has enabled (this function's contract),
    // here and in the broadcasts below.
    // SAFETY: as just said.
    let (iota, one, half, median_alpha) = unsafe {
        (
            _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7),
            _mm256_set1_ps(1.0),
            _mm256_set1_ps(0.5),
            _mm256_set1_ps(0.05),
        )
    };
    let thresholds = Thresholds::of(params);
    let mut taps = RowTaps::default();
    for (k, (span, &b)) in spans.entries.iter().zip(list).enumerate() {
        offsets.push(blended.len() as u32);
        prefetch_ahead(set, prepared, list, &spans.entries, k, (i0, j0));
        let p = prepared[b as usize].as_ref().expect("binned billboards are prepared");
        let plane = p.view_plane();
        let texture = set.texture_of(b as usize);
        // SAFETY: as for the broadcasts above.
        let (colour, normal) = unsafe {
            (
                [
                    _mm256_set1_ps(p.rgb.x),
                    _mm256_set1_ps(p.rgb.y),
                    _mm256_set1_ps(p.rgb.z),
                ],
                [
                    _mm256_set1_ps(p.normal.x),
                    _mm256_set1_ps(p.normal.y),
                    _mm256_set1_ps(p.normal.z),
                ],
            )
        };
        let mut entry_impact = impact[k];
        for (y, &[x0, x1]) in (span.rows[0]..).zip(spans.row_cols(span)) {
            let (x0, x1) = (usize::from(x0), usize::from(x1));
            let py = (j0 + u32::from(y)) as f32 + 0.5;
            let row = y as usize * tw;
            let mut x = x0;
            while x <= x1 {
                let count = LANES.min(x1 + 1 - x);
                let q0 = row + x;
                let first = i0 + x as u32;
                x += count;
                let mut lanes = states.chunk(q0);
                // SAFETY: AVX2 and FMA are enabled for this function (its caller checked the
                // CPU); the loads and stores go through the chunk's states, whose bounds were
                // checked when it was made, and `sample_lanes` reads texels at indices `RowTaps`
                // clamps into the texture.
                unsafe {
                    let in_run = _mm256_cmpgt_epi32(_mm256_set1_epi32(count as i32), iota);
                    let done = lanes.load_si::<DONE>();
                    let active = _mm256_andnot_si256(done, in_run);
                    if _mm256_testz_si256(active, active) != 0 {
                        continue;
                    }
                    // `evaluated += 1` on the active lanes (a mask is −1).
                    let evaluated = _mm256_sub_epi32(lanes.load_si::<EVALUATED>(), active);
                    lanes.store_si::<EVALUATED>(evaluated);
                    let px = row_centres(first);
                    let hits = intersect_lanes(&p.transform, &plane, camera, &px, &[py; LANES]);
                    taps.refill::<false>(&hits.u, &hits.v, ts);
                    let [r, g, bl, a] = sample_lanes(&taps, texture);
                    let stepping = _mm256_castsi256_ps(_mm256_and_si256(
                        active,
                        _mm256_and_si256(bool_mask(&hits.valid), bool_mask(taps.lane_arrays().3)),
                    ));
                    let transmittance = lanes.load_ps::<TRANSMITTANCE>();
                    let LaneDecision {
                        alpha,
                        next,
                        weight,
                        kept,
                        stop,
                        ..
                    } = decide(transmittance, a, &thresholds);
                    let blend = _mm256_and_ps(stepping, _mm256_andnot_ps(stop, kept));
                    let skipped_nan =
                        _mm256_andnot_ps(kept, _mm256_and_ps(stepping, _mm256_cmp_ps::<_CMP_UNORD_Q>(a, a)));
                    let nan_alpha = _mm256_sub_epi32(lanes.load_si::<NAN_ALPHA>(), _mm256_castps_si256(skipped_nan));
                    lanes.store_si::<NAN_ALPHA>(nan_alpha);
                    lanes.store_si::<DONE>(_mm256_or_si256(
                        done,
                        _mm256_castps_si256(_mm256_and_ps(stepping, stop)),
                    ));
                    // No branch on the blend from here on. Which lanes blend depends on the
                    // texels just read, so a branch on it resolves late; skipping the blend's
                    // work in the quarter of the runs where no lane blends cost more in
                    // mispredictions than the work (the forward is 6 % faster without it,
                    // docs/perf.md). A lane that does not blend keeps its values (the blends
                    // below choose the old ones), adds no pair and adds +0 to the impact.
                    let blend_bits = _mm256_movemask_ps(blend) as u32;
                    let depth = _mm256_loadu_ps(hits.depth.as_ptr());
                    let features = [
                        _mm256_add_ps(r, colour[0]),
                        _mm256_add_ps(g, colour[1]),
                        _mm256_add_ps(bl, colour[2]),
                        one,
                        depth,
                        normal[0],
                        normal[1],
                        normal[2],
                    ];
                    for (c, f) in features.into_iter().enumerate() {
                        let old = lanes.load_feature(c);
                        let new = _mm256_add_ps(old, _mm256_mul_ps(f, weight));
                        lanes.store_feature_blend(c, old, new, blend);
                    }
                    lanes.store_blend::<TRANSMITTANCE>(transmittance, next, blend);
                    let rule = _mm256_and_ps(
                        blend,
                        _mm256_and_ps(
                            _mm256_cmp_ps::<_CMP_GT_OQ>(transmittance, half),
                            _mm256_cmp_ps::<_CMP_GT_OQ>(alpha, median_alpha),
                        ),
                    );
                    let median = lanes.load_ps::<MEDIAN>();
                    lanes.store_blend::<MEDIAN>(median, depth, rule);
                    // The blended lanes' pairs, in pixel order.
                    push_pairs(blended, blend_bits, (q0, q0 - row, y), transmittance);
                    if DISTORTION {
                        let (weights, fronts) = (store(weight), store(transmittance));
                        let mut bits = blend_bits;
                        while bits != 0 {
                            let l = bits.trailing_zeros() as usize;
                            bits &= bits - 1;
                            states.spread[q0 + l].add(mapped_depth(hits.depth[l]), weights[l], fronts[l]);
                        }
                    }
                    // The impact in pixel order, every lane adding its weight or +0 (which
                    // changes no bit: `x + 0 = x` unless `x` is −0, and a sum that starts at +0
                    // is never −0).
                    for w in store(_mm256_and_ps(weight, blend)) {
                        entry_impact += w;
                    }
                }
            }
        }
        impact[k] = entry_impact;
    }
    offsets.push(blended.len() as u32);
    let bg = settings.background;
    pixels.clear();
    for q in 0..n {
        let state = CompositeState::<FORWARD_FEATURES> {
            transmittance: states.float(TRANSMITTANCE, q),
            features: std::array::from_fn(|c| states.float(FEATURES + c, q)),
            done: states.word(DONE, q) != 0,
        };
        let distortion = if DISTORTION { states.spread[q].distortion } else { 0.0 };
        pixels.push(PixelOut::of(
            &state,
            bg,
            states.float(MEDIAN, q),
            (states.word(EVALUATED, q), states.word(NAN_ALPHA, q)),
            distortion,
        ));
    }
}
