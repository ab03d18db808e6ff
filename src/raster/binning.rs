//! Tile binning: which billboards each tile ([`TILE_SIZE`] pixels square) must consider, in depth
//! order.

use super::preprocess::Prepared;
use super::schedule::split_by_lengths;
use crate::memory::{refill, resize_for_overwrite};
use rayon::prelude::*;

/// Side of a square screen tile in pixels.
///
/// The images do not depend on it (every pixel composites the same billboards in the same
/// order); the gradients do, through the order of the per-billboard sums (pixel order within a
/// tile, then tile order): against 16, about 3 % of a trained-like scene's gradients differ, by
/// 1e-7 of their size at the median and 1.4e-6 at the 99th percentile.
///
/// 48 rather than the reference's 16: the per-entry work (records, prefetches, texel-sum
/// read-outs) is shared by more pixels and the lanes of a billboard's rows are fuller. Measured in docs/perf.md (2026-11-27 evening, criterion,
/// interleaved with the 16-px code): forward + backward 0.87 (object) and 0.91 (capture) of
/// the time on the trained-like scenes, the training step 0.88, the 256²/50k scene unchanged;
/// 64 was slower on the latter.
pub const TILE_SIZE: u32 = 48;

// Tile-local columns and rows are kept as `u8` (`EntryPair`, `EntrySpans`), tile-local pixel
// indices and span pixel counts as `u16`: both fit while the side is at most 255.
const _: () = assert!(TILE_SIZE >= 1 && TILE_SIZE <= 255, "tile coordinates must fit u8");

/// Per-tile lists of billboards and the billboard-major index of the same entries.
///
/// An *entry* is one (tile, billboard) pair. Entries are stored tile by tile (tiles in
/// row-major order); within a tile they are sorted by the billboard's centre view depth, ties
/// broken by billboard index (the order of the reference's stable radix sort).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TileBins {
    /// Number of tile columns.
    pub tiles_x: u32,
    /// Number of tile rows.
    pub tiles_y: u32,
    /// Entry range of tile `t` is `tile_offsets[t]..tile_offsets[t + 1]`.
    pub tile_offsets: Vec<u32>,
    /// Billboard index of each entry.
    pub entries: Vec<u32>,
    /// Entries of billboard `b` are `billboard_entries[billboard_offsets[b]..billboard_offsets[b + 1]]`.
    pub billboard_offsets: Vec<u32>,
    /// Global entry indices grouped by billboard, each group in tile order.
    pub billboard_entries: Vec<u32>,
}

impl TileBins {
    /// Number of tiles.
    pub fn tile_count(&self) -> usize {
        (self.tiles_x * self.tiles_y) as usize
    }

    /// Entry range of tile `t`.
    pub fn tile_range(&self, t: usize) -> std::ops::Range<usize> {
        self.tile_offsets[t] as usize..self.tile_offsets[t + 1] as usize
    }
}

/// The pixel rectangle of tile `t`: `(i0, j0, i1, j1)`, exclusive ends.
pub(crate) fn tile_pixels(bins: &TileBins, t: usize, width: u32, height: u32) -> (u32, u32, u32, u32) {
    let tx = t as u32 % bins.tiles_x;
    let ty = t as u32 / bins.tiles_x;
    let i0 = tx * TILE_SIZE;
    let j0 = ty * TILE_SIZE;
    (i0, j0, (i0 + TILE_SIZE).min(width), (j0 + TILE_SIZE).min(height))
}

pub(crate) fn tile_rect(p: &Prepared) -> ([u32; 2], [u32; 2]) {
    (
        [p.pixel_min[0] / TILE_SIZE, p.pixel_min[1] / TILE_SIZE],
        [p.pixel_max[0] / TILE_SIZE, p.pixel_max[1] / TILE_SIZE],
    )
}

/// A `u32` whose unsigned order is [`f32::total_cmp`]'s order of `x`.
#[inline]
pub(crate) fn total_order_key(x: f32) -> u32 {
    let bits = x.to_bits();
    if bits >> 31 == 1 { !bits } else { bits | 0x8000_0000 }
}

/// Billboards per chunk of [`bin_into`]'s parallel counting pass: at least this many, and
/// few enough chunks that there are at most [`MAX_BIN_CHUNKS`]. The chunking depends only on the
/// number of billboards (never on the thread count); the result does not depend on it at all,
/// since each tile's keys are sorted afterwards.
pub(crate) const MIN_BIN_CHUNK: usize = 4096;

/// Upper bound on the number of chunks of [`bin_into`] (bounds the per-chunk tile counters).
const MAX_BIN_CHUNKS: usize = 64;

/// One chunk's local counting sort: its sort keys grouped by tile.
#[derive(Clone, Debug, Default)]
struct ChunkKeys {
    /// Keys of tile `t` are `keys[offsets[t]..offsets[t + 1]]`, in billboard order.
    offsets: Vec<u32>,
    keys: Vec<u64>,
    /// Per-tile write cursors of the scatter.
    cursor: Vec<u32>,
}

/// Scratch of [`bin_into`]: per-chunk keys and the billboard cursors, kept between calls so
/// that their storage is reused.
#[derive(Clone, Debug, Default)]
pub struct BinScratch {
    chunks: Vec<ChunkKeys>,
    cursor: Vec<u32>,
}

/// Bins the prepared billboards of an image of `width × height` pixels.
pub fn bin(prepared: &[Option<Prepared>], width: u32, height: u32) -> TileBins {
    let mut bins = TileBins::default();
    bin_into(prepared, width, height, &mut bins, &mut BinScratch::default());
    bins
}

/// Counts and groups by tile the sort keys (depth in total order, then index) of the
/// billboards `first..` of `prepared`, reading each record once and in sequence; writes each
/// billboard's entry count to `entry_counts`.
fn chunk_keys(
    prepared: &[Option<Prepared>],
    first: usize,
    tiles_x: u32,
    n_tiles: usize,
    chunk: &mut ChunkKeys,
    entry_counts: &mut [u32],
) {
    let offsets = refill(&mut chunk.offsets, n_tiles + 1, 0);
    for (p, count) in prepared.iter().zip(entry_counts.iter_mut()) {
        *count = 0;
        if let Some(p) = p {
            let (lo, hi) = tile_rect(p);
            for ty in lo[1]..=hi[1] {
                for tx in lo[0]..=hi[0] {
                    offsets[(ty * tiles_x + tx) as usize + 1] += 1;
                }
            }
            *count = (hi[0] - lo[0] + 1) * (hi[1] - lo[1] + 1);
        }
    }
    for t in 0..n_tiles {
        offsets[t + 1] += offsets[t];
    }
    // Every key slot is written by the scatter below: no reset.
    let keys = resize_for_overwrite(&mut chunk.keys, offsets[n_tiles] as usize, 0);
    // Cursors: each tile's start, advanced as its keys arrive.
    let cursor = &mut chunk.cursor;
    cursor.clear();
    cursor.extend_from_slice(&offsets[..n_tiles]);
    for (k, p) in prepared.iter().enumerate() {
        if let Some(p) = p {
            let key = (u64::from(total_order_key(p.depth)) << 32) | (first + k) as u64;
            let (lo, hi) = tile_rect(p);
            for ty in lo[1]..=hi[1] {
                for tx in lo[0]..=hi[0] {
                    let t = (ty * tiles_x + tx) as usize;
                    keys[cursor[t] as usize] = key;
                    cursor[t] += 1;
                }
            }
        }
    }
}

/// [`bin`] into `bins`, reusing the storage of `bins` and `scratch` (every value is
/// overwritten: the result does not depend on what they held).
///
/// Parallel in two passes, the result independent of the thread count: chunks of billboards
/// each group their sort keys by tile (a local counting sort, records read in sequence), then
/// each tile gathers its keys from the chunks and sorts them. Sorting `(depth, index)` keys gives
/// exactly the stable depth order of an index-ordered scatter, whatever order they arrive in;
/// comparing integers gathered here, rather than loading scattered records inside the sort,
/// keeps the sort in cache.
pub fn bin_into(prepared: &[Option<Prepared>], width: u32, height: u32, bins: &mut TileBins, scratch: &mut BinScratch) {
    let tiles_x = width.div_ceil(TILE_SIZE);
    let tiles_y = height.div_ceil(TILE_SIZE);
    let n_tiles = (tiles_x * tiles_y) as usize;
    bins.tiles_x = tiles_x;
    bins.tiles_y = tiles_y;
    let n = prepared.len();
    let chunk_len = MIN_BIN_CHUNK.max(n.div_ceil(MAX_BIN_CHUNKS));
    let n_chunks = n.div_ceil(chunk_len);
    scratch.chunks.resize_with(n_chunks, ChunkKeys::default);
    let chunks = &mut scratch.chunks[..n_chunks];
    // Billboard `b`'s entry count goes to `billboard_offsets[b + 1]`, then a prefix sum.
    let billboard_offsets = refill(&mut bins.billboard_offsets, n + 1, 0);
    prepared
        .par_chunks(chunk_len)
        .zip(billboard_offsets[1..].par_chunks_mut(chunk_len))
        .zip(chunks.par_iter_mut())
        .enumerate()
        .for_each(|(c, ((records, counts), chunk))| {
            chunk_keys(records, c * chunk_len, tiles_x, n_tiles, chunk, counts)
        });
    for b in 0..n {
        billboard_offsets[b + 1] += billboard_offsets[b];
    }
    let chunks = &scratch.chunks[..n_chunks];
    let tile_offsets = refill(&mut bins.tile_offsets, n_tiles + 1, 0);
    for t in 0..n_tiles {
        let count: u32 = chunks.iter().map(|ch| ch.offsets[t + 1] - ch.offsets[t]).sum();
        tile_offsets[t + 1] = tile_offsets[t] + count;
    }
    let total = tile_offsets[n_tiles] as usize;
    // Each tile: its keys from every chunk, sorted, then the billboard indices (every entry is
    // written: no reset).
    resize_for_overwrite(&mut bins.entries, total, 0);
    let tile_offsets = &bins.tile_offsets;
    split_by_lengths(
        &mut bins.entries,
        (0..n_tiles).map(|t| (tile_offsets[t + 1] - tile_offsets[t]) as usize),
    )
    .into_par_iter()
    .enumerate()
    .for_each_init(Vec::new, |keys: &mut Vec<u64>, (t, entries)| {
        keys.clear();
        for ch in chunks {
            keys.extend_from_slice(&ch.keys[ch.offsets[t] as usize..ch.offsets[t + 1] as usize]);
        }
        keys.sort_unstable();
        for (e, &k) in entries.iter_mut().zip(keys.iter()) {
            *e = k as u32;
        }
    });
    // Billboard-major index, each billboard's entries in tile order (every slot is written).
    let billboard_entries = resize_for_overwrite(&mut bins.billboard_entries, total, 0);
    let bcursor = &mut scratch.cursor;
    bcursor.clear();
    bcursor.extend_from_slice(&bins.billboard_offsets[..n]);
    for (e, &b) in bins.entries.iter().enumerate() {
        billboard_entries[bcursor[b as usize] as usize] = e as u32;
        bcursor[b as usize] += 1;
    }
}
