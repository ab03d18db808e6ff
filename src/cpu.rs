//! The instruction set the lane-wise loops run in, as a value: detected once, passed in.
//!
//! The rasterizer's tile loops, the trainer's texture step and texture row sums, and the SSIM
//! passes are written once, lane by lane, and compiled twice: for the baseline x86-64
//! instruction set (SSE2) and for AVX2 with FMA; the forward's billboard-by-billboard tile is
//! also compiled a third time with AVX-512 enabled. All builds compile the same operations in the
//! same order (Rust never fuses a multiply and an add by itself), so they give the same bits; only
//! the speed differs. Which build runs is a [`Simd`] value carried by the settings of each call
//! ([`crate::raster::RenderSettings::simd`], [`crate::train::TrainConfig::simd`],
//! [`crate::loss::TrainingLoss::simd`], [`crate::loss::ssim::SsimOptions::simd`]): nothing
//! process-wide, so two callers in one process (or two tests) can run different builds at once.
//!
//! A [`Simd`] can only name a build the CPU can run: [`Simd::detect`] gives the widest, and
//! [`Simd::at_most`] a narrower one (for tests comparing builds, or to rule the wide paths out);
//! the wide builds' `unsafe` calls rely on that.
//!
//! ```
//! use bbsplat::cpu::{Simd, SimdLevel};
//! let best = Simd::detect();
//! let baseline = Simd::at_most(SimdLevel::Baseline);
//! assert_eq!(baseline.level(), SimdLevel::Baseline);
//! assert!(baseline.level() <= best.level());
//! // Asking for more than the CPU has gives what it has.
//! assert_eq!(Simd::at_most(SimdLevel::Avx512), best);
//! ```

use std::sync::OnceLock;

/// The builds of the lane-wise loops, narrowest first.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum SimdLevel {
    /// The baseline x86-64 instruction set (SSE2, 4 f32 lanes per register), or plain code on
    /// other architectures: the reference the wide builds are tested against.
    Baseline,
    /// AVX2 with FMA (8 f32 lanes).
    Avx2,
    /// AVX2 with FMA, and the forward's billboard-by-billboard tile in its AVX-512 build (F, VL,
    /// BW and DQ; 32 vector registers and mask registers).
    Avx512,
}

/// A build of the lane-wise loops that this CPU can run (see the [module documentation](self)).
/// The default is [`Simd::detect`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Simd {
    level: SimdLevel,
}

impl Simd {
    /// The widest build this CPU runs (detected on the first call, then remembered).
    pub fn detect() -> Self {
        static DETECTED: OnceLock<SimdLevel> = OnceLock::new();
        Self {
            level: *DETECTED.get_or_init(detect_level),
        }
    }

    /// The widest build this CPU runs that is not wider than `level`.
    pub fn at_most(level: SimdLevel) -> Self {
        Self {
            level: level.min(Self::detect().level),
        }
    }

    /// The baseline build ([`SimdLevel::Baseline`]), which every CPU runs.
    pub const BASELINE: Self = Self {
        level: SimdLevel::Baseline,
    };

    /// Which build this is.
    pub fn level(self) -> SimdLevel {
        self.level
    }

    /// True when the lane-wise loops run their AVX2 + FMA build (also at [`SimdLevel::Avx512`]).
    /// When true, the CPU has AVX2 and FMA.
    #[inline]
    pub fn avx2_fma(self) -> bool {
        self.level >= SimdLevel::Avx2
    }

    /// True when the forward's billboard-by-billboard tile runs its AVX-512 build. When true,
    /// the CPU has AVX2, FMA and AVX-512 F, VL, BW and DQ.
    #[inline]
    pub fn avx512(self) -> bool {
        self.level >= SimdLevel::Avx512
    }
}

impl Default for Simd {
    fn default() -> Self {
        Self::detect()
    }
}

fn detect_level() -> SimdLevel {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::is_x86_feature_detected as has;
        if !(has!("avx2") && has!("fma")) {
            return SimdLevel::Baseline;
        }
        if has!("avx512f") && has!("avx512vl") && has!("avx512bw") && has!("avx512dq") {
            SimdLevel::Avx512
        } else {
            SimdLevel::Avx2
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        SimdLevel::Baseline
    }
}
