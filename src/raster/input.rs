//! What a render reads: the activated billboard set, borrowed ([`ActivatedRef`]), and the
//! settings of the render ([`RenderSettings`]); and the planar copy of its textures
//! ([`planar_textures`], the layout of the model's logits).

use super::lanes::TileWalk;
use crate::cpu::Simd;
use crate::stages::composite::CompositeParams;
use crate::stages::sh::SH_FLOATS;
use glam::{Vec2, Vec3};

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
    /// Also render the depth-distortion map ([`RenderOutput::distortion`](super::RenderOutput::distortion),
    /// [`crate::stages::depth_distortion`]); off by default (the forward then does no extra
    /// work and the map is empty).
    pub distortion: bool,
    /// The instruction set of the tile loops (default: the widest the CPU runs). The same bits
    /// whatever it is; only the speed differs.
    pub simd: Simd,
    /// How tiles are walked (default: each by its entries' size). The same bits whatever it is.
    pub tile_walk: TileWalk,
}

impl Default for RenderSettings {
    fn default() -> Self {
        Self {
            background: Vec3::ZERO,
            sh_degree: 3,
            composite: CompositeParams::default(),
            distortion: false,
            simd: Simd::detect(),
            tile_walk: TileWalk::Auto,
        }
    }
}

/// Planar copies of RGBA texels (`texels = TS²` per billboard): alpha `[billboard][texel]` and
/// colour `[billboard][channel][texel]`, the layout of [`crate::model::RawBillboards`]'s logits
/// (from the layout of [`ActivatedRef::textures`]).
///
/// ```
/// let tex = [[0.1, 0.2, 0.3, 0.9], [0.4, 0.5, 0.6, 0.8]];
/// let (alpha, colour) = bbsplat::billboards::planar_textures(&tex, 2);
/// assert_eq!(alpha, [0.9, 0.8]);
/// assert_eq!(colour, [0.1, 0.4, 0.2, 0.5, 0.3, 0.6]);
/// ```
pub fn planar_textures(textures: &[[f32; 4]], texels: usize) -> (Vec<f32>, Vec<f32>) {
    let alpha = textures.iter().map(|t| t[3]).collect();
    let colour = textures
        .chunks(texels.max(1))
        .flat_map(|row| (0..3).flat_map(move |c| row.iter().map(move |t| t[c])))
        .collect();
    (alpha, colour)
}
