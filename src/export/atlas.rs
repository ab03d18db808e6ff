//! The RGBA texture atlas of the exported planes (spec §10.3 step 3).
//!
//! Layout: tiles of `TS × TS` texels at a pitch of `TS + 2` (a 2-texel transparent gap after each
//! tile, right and below), `max(1, ⌊√N⌋)` tiles per row; tile `k` has its top-left texel at
//! `((k mod per_row)·pitch, (k div per_row)·pitch)` in the *unflipped* atlas, texel `(row, col)`
//! of the billboard's texture (row from `v`, column from `u`) at `+ (col, row)`. The stored image
//! is flipped vertically (the reference's `np.flipud`), so that texture coordinate
//! `t = unflipped row / height` has its origin at the image's bottom (OBJ's convention).

use super::ExportError;
use crate::loss::psnr::quantize_u8;
use crate::raster::ActivatedRef;
use crate::stages::sh::sh_to_rgb;
use glam::Vec2;
use image::ImageEncoder;

/// Texels of transparent gap after each tile.
pub const TILE_GAP: usize = 2;

/// The largest atlas side written (PNG readers and GPUs commonly refuse more).
pub const MAX_ATLAS_SIDE: u64 = 16384;

/// Where the tiles go.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct AtlasLayout {
    /// Texture side `TS`.
    pub tile: usize,
    /// Tiles per atlas row.
    pub per_row: usize,
    /// Atlas width in texels (`per_row · (TS + 2)`).
    pub width: usize,
    /// Atlas height in texels (`rows · (TS + 2)`).
    pub height: usize,
}

impl AtlasLayout {
    /// The layout of `tiles` tiles of side `tile`.
    ///
    /// ```
    /// use bbsplat::export::atlas::AtlasLayout;
    /// let l = AtlasLayout::new(10, 16).unwrap();
    /// assert_eq!((l.per_row, l.width, l.height), (3, 54, 72)); // ⌊√10⌋ = 3 per row, 4 rows
    /// ```
    pub fn new(tiles: usize, tile: usize) -> Result<Self, ExportError> {
        let per_row = (tiles as f64).sqrt().floor().max(1.0) as usize;
        let rows = tiles.div_ceil(per_row).max(1);
        let pitch = tile + TILE_GAP;
        let (width, height) = ((per_row * pitch) as u64, (rows * pitch) as u64);
        if width > MAX_ATLAS_SIDE || height > MAX_ATLAS_SIDE {
            return Err(ExportError::AtlasTooLarge {
                tiles,
                width,
                height,
                max: MAX_ATLAS_SIDE,
            });
        }
        Ok(Self {
            tile,
            per_row,
            width: width as usize,
            height: height as usize,
        })
    }

    /// Column and row (unflipped) of tile `k`'s top-left texel.
    pub fn tile_origin(&self, k: usize) -> (usize, usize) {
        let pitch = self.tile + TILE_GAP;
        ((k % self.per_row) * pitch, (k / self.per_row) * pitch)
    }

    /// Texture coordinates `(s, t)` of the billboard point `(u, v)` of tile `k`, OBJ convention
    /// (origin at the bottom-left of the stored, flipped image): the tile's `TS` texels span
    /// `u, v ∈ [−1, 1]` edge to edge (pixel-edge convention).
    ///
    /// ```
    /// use bbsplat::export::atlas::AtlasLayout;
    /// use glam::Vec2;
    /// let l = AtlasLayout::new(4, 16).unwrap(); // 2 × 2 tiles, 36 × 36 texels
    /// assert_eq!(l.uv(3, Vec2::new(-1.0, -1.0)), Vec2::new(0.5, 0.5));
    /// assert_eq!(l.uv(0, Vec2::new(1.0, 1.0)), Vec2::new(16.0 / 36.0, 16.0 / 36.0));
    /// ```
    pub fn uv(&self, k: usize, uv: Vec2) -> Vec2 {
        let (x0, y0) = self.tile_origin(k);
        let ts = self.tile as f32;
        Vec2::new(
            (x0 as f32 + (uv.x + 1.0) * 0.5 * ts) / self.width as f32,
            (y0 as f32 + (uv.y + 1.0) * 0.5 * ts) / self.height as f32,
        )
    }
}

/// An 8-bit RGBA atlas as stored (rows top to bottom of the *flipped* image).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Atlas {
    /// Where the tiles are.
    pub layout: AtlasLayout,
    /// `width · height · 4` bytes, row-major, first row = top of the stored image.
    pub rgba: Vec<u8>,
}

/// The 8-bit colour of texel `texel` of billboard `i` as exported: colour texture + SH DC colour
/// `max(SH_C0·f_dc + 0.5, 0)` per channel (view dependence dropped), then alpha; each quantised
/// with [`quantize_u8`] (clamped to `[0, 1]`).
pub fn texel_rgba(set: &ActivatedRef<'_>, i: usize, texel: usize) -> [u8; 4] {
    let t = set.texture_of(i)[texel];
    let dc = set.sh_of(i);
    let c = |ch: usize| quantize_u8(t[ch] + sh_to_rgb(dc[ch]).max(0.0));
    [c(0), c(1), c(2), quantize_u8(t[3])]
}

/// The atlas of the billboards `kept` (tile `k` = billboard `kept[k]`); gaps are transparent
/// black.
pub fn build_atlas(set: &ActivatedRef<'_>, kept: &[usize]) -> Result<Atlas, ExportError> {
    let ts = set.texture_size;
    let layout = AtlasLayout::new(kept.len(), ts)?;
    let mut rgba = vec![0u8; layout.width * layout.height * 4];
    for (k, &i) in kept.iter().enumerate() {
        let (x0, y0) = layout.tile_origin(k);
        for row in 0..ts {
            // Vertical flip: unflipped row y is stored at height − 1 − y.
            let stored_row = layout.height - 1 - (y0 + row);
            for col in 0..ts {
                let at = (stored_row * layout.width + x0 + col) * 4;
                rgba[at..at + 4].copy_from_slice(&texel_rgba(set, i, row * ts + col));
            }
        }
    }
    Ok(Atlas { layout, rgba })
}

/// The atlas as PNG bytes (RGBA, 8 bits).
pub fn encode_png(atlas: &Atlas) -> Result<Vec<u8>, ExportError> {
    let mut bytes = Vec::new();
    image::codecs::png::PngEncoder::new(&mut bytes).write_image(
        &atlas.rgba,
        atlas.layout.width as u32,
        atlas.layout.height as u32,
        image::ExtendedColorType::Rgba8,
    )?;
    Ok(bytes)
}
