//! The pixel columns of each row of a billboard's screen box where its projected support can be
//! hit, computed once per billboard and view and cut to each tile the billboard is listed in.
//!
//! The forward pass narrows every tile entry's pixels to the rows' spans of the billboard's
//! projected support quad ([`local_spans`](super::tile_spans::local_spans)). Computed per tile
//! entry, each image row of a billboard is found again in every tile column the billboard
//! crosses, and its quad is projected again in every tile (a trained scene's billboard is
//! listed in about five tiles). [`BillboardRows`] computes each row once, for the whole width of
//! the box, in image columns; a tile then only clamps the row to its own columns, which gives
//! the same columns as computing the row for the tile (shown below, and tested against the
//! per-entry computation on every tile of several scenes).
//!
//! Why the clamp is exact: [`pixel_range`]`(lo, hi, n)` is `(clamp(⌈lo − ½⌉, 0, n), clamp(⌊hi −
//! ½⌋ + 1, 0, n))`, evaluated with its arguments clamped first, and for whole numbers `n₁ ≤ n₂`
//! every branch of that evaluation gives `pixel_range(lo, hi, n₁) = (min(f₂, n₁), min(e₂, n₁))`
//! where `(f₂, e₂) = pixel_range(lo, hi, n₂)` (also for NaN bounds, which give 0). A tile's
//! columns end at `n₁ ≤ pixel_max + 1 = n₂` whenever the box overlaps the tile; a tile whose
//! rectangle the box misses (not binned there, kept exact anyway) takes the per-entry path.

use super::preprocess::Prepared;
use crate::cpu::Simd;
use crate::memory::resize_for_overwrite;
use crate::stages::splat_transform::{ROW_LANES, pixel_range, support_quad};
use rayon::prelude::*;

/// Boxes narrower than this many pixel columns are not culled row by row (nothing to gain).
pub const QUAD_MIN_COLUMNS: u32 = 4;

/// Billboards per parallel task of [`BillboardRows::build`].
const BUILD_BLOCK: usize = 256;

/// Per billboard of a view, the columns of each row of its pixel box that its support quad can
/// reach (see the module documentation). Rebuilt per view; its storage is reused.
#[derive(Clone, Debug, Default)]
pub(crate) struct BillboardRows {
    /// The rows of billboard `b` are `blocks[b / BUILD_BLOCK][ranges[b][0]..ranges[b][1]]`, one
    /// per image row of its box from `pixel_min[1]`; none when the billboard is culled or its
    /// box is narrower than [`QUAD_MIN_COLUMNS`] (its spans are its box).
    ranges: Vec<[u32; 2]>,
    /// Per block of [`BUILD_BLOCK`] billboards, the rows of its billboards one after another.
    /// Per row: image columns `first..end`, [`pixel_range`] of the row's quad span with
    /// `n = pixel_max[0] + 1`, the box's columns when the billboard has no quad, and `[0, 0]`
    /// when the row misses the quad. (One list per block lets each block's task write its rows
    /// without a first pass over the records to count them.)
    blocks: Vec<Vec<[u32; 2]>>,
}

/// Whether a billboard's spans are narrowed by its support quad: boxes at least
/// [`QUAD_MIN_COLUMNS`] wide.
#[inline]
pub(crate) fn is_wide(p: &Prepared) -> bool {
    p.pixel_max[0] - p.pixel_min[0] + 1 >= QUAD_MIN_COLUMNS
}

/// The rows [`BillboardRows`] holds for a billboard.
fn row_count(p: &Option<Prepared>) -> usize {
    match p {
        Some(p) if is_wide(p) => (p.pixel_max[1] - p.pixel_min[1] + 1) as usize,
        _ => 0,
    }
}

impl BillboardRows {
    /// Computes the rows of every prepared billboard (in parallel; each billboard's rows depend
    /// on its record only). `half_side` is the support's half side
    /// ([`support_half_side`](crate::stages::splat_transform::support_half_side)); `simd` the
    /// instruction set to compute them in (the same bits whatever it is).
    pub(crate) fn build(&mut self, prepared: &[Option<Prepared>], half_side: f32, simd: Simd) {
        // Every range is written below.
        resize_for_overwrite(&mut self.ranges, prepared.len(), [0, 0]);
        self.blocks.resize_with(prepared.len().div_ceil(BUILD_BLOCK), Vec::new);
        self.blocks
            .par_iter_mut()
            .zip(self.ranges.par_chunks_mut(BUILD_BLOCK))
            .zip(prepared.par_chunks(BUILD_BLOCK))
            .for_each(|((rows, ranges), block)| {
                rows.clear();
                for (p, range) in block.iter().zip(ranges) {
                    let (start, count) = (rows.len(), row_count(p));
                    if let Some(p) = p.as_ref().filter(|_| count > 0) {
                        // Every row is written by `fill_rows`.
                        rows.resize(start + count, [0, 0]);
                        fill_rows(p, half_side, simd, &mut rows[start..]);
                    }
                    *range = [start as u32, rows.len() as u32];
                }
            });
    }

    /// Hints the CPU to fetch billboard `b`'s rows (no effect on values): one prefetch per 64
    /// bytes from their first byte, so when the rows do not start on a cache line their last
    /// line may be left out. (Starting from the line boundary instead, so that every line is
    /// fetched, took 1.00-1.04 of the time on the 256²/50k bench in four interleaved rounds,
    /// 2026-11-28: one more prefetch per billboard.)
    #[inline]
    pub(crate) fn prefetch(&self, b: usize) {
        super::prefetch::prefetch_steps(self.of(b));
    }

    /// Hints the CPU to fetch where billboard `b`'s rows are (no effect on values), so that
    /// [`BillboardRows::prefetch`] of it later finds them without a wait.
    #[inline]
    pub(crate) fn prefetch_range(&self, b: usize) {
        super::prefetch::prefetch_ptr(self.ranges[b..].as_ptr().cast());
    }

    /// The rows of billboard `b`, from its box's first row (empty when its spans are its box).
    #[inline]
    pub(crate) fn of(&self, b: usize) -> &[[u32; 2]] {
        let [start, end] = self.ranges[b];
        &self.blocks[b / BUILD_BLOCK][start as usize..end as usize]
    }
}

/// The rows of a wide billboard's box (`rows`, one per image row from `pixel_min[1]`): with
/// AVX2 when `simd` has it (the rows' eight lanes in one vector instead of two; the same
/// operations, so the same bits), else with the baseline instructions.
fn fill_rows(p: &Prepared, half_side: f32, simd: Simd, rows: &mut [[u32; 2]]) {
    #[cfg(target_arch = "x86_64")]
    if simd.avx2_fma() {
        // SAFETY: the CPU has AVX2 and FMA (a `Simd` at that level exists only on such a CPU).
        return unsafe { fill_rows_avx2(p, half_side, rows) };
    }
    fill_rows_body(p, half_side, rows);
}

/// [`fill_rows_body`] compiled for AVX2 and FMA.
///
/// # Safety
/// The CPU must support AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn fill_rows_avx2(p: &Prepared, half_side: f32, rows: &mut [[u32; 2]]) {
    fill_rows_body(p, half_side, rows);
}

/// The body of [`fill_rows`], inlined into each instruction-set variant.
#[inline(always)]
fn fill_rows_body(p: &Prepared, half_side: f32, rows: &mut [[u32; 2]]) {
    let n = p.pixel_max[0] + 1;
    let Some(quad) = support_quad(&p.transform, half_side) else {
        rows.fill([p.pixel_min[0], n]);
        return;
    };
    let (y0, y1) = (p.pixel_min[1], p.pixel_max[1]);
    for (chunk, first_row) in rows.chunks_mut(ROW_LANES).zip((y0..=y1).step_by(ROW_LANES)) {
        // Lanes past the last row repeat it and are unused.
        let py: [f32; ROW_LANES] = std::array::from_fn(|l| (first_row + l as u32).min(y1) as f32 + 0.5);
        for (row, span) in chunk.iter_mut().zip(quad.row_spans(&py)) {
            *row = match span {
                Some((lo, hi)) => {
                    let (first, end) = pixel_range(lo, hi, n);
                    [first, end]
                }
                None => [0, 0],
            };
        }
    }
}
