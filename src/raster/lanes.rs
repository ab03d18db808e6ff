//! The choices the rasterizer makes for speed alone, and the switches that force them in tests:
//! the instruction set of its lane-wise loops, and the order in which a tile is walked.
//!
//! **Tile walk.** A tile is composited billboard by billboard (each entry applied to its pixels,
//! `tile_forward.rs` / `tile_backward.rs`) unless its entries cover fewer than
//! [`SMALL_ENTRY_PIXELS`] pixels on average, when it is walked pixel by
//! pixel (`tile_forward_pixels.rs`, and the backward's pixel walk, which also serves the normal
//! and distortion maps). The forward's walk leaves the tile's blended pairs grouped its way
//! ([`crate::raster::forward::PairOrder`]) and the backward walks the tile the same way, so
//! neither regroups them (except the backward with normal or distortion gradients, which
//! regroups an entry-walked tile by pixel). Both walks give the same bits; [`force_tile_walk`]
//! picks one for every tile.
//!
//! **Instruction set.**
//! The tile loops are written once, lane by lane over [`crate::stages::ray_plane::LANES`]
//! pixels, and compiled twice: for the baseline x86-64 instruction set (SSE2, 4 f32 lanes per
//! register) and for AVX2 with FMA (8 lanes), chosen at run time. Both compile the same
//! operations in the same order (Rust never fuses a multiply and an add by itself), so they give
//! the same bits; the baseline build is the reference the wide one is tested against
//! (`tests/suite/raster_lanes.rs`), and [`force_baseline`] selects it for such tests and for
//! machines where one wants to rule the wide path out. Two loops have a second, explicit
//! implementation instead of a second build: the forward's billboard-by-billboard tile
//! (`tile_forward_avx2.rs`, AVX2 intrinsics, eight pixels sampled and composited side by side)
//! and the compositing backward of each chunk of eight pairs in the backward's
//! billboard-by-billboard tile (`tile_backward_avx2.rs`), tested against the baseline the same
//! way (bit for bit, also above the alpha clamp under both clamp gradients), and the forward's
//! lane-wise decision and sample directly against the stages' scalar `classify` and
//! `RowTaps::sample_rgba`. The forward's explicit tile is also compiled a second time with
//! AVX-512 enabled (the same source; [`avx512_lanes`], [`force_avx2`]), which runs where the
//! CPU has it and is tested against the baseline in the same way.

use std::sync::atomic::{AtomicBool, AtomicU8, Ordering};

static FORCE_BASELINE: AtomicBool = AtomicBool::new(false);
static FORCE_AVX2: AtomicBool = AtomicBool::new(false);
static TILE_WALK: AtomicU8 = AtomicU8::new(TileWalk::Auto as u8);

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

/// How tiles are walked ([`force_tile_walk`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub enum TileWalk {
    /// Each tile by its entries' size (the default).
    Auto = 0,
    /// Every tile billboard by billboard (except the backward with normal or distortion
    /// gradients, which always walks pixels).
    ByEntry = 1,
    /// Every tile pixel by pixel.
    ByPixel = 2,
}

/// Makes every later render of this process walk its tiles as `walk` says. Results are the same
/// bits whatever the walk; only the speed differs.
pub fn force_tile_walk(walk: TileWalk) {
    TILE_WALK.store(walk as u8, Ordering::Relaxed);
}

/// Whether a tile whose entries cover `pixels` pixels in all over `entries` entries is walked
/// pixel by pixel.
#[inline]
pub(crate) fn walk_by_pixel(pixels: usize, entries: usize) -> bool {
    match TILE_WALK.load(Ordering::Relaxed) {
        1 => false,
        2 => true,
        _ => pixels < SMALL_ENTRY_PIXELS * entries,
    }
}

/// Makes every later render of this process use the baseline (SSE2) build of the tile loops
/// (and the trainer's texture step, `crate::train::texture_step`, its other lane-wise loop)
/// when `on`, or the widest the CPU supports when not (the default). Results are the same bits
/// either way; only the speed differs.
pub fn force_baseline(on: bool) {
    FORCE_BASELINE.store(on, Ordering::Relaxed);
}

/// Makes every later render of this process run the forward's billboard-by-billboard tile in
/// its AVX2 build even on a CPU with AVX-512 when `on` (for tests that compare the two), or
/// the widest build the CPU supports when not (the default). The same bits either way.
pub fn force_avx2(on: bool) {
    FORCE_AVX2.store(on, Ordering::Relaxed);
}

/// True when the forward's billboard-by-billboard tile runs its AVX-512 build: the same AVX2
/// source compiled with AVX-512 (F, VL, BW, DQ) enabled, where the compiler has 32 vector
/// registers and mask registers (docs/perf-log.md, 2026-11-29). The CPU has those features,
/// [`wide_lanes`] holds and [`force_avx2`] is off.
#[inline]
pub fn avx512_lanes() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        wide_lanes()
            && !FORCE_AVX2.load(Ordering::Relaxed)
            && std::arch::is_x86_feature_detected!("avx512f")
            && std::arch::is_x86_feature_detected!("avx512vl")
            && std::arch::is_x86_feature_detected!("avx512bw")
            && std::arch::is_x86_feature_detected!("avx512dq")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// True when the tile loops run their AVX2 + FMA build: the CPU has both and
/// [`force_baseline`] is off.
#[inline]
pub fn wide_lanes() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        !FORCE_BASELINE.load(Ordering::Relaxed)
            && std::arch::is_x86_feature_detected!("avx2")
            && std::arch::is_x86_feature_detected!("fma")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}
