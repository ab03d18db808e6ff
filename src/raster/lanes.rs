//! The choice of instruction set for the rasterizer's lane-wise loops.
//!
//! The tile loops are written once, lane by lane over [`crate::stages::ray_plane::LANES`]
//! pixels, and compiled twice: for the baseline x86-64 instruction set (SSE2, 4 f32 lanes per
//! register) and for AVX2 with FMA (8 lanes), chosen at run time. Both compile the same
//! operations in the same order (Rust never fuses a multiply and an add by itself), so they give
//! the same bits; the baseline build is the reference the wide one is tested against
//! (`tests/suite/raster_lanes.rs`), and [`force_baseline`] selects it for such tests and for
//! machines where one wants to rule the wide path out.

use std::sync::atomic::{AtomicBool, Ordering};

static FORCE_BASELINE: AtomicBool = AtomicBool::new(false);

/// Makes every later render of this process use the baseline (SSE2) build of the tile loops
/// when `on`, or the widest the CPU supports when not (the default). Results are the same bits
/// either way; only the speed differs.
pub fn force_baseline(on: bool) {
    FORCE_BASELINE.store(on, Ordering::Relaxed);
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
