//! Where each entry of a tile can contribute: its rows and, per row, its first and last column
//! in tile-local pixels ([`TileSpans`]), computed per tile before its forward walk. The
//! per-pixel reject test of both walks then reads these few contiguous bytes instead of the
//! whole prepared record of each billboard.

use super::binning::TILE_SIZE;
use super::prefetch::prefetch_record;
use super::preprocess::Prepared;
use super::row_spans::{BillboardRows, is_wide};
use crate::stages::splat_transform::{ROW_LANES, pixel_range, support_quad};

/// Where one entry of a tile can contribute, in tile-local pixels: rows `rows[0]..=rows[1]`
/// (none when the first exceeds the second) and, for each of them, its first and last column
/// (an empty row when the first exceeds the last), kept in the [`TileSpans`] that holds the
/// entry ([`TileSpans::row_cols`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct EntrySpans {
    pub(crate) rows: [u8; 2],
    /// The number of pixels of the rows' spans.
    pub(crate) pixels: u16,
    /// The first and last column of any row's span (the first exceeds the last when every row
    /// is empty).
    pub(crate) columns: [u8; 2],
    /// Where the rows' columns start in [`TileSpans`]'s row list.
    first_row: u32,
}

impl EntrySpans {
    /// The number of its rows ([`row_count`]).
    #[inline]
    pub(crate) fn row_count(&self) -> usize {
        row_count(self.rows)
    }
}

/// The number of rows `rows[0]..=rows[1]`: `rows[1] + 1 - rows[0]`, 0 when the first exceeds
/// the last.
#[inline]
fn row_count([first, last]: [u8; 2]) -> usize {
    (usize::from(last) + 1).saturating_sub(usize::from(first))
}

/// The [`EntrySpans`] of one tile's entries, in tile-list order, with their rows' columns in
/// one list (only the rows each entry has: a billboard of a few pixels takes a few bytes, where
/// a column pair for every row of the tile took a hundred and filled the cache with them).
#[derive(Clone, Debug, Default)]
pub(crate) struct TileSpans {
    pub(crate) entries: Vec<EntrySpans>,
    /// The columns `[first, last]` of the rows of every entry, entry after entry.
    row_columns: Vec<[u8; 2]>,
}

impl TileSpans {
    /// Empties both lists (keeping their storage).
    pub(crate) fn clear(&mut self) {
        self.entries.clear();
        self.row_columns.clear();
    }

    /// The columns `[first, last]` of each row of `span` (an entry of this list), row
    /// `span.rows[0]` first.
    #[inline]
    pub(crate) fn row_cols(&self, span: &EntrySpans) -> &[[u8; 2]] {
        let first = span.first_row as usize;
        &self.row_columns[first..first + span.row_count()]
    }

    /// Appends an entry with rows `rows[0]..=rows[1]` whose columns are `cols` (one per row,
    /// in order), counting its pixels and column range from them.
    #[inline]
    fn push(&mut self, rows: [u8; 2], cols: impl Iterator<Item = [u8; 2]>) {
        let first_row = self.row_columns.len() as u32;
        let (mut pixels, mut x0, mut x1) = (0u16, u8::MAX, 0u8);
        for [a, b] in cols {
            if a <= b {
                pixels += u16::from(b - a) + 1;
                x0 = x0.min(a);
                x1 = x1.max(b);
            }
            self.row_columns.push([a, b]);
        }
        let span = EntrySpans {
            rows,
            pixels,
            columns: [x0, x1],
            first_row,
        };
        debug_assert_eq!(self.row_columns.len() - first_row as usize, span.row_count());
        self.entries.push(span);
    }

    /// Appends the box of `p` clamped to the tile at `(i0, j0)`: every row of the box with the
    /// box's columns.
    #[inline]
    fn push_box(&mut self, p: &Prepared, tile: (u32, u32)) {
        let (columns, rows) = box_in_tile(p, tile);
        self.push(rows, std::iter::repeat_n(columns, row_count(rows)));
    }
}

/// The [`EntrySpans`] of a tile's entries, written to `spans` (its old contents replaced, its
/// storage reused): the billboard's pixel box clamped to the tile and, when the box is at least
/// [`QUAD_MIN_COLUMNS`](super::row_spans::QUAD_MIN_COLUMNS) wide and [`support_quad`] gives the projected support square, each row
/// narrowed to [`SupportQuad::row_span`] (pixels outside it cannot hit the texture support, so
/// culling them changes no value). The rows come from `rows` ([`BillboardRows`], each
/// billboard's rows computed once per view for its whole box), cut to the tile's columns: the
/// same spans as computing them for the tile ([`entry_spans_direct`], which still serves boxes
/// that miss the tile; tested on every tile of several scenes). The per-pixel reject test then
/// reads these few contiguous bytes instead of the whole prepared record of each billboard.
/// `half_side` is [`support_half_side`] of the texture size.
///
/// [`support_half_side`]: crate::stages::splat_transform::support_half_side
/// [`SupportQuad::row_span`]: crate::stages::splat_transform::SupportQuad::row_span
pub(crate) fn local_spans(
    prepared: &[Option<Prepared>],
    rows: &BillboardRows,
    list: &[u32],
    (i0, j0): (u32, u32),
    half_side: f32,
    spans: &mut TileSpans,
) {
    spans.clear();
    for (k, &b) in list.iter().enumerate() {
        // The records are scattered over the prepared array: fetch a few entries ahead.
        if let Some(&ahead) = list.get(k + 8) {
            prefetch_record(&prepared[ahead as usize]);
        }
        // Likewise each billboard's rows (written by another pass, likely by the other thread),
        // further ahead: every line of them.
        if let Some(&ahead) = list.get(k + 16) {
            rows.prefetch(ahead as usize);
        }
        // And further still, where those rows are, which that prefetch reads.
        if let Some(&ahead) = list.get(k + 24) {
            rows.prefetch_range(ahead as usize);
        }
        let p = prepared[b as usize].as_ref().expect("binned billboards are prepared");
        if !is_wide(p) {
            spans.push_box(p, (i0, j0));
        } else if !box_meets_tile(p, (i0, j0)) {
            entry_spans_direct(p, (i0, j0), half_side, spans);
        } else {
            let box_rows = rows.of(b as usize);
            let ([x0, x1], [y0, y1]) = box_in_tile(p, (i0, j0));
            // The tile's columns end at `n`; the box's rows are cut to them (see `row_spans`).
            let (n, start) = (i0 + u32::from(x1) + 1, i0 + u32::from(x0));
            let cols = (y0..=y1).map(|y| {
                let [first, end] = box_rows[(j0 + u32::from(y) - p.pixel_min[1]) as usize];
                tile_columns(first.min(n).max(start), end.min(n), i0)
            });
            spans.push([y0, y1], cols);
        }
    }
}

/// The image columns `first..end` (exclusive end, within the tile whose first column is `i0`)
/// as tile-local `[first, last]`, or the empty row `[1, 0]` when there is none.
#[inline]
fn tile_columns(first: u32, end: u32, i0: u32) -> [u8; 2] {
    if first < end {
        [(first - i0) as u8, (end - 1 - i0) as u8]
    } else {
        [1, 0]
    }
}

/// Whether a billboard's pixel box meets the tile at `(i0, j0)` (always, for a billboard the
/// binning listed in that tile).
pub(crate) fn box_meets_tile(p: &Prepared, (i0, j0): (u32, u32)) -> bool {
    let last = TILE_SIZE - 1;
    p.pixel_min[0] <= i0 + last && p.pixel_max[0] >= i0 && p.pixel_min[1] <= j0 + last && p.pixel_max[1] >= j0
}

/// A billboard's pixel box clamped to the tile at `(i0, j0)`, in tile-local pixels: its columns
/// `[x0, x1]` and rows `[y0, y1]` (inclusive; a box that misses the tile, never binned there,
/// comes out with the first of one of them beyond its last, or clamped to the tile's edge).
fn box_in_tile(p: &Prepared, (i0, j0): (u32, u32)) -> ([u8; 2], [u8; 2]) {
    let last = TILE_SIZE - 1;
    let lo = |v: u32, o: u32| v.saturating_sub(o).min(last) as u8;
    let hi = |v: u32, o: u32| if v < o { 0 } else { (v - o).min(last) as u8 };
    (
        [lo(p.pixel_min[0], i0), hi(p.pixel_max[0], i0)],
        [lo(p.pixel_min[1], j0), hi(p.pixel_max[1], j0)],
    )
}

/// Appends to `spans` the [`EntrySpans`] of one tile entry computed for the tile alone: its
/// box clamped to the tile, and when it is wide enough, the support quad projected and each of
/// the tile's rows found on it (computed [`ROW_LANES`] rows at a time by
/// [`SupportQuad::row_spans`], the same bits as `row_span`). The reference of [`local_spans`].
///
/// [`SupportQuad::row_spans`]: crate::stages::splat_transform::SupportQuad::row_spans
pub(crate) fn entry_spans_direct(p: &Prepared, (i0, j0): (u32, u32), half_side: f32, spans: &mut TileSpans) {
    let Some(quad) = is_wide(p).then(|| support_quad(&p.transform, half_side)).flatten() else {
        spans.push_box(p, (i0, j0));
        return;
    };
    let ([x0, x1], [y0, y1]) = box_in_tile(p, (i0, j0));
    let mut cols = [[1u8, 0u8]; TILE_SIZE as usize];
    // The rows' spans `ROW_LANES` at a time (rows past `y1` repeat it and are unused).
    for first_row in (y0..=y1).step_by(ROW_LANES) {
        let py: [f32; ROW_LANES] = std::array::from_fn(|l| {
            let y = (usize::from(first_row) + l).min(usize::from(y1));
            (j0 + y as u32) as f32 + 0.5
        });
        let row_spans = quad.row_spans(&py);
        for (y, span) in (first_row..=y1).zip(row_spans) {
            cols[y as usize] = match span {
                // Columns whose centres lie in [lo, hi], within the box.
                Some((lo, hi)) => {
                    let (first, end) = pixel_range(lo, hi, i0 + u32::from(x1) + 1);
                    tile_columns(first.max(i0 + u32::from(x0)), end, i0)
                }
                None => [1, 0],
            };
        }
    }
    spans.push([y0, y1], (y0..=y1).map(|y| cols[usize::from(y)]));
}
