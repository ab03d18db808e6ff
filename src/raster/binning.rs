//! Tile binning: which billboards each 16×16 tile must consider, in depth order.

use super::TILE_SIZE;
use super::preprocess::Prepared;
use crate::memory::refill;
use rayon::prelude::*;

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

fn tile_rect(p: &Prepared) -> ([u32; 2], [u32; 2]) {
    (
        [p.pixel_min[0] / TILE_SIZE, p.pixel_min[1] / TILE_SIZE],
        [p.pixel_max[0] / TILE_SIZE, p.pixel_max[1] / TILE_SIZE],
    )
}

/// A `u32` whose unsigned order is [`f32::total_cmp`]'s order of `x`.
#[inline]
fn total_order_key(x: f32) -> u32 {
    let bits = x.to_bits();
    if bits >> 31 == 1 { !bits } else { bits | 0x8000_0000 }
}

/// Scratch of [`bin_into`]: per-tile counts and cursors and the sort keys, kept between calls
/// so that their storage is reused.
#[derive(Clone, Debug, Default)]
pub struct BinScratch {
    tile_counts: Vec<u32>,
    cursor: Vec<u32>,
    keys: Vec<u64>,
}

/// Bins the prepared billboards of an image of `width × height` pixels.
pub fn bin(prepared: &[Option<Prepared>], width: u32, height: u32) -> TileBins {
    let mut bins = TileBins::default();
    bin_into(prepared, width, height, &mut bins, &mut BinScratch::default());
    bins
}

/// [`bin`] into `bins`, reusing the storage of `bins` and `scratch` (every value is
/// overwritten: the result does not depend on what they held).
pub fn bin_into(prepared: &[Option<Prepared>], width: u32, height: u32, bins: &mut TileBins, scratch: &mut BinScratch) {
    let tiles_x = width.div_ceil(TILE_SIZE);
    let tiles_y = height.div_ceil(TILE_SIZE);
    let n_tiles = (tiles_x * tiles_y) as usize;
    bins.tiles_x = tiles_x;
    bins.tiles_y = tiles_y;
    // Count entries per tile and per billboard.
    let tile_counts = refill(&mut scratch.tile_counts, n_tiles + 1, 0);
    let billboard_offsets = refill(&mut bins.billboard_offsets, prepared.len() + 1, 0);
    for (b, p) in prepared.iter().enumerate() {
        if let Some(p) = p {
            let (lo, hi) = tile_rect(p);
            for ty in lo[1]..=hi[1] {
                for tx in lo[0]..=hi[0] {
                    tile_counts[(ty * tiles_x + tx) as usize] += 1;
                }
            }
            billboard_offsets[b + 1] = (hi[0] - lo[0] + 1) * (hi[1] - lo[1] + 1);
        }
    }
    let tile_offsets = refill(&mut bins.tile_offsets, n_tiles + 1, 0);
    for t in 0..n_tiles {
        tile_offsets[t + 1] = tile_offsets[t] + tile_counts[t];
    }
    for b in 0..prepared.len() {
        billboard_offsets[b + 1] += billboard_offsets[b];
    }
    let total = tile_offsets[n_tiles] as usize;
    // Scatter the sort keys (depth in total order, then index) in billboard order, reading each
    // prepared record once and in sequence; sorting each tile's (depth, index) keys gives
    // exactly the stable depth order of an index-ordered scatter. Comparing integers gathered
    // here, rather than loading scattered records inside the sort, keeps the sort in cache.
    let keys = refill(&mut scratch.keys, total, 0);
    scratch.cursor.clear();
    scratch.cursor.extend_from_slice(&tile_offsets[..n_tiles]);
    let cursor = &mut scratch.cursor;
    for (b, p) in prepared.iter().enumerate() {
        if let Some(p) = p {
            let key = (u64::from(total_order_key(p.depth)) << 32) | b as u64;
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
    let mut slices: Vec<&mut [u64]> = Vec::with_capacity(n_tiles);
    let mut rest = &mut keys[..];
    for &count in &tile_counts[..n_tiles] {
        let (head, tail) = rest.split_at_mut(count as usize);
        slices.push(head);
        rest = tail;
    }
    slices.into_par_iter().for_each(|s| s.sort_unstable());
    bins.entries.clear();
    bins.entries.extend(keys.iter().map(|&k| k as u32));
    // Billboard-major index, each billboard's entries in tile order.
    let billboard_entries = refill(&mut bins.billboard_entries, total, 0);
    let bcursor = &mut scratch.cursor;
    bcursor.clear();
    bcursor.extend_from_slice(&billboard_offsets[..prepared.len()]);
    for (e, &b) in bins.entries.iter().enumerate() {
        billboard_entries[bcursor[b as usize] as usize] = e as u32;
        bcursor[b as usize] += 1;
    }
}

#[cfg(test)]
mod tests {
    use super::total_order_key;

    #[test]
    fn total_order_key_sorts_like_total_cmp() {
        let mut xs = vec![
            0.2f32,
            -0.0,
            0.0,
            1e-30,
            -1e-30,
            3.5,
            -7.0,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::MAX,
            f32::MIN_POSITIVE,
            100.25,
        ];
        let mut by_key = xs.clone();
        xs.sort_by(f32::total_cmp);
        by_key.sort_by_key(|&x| total_order_key(x));
        assert_eq!(
            xs.iter().map(|x| x.to_bits()).collect::<Vec<_>>(),
            by_key.iter().map(|x| x.to_bits()).collect::<Vec<_>>()
        );
    }
}
