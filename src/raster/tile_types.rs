//! The types the tile walks share: what a forward tile walk reads ([`TileInputs`]) and writes,
//! per pixel ([`PixelOut`]) and per tile ([`TileBlended`]: its blended pairs, grouped as
//! [`PairOrder`] says, which the backward walks of the tile read).

use super::input::{ActivatedRef, RenderSettings};
use super::preprocess::Prepared;
use super::tile_spans::TileSpans;
use crate::camera::Camera;
use crate::stages::composite::CompositeState;
use glam::Vec3;

/// How the blended pairs of a tile are grouped in its [`TileBlended`]: in the order the
/// forward's walk of that tile found them. The backward walks the tile the same way (pixel by
/// pixel when it also has normal or distortion gradients), so neither pass regroups them.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum PairOrder {
    /// Pixel by pixel (tile-local row-major), front to back within a pixel: the tile was
    /// walked pixel by pixel.
    #[default]
    ByPixel,
    /// Entry by entry (tile-list order, front to back), pixel order within an entry: the tile
    /// was walked billboard by billboard.
    ByEntry,
}

/// One blended pair of a tile walked entry by entry: the tile-local pixel (its index, column
/// and row, so that the backward divides nothing) and the transmittance in front of the entry
/// there. Laid out as C lays it out (pixel, column, row and transmittance at bytes 0, 2, 3 and
/// 4), so that the AVX2 forward writes the pairs of a run of lanes as two vectors
/// (`tile_forward_avx2::push_pairs`).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[repr(C)]
pub(crate) struct EntryPair {
    pub(crate) pixel: u16,
    pub(crate) x: u8,
    pub(crate) y: u8,
    pub(crate) transmittance: f32,
}

const _: () = {
    assert!(size_of::<EntryPair>() == 8);
    assert!(std::mem::offset_of!(EntryPair, pixel) == 0);
    assert!(std::mem::offset_of!(EntryPair, x) == 2);
    assert!(std::mem::offset_of!(EntryPair, y) == 3);
    assert!(std::mem::offset_of!(EntryPair, transmittance) == 4);
};

/// The blended (entry, pixel) pairs of one tile, grouped as [`TileBlended::order`] says, with
/// the transmittance in front of each entry where it was blended (`Tᵢ`), which lets the
/// backward pass visit a tile's entries back to front without replaying each pixel's
/// compositing from the front. [`TileBlended::pairs_by_pixel`] lists them in one canonical
/// order whatever the grouping.
#[derive(Clone, Debug, Default)]
pub struct TileBlended {
    pub(crate) order: PairOrder,
    /// [`PairOrder::ByPixel`]: per pair, its tile-list slot (an index into the tile's
    /// [`TileBins::tile_range`](super::binning::TileBins::tile_range) of [`TileBins::entries`](super::binning::TileBins::entries)). Empty otherwise.
    pub(crate) slots: Vec<u32>,
    /// [`PairOrder::ByPixel`]: per pair, the transmittance in front of it. Empty otherwise.
    pub(crate) transmittance: Vec<f32>,
    /// [`PairOrder::ByEntry`]: the pairs. Empty otherwise.
    pub(crate) entry_pairs: Vec<EntryPair>,
    /// The pairs of group `g` (tile-local pixel `g` by pixel, slot `g` by entry) are
    /// `offsets[g]..offsets[g + 1]`; `offsets[0] = 0`.
    pub(crate) offsets: Vec<u32>,
}

impl TileBlended {
    /// Empties every list (keeping their storage) for a tile whose pairs will be grouped as
    /// `order` says: the one start of every forward tile walk.
    pub(crate) fn start(&mut self, order: PairOrder) {
        self.order = order;
        self.slots.clear();
        self.transmittance.clear();
        self.entry_pairs.clear();
        self.offsets.clear();
    }

    /// How the pairs are grouped.
    pub fn order(&self) -> PairOrder {
        self.order
    }

    /// Number of blended pairs.
    pub fn len(&self) -> usize {
        match self.order {
            PairOrder::ByPixel => self.slots.len(),
            PairOrder::ByEntry => self.entry_pairs.len(),
        }
    }

    /// True when no pixel of the tile blended anything.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Every pair as `(tile-local pixel, slot, transmittance in front)`, pixel by pixel and
    /// front to back within a pixel, whatever [`TileBlended::order`] is.
    ///
    /// ```
    /// use bbsplat::billboards::{RandomSceneConfig, random_scene, random_scene_camera};
    /// use bbsplat::raster::{RenderSettings, render};
    /// let scene = random_scene(&RandomSceneConfig::benchmark(300, 48, 48));
    /// let out = render(&scene.borrowed(), &random_scene_camera(48, 48), &RenderSettings::default());
    /// let mut pairs = 0;
    /// for tile in &out.state.tiles {
    ///     let listed = tile.pairs_by_pixel();
    ///     // Pixel by pixel, and nearer entries (lower slots) first within a pixel.
    ///     assert!(listed.windows(2).all(|w| (w[0].0, w[0].1) < (w[1].0, w[1].1)));
    ///     pairs += listed.len();
    /// }
    /// assert_eq!(pairs as u64, out.stats.blended_pairs);
    /// ```
    pub fn pairs_by_pixel(&self) -> Vec<(u32, u32, f32)> {
        match self.order {
            PairOrder::ByPixel => (0..self.offsets.len().saturating_sub(1))
                .flat_map(|q| {
                    let r = self.offsets[q] as usize..self.offsets[q + 1] as usize;
                    self.slots[r.clone()]
                        .iter()
                        .zip(&self.transmittance[r])
                        .map(move |(&slot, &t)| (q as u32, slot, t))
                })
                .collect(),
            PairOrder::ByEntry => {
                let mut pairs: Vec<(u32, u32, f32)> = (0..self.offsets.len().saturating_sub(1))
                    .flat_map(|k| {
                        self.entry_pairs[self.offsets[k] as usize..self.offsets[k + 1] as usize]
                            .iter()
                            .map(move |pair| (u32::from(pair.pixel), k as u32, pair.transmittance))
                    })
                    .collect();
                // Stable: slots stay in list (front-to-back) order within a pixel.
                pairs.sort_by_key(|&(q, _, _)| q);
                pairs
            }
        }
    }
}

/// Features composited per pixel by the forward pass: colour (3), opacity (the constant 1, so
/// that its composite is `Σ α·T`), view depth of the hit (1) and the facing normal (3).
pub(crate) const FORWARD_FEATURES: usize = 8;

/// Per-pixel values a tile produces.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct PixelOut {
    pub(crate) rgb: Vec3,
    pub(crate) alpha: f32,
    pub(crate) depth: f32,
    pub(crate) median: f32,
    pub(crate) normal: Vec3,
    pub(crate) final_t: f32,
    /// Entries whose span holds the pixel, up to and including the one where compositing
    /// stopped (all of them when it did not stop).
    pub(crate) evaluated: u32,
    pub(crate) nan_alpha: u32,
    /// The depth-distortion value (0 unless the tile was composited with the distortion).
    pub(crate) distortion: f32,
}

impl PixelOut {
    /// A pixel's outputs from its final compositing state over the background `bg` (features
    /// `(r, g, b, 1, depth, normal)` composited over `(bg, 0, 0, 0)`) and its other counters:
    /// the one copy every forward tile walk uses.
    #[inline(always)]
    pub(crate) fn of(
        state: &CompositeState<FORWARD_FEATURES>,
        bg: Vec3,
        median: f32,
        (evaluated, nan_alpha): (u32, u32),
        distortion: f32,
    ) -> Self {
        let [r, g, b, alpha, depth, nx, ny, nz] = state.finish(&[bg.x, bg.y, bg.z, 0.0, 0.0, 0.0, 0.0, 0.0]);
        Self {
            rgb: Vec3::new(r, g, b),
            alpha,
            depth,
            median,
            normal: Vec3::new(nx, ny, nz),
            final_t: state.transmittance,
            evaluated,
            nan_alpha,
            distortion,
        }
    }
}

/// What a forward tile walk ([`composite_tile`](super::tile_forward::composite_tile) and its
/// builds, the pixel walk) reads: the camera, the set, the settings, the prepared records, the
/// tile's list, its pixel rectangle `(i0, j0, i1, j1)` (exclusive ends) and its entries' spans.
#[derive(Clone, Copy)]
pub(crate) struct TileInputs<'a, 's> {
    pub(crate) camera: &'a Camera,
    pub(crate) set: &'a ActivatedRef<'s>,
    pub(crate) settings: &'a RenderSettings,
    pub(crate) prepared: &'a [Option<Prepared>],
    pub(crate) list: &'a [u32],
    pub(crate) rect: (u32, u32, u32, u32),
    pub(crate) spans: &'a TileSpans,
}
