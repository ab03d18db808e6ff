//! The choices the rasterizer makes for speed alone: the instruction set of its lane-wise loops
//! and the order in which a tile is walked, both carried by [`super::RenderSettings`].
//!
//! **Tile walk.** A tile is composited billboard by billboard (each entry applied to its pixels,
//! `tile_forward.rs` / `tile_backward.rs`) unless its entries cover fewer than
//! [`SMALL_ENTRY_PIXELS`] pixels on average, when it is walked pixel by
//! pixel (`tile_forward_pixels.rs`, and the backward's pixel walk, which also serves the normal
//! and distortion maps). The forward's walk leaves the tile's blended pairs grouped its way
//! ([`crate::raster::forward::PairOrder`]) and the backward walks the tile the same way, so
//! neither regroups them (except the backward with normal or distortion gradients, which
//! regroups an entry-walked tile by pixel). Both walks give the same bits; [`TileWalk`]
//! ([`super::RenderSettings::tile_walk`]) picks one for every
//! tile.
//!
//! **Instruction set.** The tile loops are written once, lane by lane over
//! [`crate::stages::ray_plane::LANES`] pixels, and compiled for each [`crate::cpu::Simd`] level;
//! the one a render runs is [`super::RenderSettings::simd`]. Two loops have a second, explicit
//! implementation instead of a second build: the forward's billboard-by-billboard tile
//! (`tile_forward_avx2.rs`, AVX2 intrinsics, eight pixels sampled and composited side by side,
//! also compiled with AVX-512 enabled) and the compositing backward of each chunk of eight pairs
//! in the backward's billboard-by-billboard tile (`tile_backward_avx2.rs`), tested against the
//! baseline bit for bit (`tests/suite/raster_lanes.rs`, also above the alpha clamp under both
//! clamp gradients), and the forward's lane-wise decision and sample directly against the
//! stages' scalar `classify` and `RowTaps::sample_rgba`.

/// A tile whose entries cover fewer pixels than this on average (their span pixels, a little
/// more than the pixels they are evaluated at) is composited pixel by pixel
/// (`composite_tile_by_pixel`), others billboard by billboard (`composite_tile`); its backward
/// walks it the same way. With each walk forced on every tile of random scenes of 2 to 34
/// evaluated pixels per entry (0.8 to 7.6 per pixel) and of the trained-like scenes (63 to 223
/// per entry, 16 to 23 per pixel), the pixel walk took 12-45 % less time up to 9-11 pixels per
/// entry (one scene at 9.6 excepted: 12 % more) and the entry walk 2-38 % less from 16 on,
/// whatever the depth; the trained-like scenes took 2.1-3.2 times as long by pixel
/// (`docs/perf.md`, 2026-11-28 seventh session). The threshold had been 4, which left random
/// scenes of 4-11 pixels per entry on the slower walk (400²/50k 1.6 times as long).
pub const SMALL_ENTRY_PIXELS: usize = 12;

/// How tiles are walked ([`super::RenderSettings::tile_walk`]). Results are the same bits
/// whatever the walk; only the speed differs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum TileWalk {
    /// Each tile by its entries' size (the default).
    #[default]
    Auto,
    /// Every tile billboard by billboard (except the backward with normal or distortion
    /// gradients, which always walks pixels).
    ByEntry,
    /// Every tile pixel by pixel.
    ByPixel,
}

impl TileWalk {
    /// Whether a tile whose entries cover `pixels` pixels in all over `entries` entries is
    /// walked pixel by pixel.
    #[inline]
    pub(crate) fn by_pixel(self, pixels: usize, entries: usize) -> bool {
        match self {
            TileWalk::ByEntry => false,
            TileWalk::ByPixel => true,
            TileWalk::Auto => pixels < SMALL_ENTRY_PIXELS * entries,
        }
    }
}
