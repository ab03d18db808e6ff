//! The forward pass of one tile billboard by billboard ([`super::tile_forward`]), written in
//! explicit AVX2 instructions: the eight pixels of a run are sampled, classified and composited
//! side by side in vector registers, their states kept as one array per value (structure of
//! arrays), instead of one pixel after another. A run is eight pixels of a row's span, or the
//! rest of a row's span together with the first pixels of the next row's ([`EntryRuns`]: its
//! two parts read and write two windows of the state arrays), so that the short rows of small
//! billboards and the tails of wider ones do not leave most lanes idle.
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

use super::binning::TILE_SIZE;
use super::texel_prefetch::TexelPrefetch;
use super::tile_types::{EntryPair, FORWARD_FEATURES, PairOrder, PixelOut, TileBlended, TileInputs};
use crate::camera::Camera;
use crate::stages::bilinear::RowTaps;
#[cfg(feature = "testing")]
use crate::stages::composite::{Blend, Step};
use crate::stages::composite::{CompositeParams, CompositeState};
use crate::stages::depth_distortion::{DistortionState, mapped_depth};
use crate::stages::ray_plane::{LANES, ViewPlane, intersect_lanes, row_centres};
use crate::stages::splat_transform::SplatTransform;
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

    /// The states of a run's two windows of [`LANES`] pixels, from `qa` and from `qb`: either
    /// the same window (`qa == qb`) or two that share no pixel (`qb ≥ qa + LANES`), both
    /// starting at a pixel of the tile; every row's bounds checked at once.
    #[inline(always)]
    fn chunk_pair(&mut self, qa: usize, qb: usize) -> (ChunkStates<'_>, ChunkStates<'_>) {
        assert!(
            qa == qb || qb >= qa + LANES,
            "a run's two windows are one window or share no pixel"
        );
        let stride = self.stride;
        assert!(
            qb + LANES <= stride && self.floats.len() == FLOAT_ROWS * stride && self.words.len() == WORD_ROWS * stride,
            "a chunk starts at a pixel of the tile"
        );
        let (floats, words) = (self.floats.as_mut_ptr(), self.words.as_mut_ptr());
        let at = |q: usize| ChunkStates {
            floats: floats.wrapping_add(q),
            words: words.wrapping_add(q),
            stride,
            _states: std::marker::PhantomData,
        };
        (at(qa), at(qb))
    }
}

/// The [`LANES`] elements from one pixel of every row of a [`LaneStates`]; rows are chosen by
/// constant index, checked at compile time, and the chunk's bounds were checked when it was
/// made ([`LaneStates::chunk_pair`]).
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
    /// `LaneStates::chunk_pair` made, the start of [`LANES`] floats inside the rows. Every access of
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
        // SAFETY: `LaneStates::chunk_pair` checked `q0 + LANES <= stride` and the length of the
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

/// The states of a run's lanes ([`RunPixels`]): lanes `0..split` in window `first`, the
/// others in window `second` (`TWO`), or every lane in `first` (not `TWO`). A load takes each
/// lane from its window; a store writes both windows, each lane of a window that is not its
/// run lane getting back the value it held (read again just before: the windows share no
/// pixel), so the other pixels' states keep their bits.
struct RunStates<'a, const TWO: bool> {
    first: ChunkStates<'a>,
    second: ChunkStates<'a>,
    /// The lanes of `second` (lanes `split..`), all bits set; with `TWO` only.
    in_second: __m256,
}

impl<const TWO: bool> RunStates<'_, TWO> {
    /// `read` of the run's lanes: of `first`, and with `TWO` of `second` for lanes `split..`.
    #[inline(always)]
    unsafe fn read(&self, read: impl Fn(&ChunkStates<'_>) -> __m256) -> __m256 {
        let a = read(&self.first);
        if TWO {
            // SAFETY: a register operation of AVX, enabled by every caller.
            unsafe { _mm256_blendv_ps(a, read(&self.second), self.in_second) }
        } else {
            a
        }
    }

    /// `write(window, mask)` of the run's lanes set in `mask`: once for `first` and, with `TWO`,
    /// once per window with that window's lanes of `mask`. A write keeps the window's lanes
    /// outside its mask as it reads them (the two windows share no pixel, so a window read
    /// after the other was written still holds its own values).
    #[inline(always)]
    unsafe fn write(&mut self, mask: __m256, mut write: impl FnMut(&mut ChunkStates<'_>, __m256)) {
        if TWO {
            // SAFETY: register operations of AVX, enabled by every caller.
            let (in_first, in_second) = unsafe {
                (
                    _mm256_andnot_ps(self.in_second, mask),
                    _mm256_and_ps(self.in_second, mask),
                )
            };
            write(&mut self.first, in_first);
            write(&mut self.second, in_second);
        } else {
            write(&mut self.first, mask);
        }
    }

    #[inline(always)]
    unsafe fn load_ps<const ROW: usize>(&self) -> __m256 {
        // SAFETY: the chunks' contract (`ChunkStates::load_ps`); AVX is enabled by every caller.
        unsafe { self.read(|w| w.load_ps::<ROW>()) }
    }

    /// Float row `ROW` set to `new` where `mask` is set and left as it was elsewhere; `old`
    /// is what [`Self::load_ps`] read (read again per window with `TWO`).
    #[inline(always)]
    unsafe fn store_blend<const ROW: usize>(&mut self, old: __m256, new: __m256, mask: __m256) {
        // SAFETY: the chunks' contract (`ChunkStates::store_blend`); AVX is enabled by every
        // caller.
        unsafe {
            self.write(mask, |w, m| {
                let old = if TWO { w.load_ps::<ROW>() } else { old };
                w.store_blend::<ROW>(old, new, m);
            });
        }
    }

    #[inline(always)]
    unsafe fn load_feature(&self, c: usize) -> __m256 {
        // SAFETY: as in `load_ps`.
        unsafe { self.read(|w| w.load_feature(c)) }
    }

    /// [`Self::store_blend`] for feature `c`.
    #[inline(always)]
    unsafe fn store_feature_blend(&mut self, c: usize, old: __m256, new: __m256, mask: __m256) {
        // SAFETY: as in `store_blend`.
        unsafe {
            self.write(mask, |w, m| {
                let old = if TWO { w.load_feature(c) } else { old };
                w.store_feature_blend(c, old, new, m);
            });
        }
    }

    /// Word row `ROW` (the blend of two windows chooses lanes by their bits only).
    #[inline(always)]
    unsafe fn load_si<const ROW: usize>(&self) -> __m256i {
        // SAFETY: as in `load_ps`.
        unsafe { _mm256_castps_si256(self.read(|w| _mm256_castsi256_ps(w.load_si::<ROW>()))) }
    }

    /// Word row `ROW` set to `x` in the run's lanes.
    #[inline(always)]
    unsafe fn store_si<const ROW: usize>(&mut self, x: __m256i) {
        if !TWO {
            // SAFETY: as in `store_blend`.
            unsafe { self.first.store_si::<ROW>(x) };
            return;
        }
        // SAFETY: as in `store_blend`; the word row is written through its float view, bits
        // unchanged (`store_blend_at` only selects lanes).
        unsafe {
            let all = _mm256_castsi256_ps(_mm256_set1_epi32(-1));
            self.write(all, |w, m| {
                let old = _mm256_castsi256_ps(w.load_si::<ROW>());
                store_blend_at(w.word_row(ROW).cast(), old, _mm256_castsi256_ps(x), m);
            });
        }
    }
}

/// Writes `blendv(old, new, mask)` to the eight floats at `p` with one plain 32-byte store:
/// `new` in the lanes where `mask` is set, `old` (what the caller loaded from `p`) in the others.
///
/// `old` first passes through an empty assembly block, which leaves its bits as they are but
/// hides from the compiler that it was loaded from `p`. Otherwise the compiler turns "load,
/// blend with what was loaded, store back" into a masked store (`vmaskmovps`), which gives the
/// same bits but is slow on AMD Zen cores: on a Zen 4 host the object scene's forward took 34 ms
/// with the nine masked stores per run and 28 ms with blends and plain stores (docs/perf-log.md,
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
    if !crate::cpu::Simd::detect().avx2_fma() {
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
    if !crate::cpu::Simd::detect().avx2_fma() {
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
#[cfg(feature = "testing")]
#[inline(always)]
unsafe fn push_pairs(pairs: &mut Vec<EntryPair>, bits: u32, (q0, x0, y): (usize, usize, u8), fronts: __m256) {
    // SAFETY: AVX2 is enabled by the caller.
    unsafe { push_placed_pairs(pairs, bits, lane_places((q0, x0, y), 0), fronts) }
}

/// Each lane's pair place (pixel, column and row packed as [`EntryPair`]'s first word) for a
/// run of pixels from `(q0, x0, y)`, shifted by `shift` lanes: lane `l ≥ shift` holds pixel
/// `q0 + l − shift`, column `x0 + l − shift`, row `y` (lanes below `shift` are unspecified).
///
/// # Safety
/// The CPU must support AVX2 (the caller is compiled with it).
#[inline(always)]
unsafe fn lane_places((q0, x0, y): (usize, usize, u8), shift: usize) -> __m256i {
    debug_assert!(q0 < (TILE_SIZE * TILE_SIZE) as usize && x0 < TILE_SIZE as usize && shift < LANES);
    // SAFETY: register operations of AVX2, enabled by the caller.
    unsafe {
        // Lane `l`: `first + (l − shift)·(1 + 2¹⁶)`, in wrapping arithmetic; for `l ≥ shift` the
        // pixel and column take no carry (they stay inside the tile), so the fields are exact.
        let step = _mm256_setr_epi32(0, 0x1_0001, 0x2_0002, 0x3_0003, 0x4_0004, 0x5_0005, 0x6_0006, 0x7_0007);
        let first = (q0 as u32 | (x0 as u32) << 16 | u32::from(y) << 24).wrapping_sub(shift as u32 * 0x1_0001);
        _mm256_add_epi32(_mm256_set1_epi32(first as i32), step)
    }
}

/// [`push_pairs`] with the lanes' places given (see [`lane_places`]): the runs of the forward
/// push their pairs through this, with the places of their one or two parts.
///
/// # Safety
/// The CPU must support AVX2 (the caller is compiled with it).
#[inline(always)]
unsafe fn push_placed_pairs(pairs: &mut Vec<EntryPair>, bits: u32, place: __m256i, fronts: __m256) {
    debug_assert!(bits < 1 << LANES);
    pairs.reserve(LANES);
    let len = pairs.len();
    // SAFETY: register operations of AVX2, enabled by the caller. `reserve` left room for
    // LANES pairs after `len`, which the two 32-byte stores fill: `EntryPair` is `repr(C)`, 8
    // bytes (checked at compile time), with the pixel in bytes 0-1, the column in byte 2, the
    // row in byte 3 and the transmittance in bytes 4-7, as the little-endian lanes below hold
    // them. The first `count_ones` stored pairs are the set lanes' pairs, so the new length
    // covers initialised pairs only.
    unsafe {
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
    if !crate::cpu::Simd::detect().avx2_fma() {
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
/// 0.94 of the AVX2 build's time (docs/perf-log.md, 2026-11-29). [`crate::cpu::SimdLevel::Avx512`]
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

/// Where a run's lanes start: tile-local pixel `q`, its column `x` and row `y`.
#[derive(Clone, Copy, Debug)]
struct RunStart {
    q: usize,
    x: usize,
    y: u8,
}

/// The pixels of a run, in pixel order: lanes `0..split` from `first` on (along its row),
/// lanes `split..len` from `second` on (along its row; none when `split == len`).
#[derive(Clone, Copy, Debug)]
struct RunPixels {
    first: RunStart,
    second: RunStart,
    split: usize,
    len: usize,
}

impl RunPixels {
    /// `len` pixels from `first` along its row.
    fn one(first: RunStart, len: usize) -> Self {
        Self {
            first,
            second: first,
            split: len,
            len,
        }
    }

    /// Whether the run has a second part.
    fn has_two_parts(&self) -> bool {
        self.split < self.len
    }

    /// The first pixel of the second part's window of [`LANES`] (`split` pixels before the
    /// part), so that lane `l ≥ split` holds pixel `window + l`; `first.q` for one part.
    fn second_window(&self) -> usize {
        if self.has_two_parts() {
            self.second.q - self.split
        } else {
            self.first.q
        }
    }

    /// The tile-local pixel of lane `l` (below `len`).
    fn pixel(&self, l: usize) -> usize {
        debug_assert!(l < self.len);
        if l < self.split {
            self.first.q + l
        } else {
            self.second_window() + l
        }
    }
}

/// The runs of an entry's pixels, in pixel order: a row's span in runs of [`LANES`] pixels, and the rest of it (its tail, fewer than `LANES`)
/// in one run with the head of the next non-empty row, when the two runs' windows of states
/// share no pixel (else the tail is a run of its own). Rows of a billboard a few pixels wide
/// thus share runs, as do the tails of wider ones.
struct EntryRuns<'s> {
    /// The columns `[first, last]` of the rows after the current one.
    rows: std::slice::Iter<'s, [u8; 2]>,
    /// The current row, its next column and the end of its span.
    y: u8,
    x: usize,
    end: usize,
    /// The tile's width.
    tw: usize,
}

impl<'s> EntryRuns<'s> {
    /// The runs of the rows `first_row, first_row + 1, …` whose spans are `rows`, in a tile
    /// `tw` pixels wide.
    fn new(rows: &'s [[u8; 2]], first_row: u8, tw: usize) -> Self {
        Self {
            rows: rows.iter(),
            // One row before the first (wrapping: `next_row` adds 1 first).
            y: first_row.wrapping_sub(1),
            x: 0,
            end: 0,
            tw,
        }
    }

    /// Moves to the next row whose span holds a pixel; false when there is none.
    #[inline(always)]
    fn next_row(&mut self) -> bool {
        for &[x0, x1] in self.rows.by_ref() {
            self.y = self.y.wrapping_add(1);
            if x0 <= x1 {
                (self.x, self.end) = (usize::from(x0), usize::from(x1) + 1);
                return true;
            }
        }
        false
    }

    /// Where the current row's next pixel is.
    #[inline(always)]
    fn start(&self) -> RunStart {
        RunStart {
            q: usize::from(self.y) * self.tw + self.x,
            x: self.x,
            y: self.y,
        }
    }
}

impl Iterator for EntryRuns<'_> {
    type Item = RunPixels;

    #[inline(always)]
    fn next(&mut self) -> Option<Self::Item> {
        if self.x >= self.end && !self.next_row() {
            return None;
        }
        let first = self.start();
        let left = self.end - self.x;
        if left >= LANES {
            self.x += LANES;
            return Some(RunPixels::one(first, LANES));
        }
        self.x = self.end;
        if !self.next_row() {
            return Some(RunPixels::one(first, left));
        }
        let second = self.start();
        if second.q - first.q < left + LANES {
            return Some(RunPixels::one(first, left));
        }
        let len = LANES.min(left + self.end - self.x);
        self.x += len - left;
        Some(RunPixels {
            first,
            second,
            split: left,
            len,
        })
    }
}

/// For the tests (`testing_internals`): the runs of [`EntryRuns`], each as its lanes'
/// tile-local pixels in lane order and whether it has two parts.
#[cfg(feature = "testing")]
pub(crate) fn entry_runs(rows: &[[u8; 2]], first_row: u8, tw: usize) -> Vec<(Vec<usize>, bool)> {
    EntryRuns::new(rows, first_row, tw)
        .map(|run| ((0..run.len).map(|l| run.pixel(l)).collect(), run.has_two_parts()))
        .collect()
}

/// What the runs of one entry read and write ([`EntryRun::run`]).
struct EntryRun<'e> {
    states: &'e mut LaneStates,
    taps: &'e mut RowTaps,
    /// The tile's blended pairs.
    pairs: &'e mut Vec<EntryPair>,
    /// The entry's impact so far.
    impact: f32,
    transform: &'e SplatTransform,
    plane: ViewPlane,
    camera: &'e Camera,
    texture: &'e [[f32; 4]],
    ts: usize,
    /// The tile's first pixel.
    origin: (u32, u32),
    colour: [__m256; 3],
    normal: [__m256; 3],
    thresholds: &'e Thresholds,
}

impl EntryRun<'_> {
    /// Composites the entry over the pixels of `run` (see the module docs): with `TWO`, its
    /// two parts, each in its own window of states ([`RunStates`]); else `run.split == run.len`
    /// and one window.
    ///
    /// # Safety
    /// The CPU must support AVX2 and FMA (the caller is compiled with them).
    #[inline(always)]
    unsafe fn run<const TWO: bool, const DISTORTION: bool>(&mut self, run: RunPixels) {
        let RunPixels {
            first,
            second,
            split,
            len,
        } = run;
        debug_assert!(0 < split && split <= len && len <= LANES && TWO == run.has_two_parts());
        let (i0, j0) = self.origin;
        let (a, b) = self.states.chunk_pair(first.q, run.second_window());
        // SAFETY: AVX2 and FMA are enabled (the caller's contract); the loads and stores go
        // through the run's windows of states, whose bounds were checked when they were made,
        // and `sample_lanes` reads texels at indices `RowTaps` clamps into the texture.
        unsafe {
            let iota = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
            let in_second = _mm256_castsi256_ps(_mm256_cmpgt_epi32(iota, _mm256_set1_epi32(split as i32 - 1)));
            let mut lanes = RunStates::<TWO> {
                first: a,
                second: b,
                in_second,
            };
            let in_run = _mm256_cmpgt_epi32(_mm256_set1_epi32(len as i32), iota);
            let done = lanes.load_si::<DONE>();
            let active = _mm256_andnot_si256(done, in_run);
            if _mm256_testz_si256(active, active) != 0 {
                return;
            }
            // `evaluated += 1` on the active lanes (a mask is −1).
            let evaluated = _mm256_sub_epi32(lanes.load_si::<EVALUATED>(), active);
            lanes.store_si::<EVALUATED>(evaluated);
            // The pixel centres, as the scalar code makes them: `(i0 + x) as f32 + 0.5`. For
            // the second part `row_centres` starts `split` columns early (wrapping below 0),
            // which leaves its lanes from `split` on exact.
            let centre_row = |start: RunStart| (j0 + u32::from(start.y)) as f32 + 0.5;
            let px = row_centres(i0 + first.x as u32);
            let (px, py) = if TWO {
                let px_second = row_centres((i0 + second.x as u32).wrapping_sub(split as u32));
                (
                    store(_mm256_blendv_ps(
                        _mm256_loadu_ps(px.as_ptr()),
                        _mm256_loadu_ps(px_second.as_ptr()),
                        in_second,
                    )),
                    store(_mm256_blendv_ps(
                        _mm256_set1_ps(centre_row(first)),
                        _mm256_set1_ps(centre_row(second)),
                        in_second,
                    )),
                )
            } else {
                (px, [centre_row(first); LANES])
            };
            let hits = intersect_lanes(self.transform, &self.plane, self.camera, &px, &py);
            self.taps.refill::<false>(&hits.u, &hits.v, self.ts);
            let [r, g, bl, a] = sample_lanes(self.taps, self.texture);
            let stepping = _mm256_castsi256_ps(_mm256_and_si256(
                active,
                _mm256_and_si256(bool_mask(&hits.valid), bool_mask(self.taps.lane_arrays().3)),
            ));
            let transmittance = lanes.load_ps::<TRANSMITTANCE>();
            let LaneDecision {
                alpha,
                next,
                weight,
                kept,
                stop,
                ..
            } = decide(transmittance, a, self.thresholds);
            let blend = _mm256_and_ps(stepping, _mm256_andnot_ps(stop, kept));
            let skipped_nan = _mm256_andnot_ps(kept, _mm256_and_ps(stepping, _mm256_cmp_ps::<_CMP_UNORD_Q>(a, a)));
            let nan_alpha = _mm256_sub_epi32(lanes.load_si::<NAN_ALPHA>(), _mm256_castps_si256(skipped_nan));
            lanes.store_si::<NAN_ALPHA>(nan_alpha);
            lanes.store_si::<DONE>(_mm256_or_si256(
                done,
                _mm256_castps_si256(_mm256_and_ps(stepping, stop)),
            ));
            // No branch on the blend from here on. Which lanes blend depends on the texels
            // just read, so a branch on it resolves late; skipping the blend's work in the
            // quarter of the runs where no lane blends cost more in mispredictions than the
            // work (the forward is 6 % faster without it, docs/perf.md). A lane that does not
            // blend keeps its values (the blends below choose the old ones), adds no pair and
            // adds +0 to the impact.
            let blend_bits = _mm256_movemask_ps(blend) as u32;
            let depth = _mm256_loadu_ps(hits.depth.as_ptr());
            let one = _mm256_set1_ps(1.0);
            let features = [
                _mm256_add_ps(r, self.colour[0]),
                _mm256_add_ps(g, self.colour[1]),
                _mm256_add_ps(bl, self.colour[2]),
                one,
                depth,
                self.normal[0],
                self.normal[1],
                self.normal[2],
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
                    _mm256_cmp_ps::<_CMP_GT_OQ>(transmittance, _mm256_set1_ps(0.5)),
                    _mm256_cmp_ps::<_CMP_GT_OQ>(alpha, _mm256_set1_ps(0.05)),
                ),
            );
            let median = lanes.load_ps::<MEDIAN>();
            lanes.store_blend::<MEDIAN>(median, depth, rule);
            // The blended lanes' pairs, in pixel order.
            let places = lane_places((first.q, first.x, first.y), 0);
            let places = if TWO {
                _mm256_castps_si256(_mm256_blendv_ps(
                    _mm256_castsi256_ps(places),
                    _mm256_castsi256_ps(lane_places((second.q, second.x, second.y), split)),
                    in_second,
                ))
            } else {
                places
            };
            push_placed_pairs(self.pairs, blend_bits, places, transmittance);
            if DISTORTION {
                let (weights, fronts) = (store(weight), store(transmittance));
                let mut bits = blend_bits;
                while bits != 0 {
                    let l = bits.trailing_zeros() as usize;
                    bits &= bits - 1;
                    self.states.spread[run.pixel(l)].add(mapped_depth(hits.depth[l]), weights[l], fronts[l]);
                }
            }
            // The impact in pixel order, every lane adding its weight or +0 (which changes no
            // bit: `x + 0 = x` unless `x` is −0, and a sum that starts at +0 is never −0).
            for w in store(_mm256_and_ps(weight, blend)) {
                self.impact += w;
            }
        }
    }
}

/// The body of [`composite_tile_avx2`] and [`composite_tile_avx512`], inlined into each.
///
/// # Safety
/// The CPU must support AVX2 and FMA, and the caller must be compiled with them.
#[inline(always)]
unsafe fn composite_tile_lanes<const DISTORTION: bool>(
    states: &mut LaneStates,
    TileInputs {
        camera,
        set,
        settings,
        prepared,
        list,
        rect: (i0, j0, i1, j1),
        spans,
    }: TileInputs<'_, '_>,
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
    let thresholds = Thresholds::of(params);
    let mut taps = RowTaps::default();
    let mut texel_prefetch = TexelPrefetch::default();
    for (k, (span, &b)) in spans.entries.iter().zip(list).enumerate() {
        offsets.push(blended.len() as u32);
        texel_prefetch.ahead(set, prepared, list, &spans.entries, k, (i0, j0));
        let p = prepared[b as usize].as_ref().expect("binned billboards are prepared");
        // SAFETY: broadcasts, register operations of AVX, which every caller has enabled (this
        // function's contract).
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
        let mut entry = EntryRun {
            states: &mut *states,
            taps: &mut taps,
            pairs: &mut *blended,
            impact: impact[k],
            transform: &p.transform,
            plane: p.view_plane(),
            camera,
            texture: set.texture_of(b as usize),
            ts,
            origin: (i0, j0),
            colour,
            normal,
            thresholds: &thresholds,
        };
        for run in EntryRuns::new(spans.row_cols(span), span.rows[0], tw) {
            // SAFETY: AVX2 and FMA are enabled for this function (its caller checked the CPU).
            unsafe {
                if run.has_two_parts() {
                    entry.run::<true, DISTORTION>(run);
                } else {
                    entry.run::<false, DISTORTION>(run);
                }
            }
        }
        let entry_impact = entry.impact;
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
