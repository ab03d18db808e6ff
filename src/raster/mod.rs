//! The image rasterizer: every billboard of a view, forward and backward, tiled, parallel and
//! deterministic.
//!
//! Pipeline (method: the BBSplat spec, §3-§4):
//! 1. [`preprocess`]: per billboard, the ray-splat transform, the facing normal, the centre
//!    depth, the SH colour and a tight screen bounding box of the texture support.
//! 2. [`binning`]: square tiles of [`TILE_SIZE`] pixels; each tile lists the billboards whose
//!    box touches it, sorted by centre view depth (ties by billboard index, as the reference's
//!    stable radix sort).
//! 3. [`forward`]: per pixel, front-to-back compositing over its tile's list.
//! 4. [`backward`]: per pixel, the same list re-walked to rebuild the transmittances, then a
//!    back-to-front pass giving gradients without dividing by `1 − alpha`; per-tile partial sums
//!    are reduced per billboard in tile order, so results do not depend on the thread count.
//!
//! [`reference`](mod@reference) holds a plain brute-force renderer (every pixel against every billboard) that
//! the tiled renderer is tested against.
//!
//! Conventions: camera and pixel conventions of [`crate::camera`]; textures are *activated*
//! values (colour and alpha in `[0, 1]`), `TS × TS` RGBA texels `[r, g, b, alpha]` per billboard,
//! row-major (`[billboard][row][col]`); SH coefficients `[coeff][rgb]`, 48 floats per billboard.
//! Output images are interleaved row-major.

pub mod backward;
pub mod binning;
pub mod forward;
pub mod lanes;
pub(crate) mod prefetch;
pub mod preprocess;
pub mod reference;
pub(crate) mod row_spans;
pub(crate) mod schedule;
mod tile_backward;
mod tile_backward_avx2;
mod tile_forward;
pub(crate) mod tile_forward_avx2;
mod tile_forward_pixels;
pub mod workload;

use crate::stages::composite::CompositeParams;
use glam::{Vec2, Vec3};

pub use backward::{RenderGradients, render_backward};
pub use forward::{
    ForwardState, PairOrder, RenderBuffers, RenderOutput, RenderStats, TileBlended, render, render_with,
};
pub use workload::WorkloadStats;

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

/// SH storage per billboard: 16 coefficients × 3 channels, `[coeff][rgb]` (defined by the SH stage).
pub use crate::stages::sh::{SH_COEFFS, SH_FLOATS};

/// The *activated*, borrowed form of the billboard set, in structure-of-arrays layout: what the
/// rasterizer reads. [`ActivatedBillboards::borrowed`](crate::billboards::ActivatedBillboards::borrowed)
/// makes one; any slices in this layout will do. The three forms of the set:
/// [`crate::billboards`].
#[derive(Clone, Copy, Debug)]
pub struct ActivatedRef<'a> {
    /// Centres in world coordinates.
    pub positions: &'a [Vec3],
    /// Raw quaternions (w, x, y, z), normalised at use.
    pub quaternions: &'a [[f32; 4]],
    /// Natural logarithms of the half side lengths along the two tangent axes.
    pub log_scales: &'a [Vec2],
    /// SH coefficients, `[billboard][coeff][rgb]`, 48 floats per billboard.
    pub sh: &'a [f32],
    /// Activated textures, `TS²` texels `[r, g, b, alpha]` (each in `[0, 1]`) per billboard,
    /// `[billboard][row][col]`. Interleaved so that a bilinear tap row reads one or two cache
    /// lines for all four channels.
    pub textures: &'a [[f32; 4]],
    /// Texture side `TS ≥ 2`.
    pub texture_size: usize,
}

impl ActivatedRef<'_> {
    /// Number of billboards.
    pub fn len(&self) -> usize {
        self.positions.len()
    }

    /// True when there is no billboard.
    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }

    /// Texels per channel, `TS²`.
    pub fn texels(&self) -> usize {
        self.texture_size * self.texture_size
    }

    /// Checks that every slice has the length implied by the number of positions.
    ///
    /// # Panics
    /// When a slice length is inconsistent or `TS < 2`: this is a programming error of the caller,
    /// not bad user input.
    pub fn assert_consistent(&self) {
        let n = self.len();
        let t = self.texels();
        assert!(self.texture_size >= 2, "texture size must be at least 2");
        assert_eq!(self.quaternions.len(), n, "one quaternion per billboard");
        assert_eq!(self.log_scales.len(), n, "one scale pair per billboard");
        assert_eq!(self.sh.len(), n * SH_FLOATS, "48 SH floats per billboard");
        assert_eq!(self.textures.len(), n * t, "TS² RGBA texels per billboard");
    }

    /// The RGBA texture of billboard `i`, `TS²` texels `[r, g, b, alpha]`, row-major.
    #[inline]
    pub fn texture_of(&self, i: usize) -> &[[f32; 4]] {
        let t = self.texels();
        &self.textures[i * t..(i + 1) * t]
    }

    /// The SH coefficients of billboard `i`.
    #[inline]
    pub fn sh_of(&self, i: usize) -> &[f32] {
        &self.sh[i * SH_FLOATS..(i + 1) * SH_FLOATS]
    }
}

/// Settings of one render.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RenderSettings {
    /// Colour behind everything (linear RGB).
    pub background: Vec3,
    /// Active SH degree, 0 to 3.
    pub sh_degree: u32,
    /// Compositing thresholds (alpha clamp, alpha cut-off, transmittance stop).
    pub composite: CompositeParams,
    /// Also render the depth-distortion map ([`RenderOutput::distortion`],
    /// [`crate::stages::depth_distortion`]); off by default (the forward then does no extra
    /// work and the map is empty).
    pub distortion: bool,
}

impl Default for RenderSettings {
    fn default() -> Self {
        Self {
            background: Vec3::ZERO,
            sh_degree: 3,
            composite: CompositeParams::default(),
            distortion: false,
        }
    }
}
