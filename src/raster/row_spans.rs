//! The pixel columns of each row of a billboard's screen box where its projected support can be
//! hit, computed once per billboard and view and cut to each tile the billboard is listed in.
//!
//! The forward pass narrows every tile entry's pixels to the rows' spans of the billboard's
//! projected support quad ([`local_spans`](super::forward::local_spans)). Computed per tile
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

use super::forward::{QUAD_MIN_COLUMNS, split_by_lengths};
use super::preprocess::Prepared;
use crate::memory::resize_for_overwrite;
use crate::stages::splat_transform::{ROW_LANES, pixel_range, support_quad};
use rayon::prelude::*;

/// Billboards per parallel task of [`BillboardRows::build`].
const BUILD_BLOCK: usize = 256;

/// Per billboard of a view, the columns of each row of its pixel box that its support quad can
/// reach (see the module documentation). Rebuilt per view; its storage is reused.
#[derive(Clone, Debug, Default)]
pub(crate) struct BillboardRows {
    /// The rows of billboard `b` are `cols[offsets[b]..offsets[b + 1]]`, one per image row of its
    /// box from `pixel_min[1]`; none when the billboard is culled or its box is narrower than
    /// [`QUAD_MIN_COLUMNS`] (its spans are its box).
    offsets: Vec<usize>,
    /// Per row: image columns `first..end`, [`pixel_range`] of the row's quad span with
    /// `n = pixel_max[0] + 1`, the box's columns when the billboard has no quad, and `[0, 0]`
    /// when the row misses the quad.
    cols: Vec<[u32; 2]>,
    /// Scratch of [`BillboardRows::build`]: the rows of each block of [`BUILD_BLOCK`]
    /// billboards.
    block_rows: Vec<usize>,
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
    /// ([`support_half_side`](crate::stages::splat_transform::support_half_side)).
    pub(crate) fn build(&mut self, prepared: &[Option<Prepared>], half_side: f32) {
        // Rows per block of billboards, counted in parallel (the records are megabytes: one
        // serial pass over them took as long as the rest of the build).
        self.block_rows.clear();
        prepared
            .par_chunks(BUILD_BLOCK)
            .map(|block| block.iter().map(row_count).sum::<usize>())
            .collect_into_vec(&mut self.block_rows);
        let total = self.block_rows.iter().sum();
        // Every offset and row is written below.
        resize_for_overwrite(&mut self.offsets, prepared.len() + 1, 0);
        self.offsets[0] = 0;
        resize_for_overwrite(&mut self.cols, total, [0, 0]);
        let block_starts = self.block_rows.iter().scan(0, |start, &rows| {
            let first = *start;
            *start += rows;
            Some(first)
        });
        let blocks: Vec<_> = split_by_lengths(&mut self.cols, self.block_rows.iter().copied())
            .into_iter()
            .zip(self.offsets[1..].chunks_mut(BUILD_BLOCK))
            .zip(block_starts)
            .collect();
        blocks.into_par_iter().zip(prepared.par_chunks(BUILD_BLOCK)).for_each(
            |(((mut out, offsets), mut end), block)| {
                for (p, offset) in block.iter().zip(offsets) {
                    let (rows, rest) = std::mem::take(&mut out).split_at_mut(row_count(p));
                    if let Some(p) = p.as_ref().filter(|_| !rows.is_empty()) {
                        fill_rows(p, half_side, rows);
                    }
                    end += rows.len();
                    *offset = end;
                    out = rest;
                }
            },
        );
    }

    /// Hints the CPU to fetch billboard `b`'s rows (no effect on values): one prefetch per 64
    /// bytes from their first byte, so when the rows do not start on a cache line their last
    /// line may be left out. (Starting from the line boundary instead, so that every line is
    /// fetched, took 1.00-1.04 of the time on the 256²/50k bench in four interleaved rounds,
    /// 2026-11-28: one more prefetch per billboard.)
    #[inline]
    pub(crate) fn prefetch(&self, b: usize) {
        let (start, end) = (self.offsets[b], self.offsets[b + 1]);
        let rows = self.cols[start..end].as_ptr_range();
        let mut line = rows.start.cast::<u8>();
        while line < rows.end.cast::<u8>() {
            super::forward::prefetch_ptr(line);
            line = line.wrapping_add(64);
        }
    }

    /// Hints the CPU to fetch where billboard `b`'s rows are (no effect on values), so that
    /// [`BillboardRows::prefetch`] of it later finds them without a wait.
    #[inline]
    pub(crate) fn prefetch_offsets(&self, b: usize) {
        super::forward::prefetch_ptr(self.offsets[b..].as_ptr().cast());
    }

    /// The rows of billboard `b`, from its box's first row (empty when its spans are its box).
    #[inline]
    pub(crate) fn of(&self, b: usize) -> &[[u32; 2]] {
        &self.cols[self.offsets[b]..self.offsets[b + 1]]
    }
}

/// The rows of a wide billboard's box (`rows`, one per image row from `pixel_min[1]`): with
/// AVX2 when the CPU has it (the rows' eight lanes in one vector instead of two; the same
/// operations, so the same bits), else with the baseline instructions.
fn fill_rows(p: &Prepared, half_side: f32, rows: &mut [[u32; 2]]) {
    #[cfg(target_arch = "x86_64")]
    if super::lanes::wide_lanes() {
        // SAFETY: the CPU has AVX2 and FMA (checked at run time by `wide_lanes`).
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
