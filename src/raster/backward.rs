//! Tiled backward pass.
//!
//! Per pixel the entries the forward pass blended (their tile-list slots are kept in
//! [`super::ForwardState`]) are evaluated again, front to back, to rebuild each one's alpha,
//! transmittance `T_i`, hit and colour; entries that were only tested are not revisited. A back-to-front pass then applies the compositing recursion without ever dividing
//! by `1 − α`: with `B` the normalised colour behind entry `i` (starting at the background),
//! `∂L/∂α_i = T_i · Σ_ch g_ch (f_i,ch − B_ch)` and `B ← α_i f_i + (1 − α_i) B`.
//!
//! Gradients are first accumulated per tile entry (one (tile, billboard) pair) in a record at
//! the entry's global index, then summed per billboard over its entries in tile order, so the
//! result does not depend on how rayon schedules tiles. Texture gradients are summed per
//! (entry, texel) as the pixels produce them, in a per-thread accumulator of dense cells with
//! touched flags, and handed on sparse per entry (only the texels some pixel of the tile
//! touched); see `TexelSums`. The billboard's entry with the most blended pairs (its owning
//! entry) needs no sum: its tile adds each texel contribution straight to the billboard's
//! gradient row as the pixels produce it, and the reduction adds the other entries' sums to the
//! row after it, in tile order (see `OwnedRows`); a billboard with a single tile entry thus has
//! no texel sums at all.

use super::binning::tile_pixels;
use super::candidates::{Candidate, TileCandidates};
use super::input::ActivatedRef;
use super::output::{ForwardState, RenderOutput};
use super::prefetch::{prefetch, prefetch_lines, prefetch_record, prefetch_ref, prefetch_taps};
use super::preprocess::Prepared;
use super::schedule::{map_heaviest_first, split_by_lengths};
use super::tile_backward::{EntryScratch, backward_tile_by_entry};
use super::tile_types::{PairOrder, TileBlended};
use crate::camera::offset_from;
use crate::stages::bilinear::BilinearTaps;
use crate::stages::composite::{Blend, CompositeBackState, Step, classify};
use crate::stages::depth_distortion::{DistortionTotals, depth_gradient, mapped_depth, weight_gradient};
use crate::stages::ray_plane::{intersect_vjp_with, pixel_ray};
use crate::stages::sh::{SH_FLOATS, sh_colour_vjp_clamped};
use crate::stages::splat_transform::{CameraGrads, SplatTransform, camera_vjp, project_splat_vjp_visible};
use glam::{DVec2, DVec3, Vec2, Vec3, Vec4};
use rayon::prelude::*;

/// Gradients of a scalar loss with respect to every billboard parameter and the background.
///
/// Dense per billboard, laid out like [`ActivatedRef`]. [`render_backward`] *adds* into it, so
/// several views can be accumulated; rows of billboards that received nothing are untouched.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderGradients {
    /// `∂L/∂position`.
    pub positions: Vec<Vec3>,
    /// `∂L/∂quaternion` (raw, w x y z).
    pub quaternions: Vec<[f32; 4]>,
    /// `∂L/∂log_scales`.
    pub log_scales: Vec<Vec2>,
    /// `∂L/∂SH`, 48 floats per billboard.
    pub sh: Vec<f32>,
    /// `∂L/∂texel`, `[∂r, ∂g, ∂b, ∂alpha]` of the activated texture values, laid out like
    /// [`ActivatedRef::textures`].
    pub textures: Vec<[f32; 4]>,
    /// `∂L/∂background`.
    pub background: Vec3,
    /// `∂L/∂` the camera of the view (its pose and intrinsics; see [`CameraGradient`]).
    pub camera: CameraGradient,
}

/// Gradients of a loss with respect to a small change of the camera a view was rendered with,
/// summed in f64 over the billboards in index order (so the same for any thread count).
///
/// The parametrisation is [`crate::stages::splat_transform::camera_vjp`]'s:
/// `p_view → (I + [ω]×)·p_view + δ`, i.e. the camera turned by `ω` about its own centre
/// (radians, camera axes) and its view frame shifted by `δ` (camera axes, world units; the
/// centre moves by `−R_cwᵀ·δ`). `translation` includes the SH colours' view directions, which
/// follow the camera centre. [`crate::camera::Camera::adjusted`] applies such a change.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CameraGradient {
    /// `∂L/∂ω`.
    pub rotation: DVec3,
    /// `∂L/∂δ`.
    pub translation: DVec3,
    /// `(∂L/∂fx, ∂L/∂fy)`.
    pub focal: DVec2,
    /// `(∂L/∂cx, ∂L/∂cy)`.
    pub principal: DVec2,
}

impl From<CameraGrads> for CameraGradient {
    fn from(g: CameraGrads) -> Self {
        Self {
            rotation: g.rotation.as_dvec3(),
            translation: g.translation.as_dvec3(),
            focal: g.focal.as_dvec2(),
            principal: g.principal.as_dvec2(),
        }
    }
}

impl std::ops::AddAssign for CameraGradient {
    fn add_assign(&mut self, g: Self) {
        self.rotation += g.rotation;
        self.translation += g.translation;
        self.focal += g.focal;
        self.principal += g.principal;
    }
}

impl RenderGradients {
    /// All-zero gradients for `n` billboards with textures of side `texture_size`.
    pub fn zeros(n: usize, texture_size: usize) -> Self {
        let t = texture_size * texture_size;
        Self {
            positions: vec![Vec3::ZERO; n],
            quaternions: vec![[0.0; 4]; n],
            log_scales: vec![Vec2::ZERO; n],
            sh: vec![0.0; n * SH_FLOATS],
            textures: crate::memory::filled(n * t, [0.0; 4]),
            background: Vec3::ZERO,
            camera: CameraGradient::default(),
        }
    }

    /// Zeroes every gradient of billboard `b` (not the background): after an optimiser has
    /// consumed the rows [`render_backward`] reported, clearing just those keeps the buffers
    /// ready for the next accumulation without touching the whole set.
    pub fn clear_row(&mut self, b: usize) {
        let t = self.textures.len() / self.positions.len().max(1);
        self.positions[b] = Vec3::ZERO;
        self.quaternions[b] = [0.0; 4];
        self.log_scales[b] = Vec2::ZERO;
        self.sh[b * SH_FLOATS..(b + 1) * SH_FLOATS].fill(0.0);
        self.textures[b * t..(b + 1) * t].fill([0.0; 4]);
    }
}

/// Upstream gradients of the loss with respect to the render's images.
///
/// With [`ImageGradients::normal`] and [`ImageGradients::distortion`] both `None` the backward
/// pass does exactly the work (and gives exactly the bits) it did before they existed.
#[derive(Clone, Copy, Debug, Default)]
pub struct ImageGradients<'a> {
    /// `∂L/∂rgb`, interleaved like [`RenderOutput::rgb`].
    pub rgb: &'a [f32],
    /// `∂L/∂alpha` per pixel, if the loss uses the opacity map.
    pub alpha: Option<&'a [f32]>,
    /// `∂L/∂depth` per pixel (of the alpha-weighted depth map), if the loss uses it.
    pub depth: Option<&'a [f32]>,
    /// `∂L/∂normal` per pixel, interleaved xyz like [`RenderOutput::normal`] (the alpha-weighted
    /// view-space normal map), if the loss uses it. Reaches the alphas (hence the textures and,
    /// through `(u, v)`, the geometry) and each billboard's rotation through its facing normal
    /// (the flip to face the camera is a constant sign).
    pub normal: Option<&'a [f32]>,
    /// `∂L/∂distortion` per pixel ([`RenderOutput::distortion`]), if the loss uses it. The
    /// render need not have computed the map: the backward pass rebuilds what it needs.
    pub distortion: Option<&'a [f32]>,
    /// Also compute [`RenderGradients::camera`] (a few hundred instructions per billboard that
    /// received a gradient, about 10 % of a backward pass of many small billboards); left at
    /// zero when false.
    pub camera: bool,
}

impl ImageGradients<'_> {
    /// True when a gradient of the normal or distortion map is given (the backward pass then
    /// carries four more channels per entry).
    fn has_aux(&self) -> bool {
        self.normal.is_some() || self.distortion.is_some()
    }
}

/// One blended entry of a pixel, rebuilt for the backward pass.
#[derive(Clone, Copy)]
struct Blended {
    slot: u32,
    billboard: u32,
    /// The compositing stage's record of the entry (alpha after the clamp, transmittance in
    /// front, weight, clamp flag), replayed bit for bit as the forward made it.
    blend: Blend,
    depth: f32,
    /// The entry's candidate in the run ([`TileCandidates::of`] of the pixel), which holds its
    /// taps (referred to, not copied: 72 bytes a pair).
    candidate: u32,
    colour: Vec3,
}

/// What the tile pass leaves for one entry (one (tile, billboard) pair), stored at the entry's
/// global index so that the per-billboard reduction reaches it with one read (one cache line)
/// from the billboard-major entry index: the geometric gradients accumulated over the tile's
/// pixels and where its texel gradients are.
#[derive(Clone, Copy)]
#[repr(C, align(64))]
pub(super) struct EntryRecord {
    pub(super) transform: SplatTransform,
    pub(super) rgb: Vec3,
    /// The tile; its texel gradients are `tiles[tile].texels[texels.0..texels.1]` (empty when
    /// the tile added them to the billboard's gradient row itself, see [`OwnedRows`]).
    pub(super) tile: u32,
    pub(super) texels: (u32, u32),
    /// Some pixel of the tile blended this entry (it has gradients to reduce).
    pub(super) blended: bool,
}

pub(super) const EMPTY_RECORD: EntryRecord = EntryRecord {
    transform: ZERO_TRANSFORM,
    rgb: Vec3::ZERO,
    tile: 0,
    texels: (0, 0),
    blended: false,
};

/// The texture-gradient rows of the billboards, each written during the tile pass by the tile
/// of the billboard's *owning* entry: its entry with the most blended pairs (the first of them
/// in tile order on a tie; [`row_owners`]).
///
/// The owning entry is the first term of the per-billboard sum, so its tile adds each texel
/// contribution to the row the moment a pixel produces it, in pixel order, instead of summing
/// them per (entry, texel) in [`TexelSums`] and handing the sums on; the reduction then adds the
/// other entries' sums to the row, in tile order, after the tile pass. A billboard with a single
/// entry is done in its tile. Owning by the most pairs rather than by the first entry in tile
/// order halves the pairs whose gradients go through the sums on the trained-like object scene
/// (1.18 M → 0.55 M of 1.80 M pairs: a billboard's first tile usually holds a sliver of it),
/// and with them the texel lists written and read back (`docs/perf.md`). Each row has one writer
/// during the tile pass (the tile holding the owning entry), so tiles running in parallel never
/// touch the same row.
///
/// Rounding: into a zero row (a fresh [`RenderGradients`]) this gives the sums bit for bit
/// (`((0 + g₁) + g₂) + …` equals `0 + ((g₁ + g₂) + …)` in IEEE arithmetic, signed zeros
/// included, which is what adding the owning entry's sum to the zero row gives); into a row
/// that already holds other views' gradients, the owning entry's contributions are added one at
/// a time rather than as one sum. Either way the order is fixed (the owning entry in pixel
/// order, then the others in tile order, each summed in pixel order; which entry owns depends
/// on the forward's blended pairs only), so the result does not depend on the thread count.
pub(super) struct OwnedRows<'a> {
    /// Start of `RenderGradients::textures`.
    rows: *mut [f32; 4],
    /// Texels per billboard (`TS²`).
    texels: usize,
    /// Number of billboards.
    len: usize,
    /// Per billboard: the global index of its owning entry ([`row_owners`]).
    owners: &'a [u32],
}

// SAFETY: the pointer is only dereferenced through `OwnedRows::add` and `OwnedRows::row_mut`,
// whose callers (the tile tasks) each write only rows that `owns` gives them: one entry per
// billboard passes, and the tile ranges are disjoint, so no two tasks write the same row. The
// buffer outlives the tile pass, during which nothing else accesses it (the reduction runs after
// it).
unsafe impl Sync for OwnedRows<'_> {}
// SAFETY: the struct is a pointer into a buffer that outlives the tile pass, two sizes and a
// shared slice; moving it to a worker thread moves no data, and the writes through it follow the
// rules above.
unsafe impl Send for OwnedRows<'_> {}

impl OwnedRows<'_> {
    /// Whether the task processing global entry `entry` (of billboard `b`) writes `b`'s row:
    /// `entry` is `b`'s owning entry. At most one entry passes for each billboard (the one
    /// `owners` names), so with disjoint tile ranges (checked by [`render_backward`]) at most
    /// one task writes each row.
    #[inline]
    pub(super) fn owns(&self, b: u32, entry: usize) -> bool {
        self.owners[b as usize] as usize == entry
    }

    /// `row[texel] += value` for billboard `b`'s texture gradients.
    ///
    /// # Safety
    /// [`OwnedRows::owns`] holds for `b` and an entry that the caller's task alone
    /// processes, during the tile pass.
    #[inline]
    pub(super) unsafe fn add(&self, b: usize, texel: u32, value: [f32; 4]) {
        assert!(
            b < self.len && (texel as usize) < self.texels,
            "texel gradient out of range"
        );
        // SAFETY: in bounds (checked above); exclusive by the caller's contract.
        add_texel(unsafe { &mut *self.rows.add(b * self.texels + texel as usize) }, value);
    }

    /// Billboard `b`'s gradient row (`TS²` texels).
    ///
    /// # Safety
    /// As for [`OwnedRows::add`]; the row must not be reached in another way (through
    /// `add` or another `row_mut`) while the returned slice is alive.
    #[inline]
    // The rows are shared by the tile tasks through `&self`; each row's exclusivity is the
    // caller's contract, as for `add`.
    #[allow(clippy::mut_from_ref)]
    pub(super) unsafe fn row_mut(&self, b: usize) -> &mut [[f32; 4]] {
        assert!(b < self.len, "billboard out of range");
        // SAFETY: in bounds (checked above); exclusive by the caller's contract.
        unsafe { std::slice::from_raw_parts_mut(self.rows.add(b * self.texels), self.texels) }
    }

    /// Start of billboard `b`'s gradient row, for prefetches only (never dereferenced through
    /// this pointer).
    #[inline]
    pub(super) fn row_start(&self, b: usize) -> *const [f32; 4] {
        self.rows.wrapping_add(b.min(self.len) * self.texels)
    }

    /// Hints the CPU to fetch billboard `b`'s gradients of the texels `taps` reads (no effect
    /// on values).
    #[inline]
    fn prefetch(&self, b: usize, taps: &BilinearTaps) {
        if b < self.len {
            prefetch_taps(self.rows.wrapping_add(b * self.texels), taps.indices());
        }
    }
}

const ZERO_TRANSFORM: SplatTransform = SplatTransform {
    tu: Vec3::ZERO,
    tv: Vec3::ZERO,
    tw: Vec3::ZERO,
};

pub(super) fn add_transform(acc: &mut SplatTransform, d: &SplatTransform) {
    acc.tu += d.tu;
    acc.tv += d.tv;
    acc.tw += d.tw;
}

/// One tile's texel gradients of the entries that do not own their billboard's row: (texel
/// index, `[∂r, ∂g, ∂b, ∂alpha]`), grouped by entry (see [`EntryRecord::texels`]). The groups
/// are in no fixed order: the pixel walk writes them in list order, the entry walk in reverse
/// list order. Readers reach each group through its record's span.
pub(super) type TileTexels = Vec<(u32, [f32; 4])>;

/// Reusable per-task scratch of the tile backward.
#[derive(Default)]
struct Scratch {
    blended: Vec<Blended>,
    candidates: TileCandidates,
    /// Per tile-list slot: the tile adds the entry's texture gradients to its billboard's row
    /// itself (see [`OwnedRows`]).
    direct: Vec<bool>,
    /// The scratch of the entry-by-entry tile pass.
    by_entry: EntryScratch,
    /// A tile's blended slots regrouped pixel by pixel, when its forward grouped them by entry.
    pixel_slots: PixelSlots,
}

/// The blended slots of each pixel of a tile, front to back: those of tile-local pixel `q` are
/// `slots[offsets[q]..offsets[q + 1]]`.
#[derive(Default)]
struct PixelSlots {
    offsets: Vec<u32>,
    slots: Vec<u32>,
    cursor: Vec<u32>,
}

impl PixelSlots {
    /// `blended`'s pairs, of a tile of `pixels` pixels, as per-pixel slot lists: its own when
    /// it is grouped by pixel, else a counting sort of its entry-grouped pairs into `self`
    /// (entries in list order, so each pixel's slots come out front to back).
    fn of<'a>(&'a mut self, blended: &'a TileBlended, pixels: usize) -> (&'a [u32], &'a [u32]) {
        if blended.order == PairOrder::ByPixel {
            return (&blended.offsets, &blended.slots);
        }
        let Self { offsets, slots, cursor } = self;
        offsets.clear();
        offsets.resize(pixels + 1, 0);
        for pair in &blended.entry_pairs {
            offsets[usize::from(pair.pixel) + 1] += 1;
        }
        for q in 0..pixels {
            offsets[q + 1] += offsets[q];
        }
        cursor.clear();
        cursor.extend_from_slice(&offsets[..pixels]);
        crate::memory::resize_for_overwrite(slots, blended.entry_pairs.len(), 0);
        for (k, group) in blended.offsets.windows(2).enumerate() {
            for pair in &blended.entry_pairs[group[0] as usize..group[1] as usize] {
                let at = &mut cursor[usize::from(pair.pixel)];
                slots[*at as usize] = k as u32;
                *at += 1;
            }
        }
        (offsets, slots)
    }
}

/// `cell += g` channel by channel, one f32 add each: the add of every texture-gradient sum (the
/// tile sums' cells and the gradient rows alike; the AVX2 backward makes the same four adds as
/// one `_mm_add_ps`).
#[inline(always)]
pub(super) fn add_texel(cell: &mut [f32; 4], g: [f32; 4]) {
    *cell = (Vec4::from_array(*cell) + Vec4::from_array(g)).to_array();
}

/// What an untouched cell of [`TexelSums`] holds: `−0.0` in every channel, so that adding the
/// first contribution `g` gives `g` bit for bit.
pub(crate) const UNTOUCHED: [f32; 4] = [-0.0; 4];

/// Per-tile texture-gradient sums over (entry slot, texel) cells, reused by every tile a
/// thread processes (see [`TEXEL_SUMS`]). The pixel-by-pixel walk interleaves its entries'
/// contributions, so it keeps one slot per entry of the tile and reads them all out at the end
/// ([`TexelSums::finish`]); the entry-by-entry walk finishes one entry before the next, so it
/// uses a single slot and reads it out after each entry ([`TexelSums::read_out`]), while its
/// cells are still in cache (a slot per entry would take 1 MB for a tile of 250 entries, more
/// than L2).
///
/// Each contribution is added to its cell the moment the pixel pass produces it, so every cell
/// is the sum of its contributions in pixel order, starting from the first one (assigned, not
/// added to 0, so that a lone `−0.0` stays `−0.0`): the same sums, in the same order, as a
/// stable sort of all contributions by (slot, texel) followed by a merge of equal keys
/// (`texel_sums_reference` in tests/suite/raster_backward.rs, tested).
///
/// The cells are dense, `slots × TS²` sums of 16 bytes with a one-byte touched flag each. An
/// untouched cell holds `−0.0` in every channel, so an add has no branch and reads no flag: it
/// adds `g` to the cell, and `−0.0 + g` is `g` bit for bit. (A branch on the first touch depends
/// on the data; cachegrind's branch simulation counted 1.5 M mispredictions of it per forward +
/// backward of the trained-like object scene. A select on the flag, the previous form, put the
/// flag's load on every add's path.) [`TexelSums::finish`] reads the flags of the slots
/// something was added to, eight at a time, and resets each cell it reads out to `−0.0`.
#[derive(Default)]
pub(crate) struct TexelSums {
    /// Per cell `slot · texels + texel`: the sum of its contributions in the current tile
    /// (`−0.0` in every channel where `touched` is not set).
    pub(crate) sums: Vec<[f32; 4]>,
    /// Per cell: 1 when some contribution was added in the current tile, else 0.
    pub(crate) touched: Vec<u8>,
    /// Per slot: some contribution was added in the current tile.
    pub(crate) slot_touched: Vec<bool>,
    /// Cells per slot (`TS²`) of the current tile.
    texels: usize,
}

impl TexelSums {
    /// Prepares for a tile with `slots` slots (one per entry in the pixel-by-pixel walk, a single
    /// shared one in the entry-by-entry walk) of `texels` texels each.
    pub(crate) fn start(&mut self, slots: usize, texels: usize) {
        debug_assert!(self.slot_touched.iter().all(|&t| !t), "the previous tile was finished");
        let cells = slots * texels;
        if self.sums.len() < cells {
            self.sums.resize(cells, UNTOUCHED);
            self.touched.resize(cells, 0);
        }
        if self.slot_touched.len() < slots {
            self.slot_touched.resize(slots, false);
        }
        self.texels = texels;
    }

    /// Start of the cell sums (`slots × texels` values of `[f32; 4]`), for prefetches only
    /// (never dereferenced through this pointer; valid until the next [`TexelSums::start`]).
    pub(crate) fn cell_sums(&self) -> *const [f32; 4] {
        self.sums.as_ptr()
    }

    /// Adds one contribution to cell (`slot`, `texel`). The slot must have been marked
    /// ([`TexelSums::mark`]) in this tile: an unmarked slot's cells would be neither read out nor
    /// reset (checked in debug builds).
    #[inline(always)]
    pub(crate) fn add(&mut self, slot: u32, texel: u32, g: [f32; 4]) {
        debug_assert!(self.slot_touched[slot as usize], "the slot was marked before its adds");
        let cell = slot as usize * self.texels + texel as usize;
        // An untouched cell holds −0.0 (`finish` resets what it reads out), and `−0.0 + g` is
        // `g` bit for bit (`−0.0` included): the first contribution is assigned.
        add_texel(&mut self.sums[cell], g);
        self.touched[cell] = 1;
    }

    /// Marks `slot` (see [`TexelSums::mark`]) and returns its cells and touched flags, for
    /// adding to directly: an add to texel `t` adds to `cells[t]` (which holds `−0.0` in every
    /// channel until its first add, so that the first is assigned) and sets `flags[t]` to 1,
    /// as [`TexelSums::add`] does.
    #[inline(always)]
    pub(crate) fn slot_mut(&mut self, slot: u32) -> (&mut [[f32; 4]], &mut [u8]) {
        self.mark(slot);
        let cells = slot as usize * self.texels..(slot as usize + 1) * self.texels;
        (&mut self.sums[cells.clone()], &mut self.touched[cells])
    }

    /// Marks `slot` as added to: [`TexelSums::finish`] reads out (and resets) only marked
    /// slots. Callers of [`TexelSums::add`] mark the slot first, once per entry or per pair.
    #[inline(always)]
    pub(crate) fn mark(&mut self, slot: u32) {
        self.slot_touched[slot as usize] = true;
    }

    /// The touched cells grouped by slot, in texel order within a slot, written over `out`
    /// (cleared first; its storage is kept, see [`BackwardStorage`]), resetting the cells and
    /// flags for the next tile. `span(k, (start, end))` is called for every slot `k` in order:
    /// the texels of slot `k` are `out[start..end]`.
    #[inline(always)]
    pub(crate) fn finish(&mut self, slots: usize, out: &mut TileTexels, mut span: impl FnMut(usize, (u32, u32))) {
        out.clear();
        for slot in 0..slots {
            span(slot, self.read_out(slot, out));
        }
    }

    /// Appends the touched cells of `slot` to `out` in texel order as `(texel, sum)`, resets
    /// them and their flags (so that the slot can take the next entry's contributions), and
    /// returns where they went: `out[start..end]` (empty when the slot was not marked).
    #[inline(always)]
    pub(crate) fn read_out(&mut self, slot: usize, out: &mut TileTexels) -> (u32, u32) {
        let texels = self.texels;
        let start = out.len() as u32;
        if std::mem::take(&mut self.slot_touched[slot]) {
            let flags = &mut self.touched[slot * texels..(slot + 1) * texels];
            let sums = &mut self.sums[slot * texels..(slot + 1) * texels];
            let mut chunks = flags.chunks_exact_mut(8);
            let mut base = 0usize;
            for chunk in &mut chunks {
                let word = u64::from_le_bytes(chunk.try_into().expect("eight flags"));
                if word != 0 {
                    // One set bit per touched flag (each flag is 0 or 1), lowest first.
                    let mut bits = word;
                    while bits != 0 {
                        let t = base + bits.trailing_zeros() as usize / 8;
                        out.push((t as u32, std::mem::replace(&mut sums[t], UNTOUCHED)));
                        bits &= bits - 1;
                    }
                    chunk.fill(0);
                }
                base += 8;
            }
            for (t, flag) in chunks.into_remainder().iter_mut().enumerate() {
                if std::mem::take(flag) != 0 {
                    out.push(((base + t) as u32, std::mem::replace(&mut sums[base + t], UNTOUCHED)));
                }
            }
        }
        (start, out.len() as u32)
    }
}

/// The large arrays of one [`render_backward`] call, kept for the next call on the same
/// thread (see [`BACKWARD_STORAGE`]) so that their pages are faulted in and zeroed by the
/// kernel once, not per call (they are several megabytes: freed, they go back to the system
/// and come back as fresh pages). Every value is written before it is read.
#[derive(Default)]
struct BackwardStorage {
    /// Per tile entry: its record.
    records: Vec<EntryRecord>,
    /// Per tile entry, only with a normal or distortion gradient: `∂L/∂normal_view`.
    normal_records: Vec<Vec3>,
    /// Per tile: its [`TileTexels`].
    tile_texels: Vec<TileTexels>,
    /// Per tile entry: its blended pairs (see [`row_owners`]).
    entry_pairs: Vec<u32>,
    /// Per billboard: its owning entry ([`row_owners`]).
    owners: Vec<u32>,
}

/// Per billboard of `state`, written over `owners` (its storage reused): the global index of
/// the entry whose tile writes the billboard's texture-gradient row ([`OwnedRows`]), the entry
/// with the most blended pairs, the first of them in tile order on a tie; `u32::MAX` for a
/// billboard without entries. `entry_pairs` is scratch: each entry's blended pairs, counted
/// from the tiles' pair lists in parallel (tile by tile, into the tiles' disjoint ranges).
/// Depends on the forward's pairs only, so not on the thread count.
fn row_owners(state: &ForwardState, entry_pairs: &mut Vec<u32>, owners: &mut Vec<u32>) {
    let bins = &state.bins;
    let n_tiles = bins.tile_count();
    crate::memory::resize_for_overwrite(entry_pairs, bins.entries.len(), 0);
    split_by_lengths(entry_pairs, (0..n_tiles).map(|t| bins.tile_range(t).len()))
        .into_par_iter()
        .enumerate()
        .for_each(|(t, counts)| {
            let tile = &state.tiles[t];
            match tile.order {
                PairOrder::ByEntry => {
                    debug_assert_eq!(tile.offsets.len(), counts.len() + 1, "one group per entry");
                    for (count, w) in counts.iter_mut().zip(tile.offsets.windows(2)) {
                        *count = w[1] - w[0];
                    }
                }
                PairOrder::ByPixel => {
                    counts.fill(0);
                    for &slot in &tile.slots {
                        counts[slot as usize] += 1;
                    }
                }
            }
        });
    let n = bins.billboard_offsets.len().saturating_sub(1);
    crate::memory::resize_for_overwrite(owners, n, u32::MAX);
    let entry_pairs: &[u32] = entry_pairs;
    owners
        .par_iter_mut()
        .enumerate()
        .with_min_len(1024)
        .for_each(|(b, owner)| {
            let entries =
                &bins.billboard_entries[bins.billboard_offsets[b] as usize..bins.billboard_offsets[b + 1] as usize];
            let mut best: Option<(u32, u32)> = None;
            for &e in entries {
                let pairs = entry_pairs[e as usize];
                if best.is_none_or(|(most, _)| pairs > most) {
                    best = Some((pairs, e));
                }
            }
            *owner = best.map_or(u32::MAX, |(_, e)| e);
        });
}

thread_local! {
    /// Each thread's [`TexelSums`], kept across tiles and calls so that its pages are zeroed
    /// by the kernel once, not per call.
    static TEXEL_SUMS: std::cell::RefCell<TexelSums> = std::cell::RefCell::default();

    /// The [`BackwardStorage`] of the last [`render_backward`] call made on this thread. A call
    /// takes it and puts it back when done, so a call nested in another on the same thread
    /// (a rayon worker that steals a second view while the first waits) starts from empty
    /// storage instead of sharing it.
    static BACKWARD_STORAGE: std::cell::RefCell<BackwardStorage> = std::cell::RefCell::default();
}

/// Where the gradients of a by-pixel tile's blended pairs go ([`PairSinks::apply`]).
struct PairSinks<'a, 'b> {
    set: &'a ActivatedRef<'b>,
    prepared: &'a [Option<Prepared>],
    /// Per tile-list slot: [`OwnedRows::owns`] holds for the entry (its tile writes the
    /// billboard's gradient row).
    direct: &'a [bool],
    owned_rows: &'a OwnedRows<'a>,
}

impl PairSinks<'_, '_> {
    /// The gradients of one blended pair `bl` at pixel `(px, py)` (its `ray`), given its alpha,
    /// colour and depth gradients (`d_tex_alpha`, `d_colour`, `d_depth`) and its pixel's
    /// `candidates` (which hold its taps, [`Blended::candidate`]): into the
    /// texture gradients (the billboard's row when its entry owns it, else the tile's `sums`),
    /// the transform (through the hit) and the entry's record in `records`. A function inlined
    /// at both of its calls (a closure called twice was compiled out of line, a call per pair).
    #[inline(always)]
    fn apply(
        &self,
        sums: &mut TexelSums,
        records: &mut [EntryRecord],
        candidates: &[Candidate],
        bl: &Blended,
        (px, py, ray): (f32, f32, Vec3),
        (d_tex_alpha, d_colour, d_depth): (f32, Vec3, f32),
    ) {
        let b = bl.billboard as usize;
        let slot = bl.slot;
        let d_rgba = [d_colour.x, d_colour.y, d_colour.z, d_tex_alpha];
        let taps = &candidates[bl.candidate as usize].taps;
        let texture = self.set.texture_of(b);
        let (du, dv) = if self.direct[slot as usize] {
            // SAFETY: `direct[slot]` is set only where `owns` holds for the tile's entry at
            // `slot` (`backward_tile` builds it), and this task is the only one processing it.
            taps.vjp_rgba(texture, d_rgba, |texel, g| unsafe { self.owned_rows.add(b, texel, g) })
        } else {
            sums.mark(slot);
            taps.vjp_rgba(texture, d_rgba, |texel, g| sums.add(slot, texel, g))
        };
        let pr = self.prepared[b].as_ref().expect("blended entries are prepared");
        let plane = pr.view_plane();
        let d_t = intersect_vjp_with(&pr.transform, px, py, |_, _| plane.depth(ray), du, dv, d_depth);
        let rec = &mut records[slot as usize];
        add_transform(&mut rec.transform, &d_t);
        rec.rgb += d_colour;
        rec.blended = true;
    }
}

#[allow(clippy::too_many_arguments)]
fn backward_tile(
    set: &ActivatedRef<'_>,
    out: &RenderOutput,
    grads_in: &ImageGradients<'_>,
    tile: usize,
    records: &mut [EntryRecord],
    normal_records: &mut [Vec3],
    owned_rows: &OwnedRows<'_>,
    scratch: &mut Scratch,
    sums: &mut TexelSums,
    texels: &mut TileTexels,
) -> Vec3 {
    let state = &out.state;
    let bins = &state.bins;
    let range = bins.tile_range(tile);
    let list = &bins.entries[range.clone()];
    let prepared: &[Option<Prepared>] = &state.prepared;
    let settings = &state.settings;
    let params = &settings.composite;
    let ts = set.texture_size;
    let width = out.width;
    let (i0, j0, i1, j1) = tile_pixels(bins, tile, width, out.height);
    debug_assert_eq!(records.len(), list.len());
    records.fill(EntryRecord {
        tile: tile as u32,
        ..EMPTY_RECORD
    });
    let aux = grads_in.has_aux();
    // Per-entry normal gradients: one per slot when a normal or distortion gradient is given.
    debug_assert_eq!(normal_records.len(), if aux { list.len() } else { 0 });
    normal_records.fill(Vec3::ZERO);
    let mut background = Vec3::ZERO;
    sums.start(list.len(), ts * ts);
    let bg = settings.background;
    // The entries that own their billboard's row: their texel gradients go straight to the
    // billboard's gradient row, which is prefetched with the texels of each candidate.
    let direct = &mut scratch.direct;
    direct.clear();
    direct.extend(
        list.iter()
            .enumerate()
            .map(|(k, &b)| owned_rows.owns(b, range.start + k)),
    );
    let direct: &[bool] = direct;
    // Where each candidate's texel gradients will go is prefetched with its texels: the
    // billboard's gradient row for an owning entry, else the (slot, texel) cells of
    // the sums (a `slots × TS²` array, a random cache line per candidate otherwise).
    let cell_sums = sums.cell_sums();
    let prefetch_gradient_cells = |k: u32, taps: &BilinearTaps| {
        if direct[k as usize] {
            owned_rows.prefetch(list[k as usize] as usize, taps);
        } else {
            prefetch_taps(cell_sums.wrapping_add(k as usize * ts * ts), taps.indices());
        }
    };
    let rect = (i0, j0, i1, j1);
    let tw = (i1 - i0) as usize;
    let n_q = tw * (j1 - j0) as usize;
    let (pixel_offsets, pixel_slots) = scratch.pixel_slots.of(&state.tiles[tile], n_q);
    let blended_of = |q: usize| &pixel_slots[pixel_offsets[q] as usize..pixel_offsets[q + 1] as usize];
    // The prepared records of the tile's blended entries are scattered over the whole array and
    // were last read by whichever thread ran this tile's forward: request them all up front so
    // that their cache misses overlap instead of stalling the candidate loop one by one.
    for &slot in pixel_slots {
        prefetch_record(&prepared[list[slot as usize] as usize]);
    }
    let sinks = PairSinks {
        set,
        prepared,
        direct,
        owned_rows,
    };
    let mut first = 0;
    while first < n_q {
        // Hits and taps of the blended entries of a run of pixels, their texels prefetched.
        let end = scratch.candidates.build(
            &state.camera,
            set,
            prepared,
            list,
            rect,
            first,
            blended_of,
            prefetch_gradient_cells,
        );
        // The pixel of `q`, advanced row-major (no division per pixel).
        let (mut i, mut j) = (i0 + (first % tw) as u32, j0 + (first / tw) as u32);
        for q in first..end {
            if q > first {
                i += 1;
                if i == i1 {
                    (i, j) = (i0, j + 1);
                }
            }
            let p = (j * width + i) as usize;
            let g_rgb = Vec3::from_slice(&grads_in.rgb[3 * p..3 * p + 3]);
            let g_alpha = grads_in.alpha.map_or(0.0, |a| a[p]);
            let g_depth = grads_in.depth.map_or(0.0, |d| d[p]);
            let final_t = state.final_transmittance[p];
            background += g_rgb * final_t;
            let candidates = scratch.candidates.of(q);
            if candidates.is_empty() {
                continue;
            }
            // Front to back: rebuild the blended entries and their transmittances with the
            // compositing stage's own decision ([`classify`]), as the forward made them.
            let (px, py) = (i as f32 + 0.5, j as f32 + 0.5);
            let ray = pixel_ray(&state.camera, px, py);
            scratch.blended.clear();
            let mut t = 1.0f32;
            for (ci, cand) in candidates.iter().enumerate() {
                let k = cand.slot as usize;
                let b = list[k];
                let taps = &cand.taps;
                let [r, g, bl, a] = taps.sample_rgba(set.texture_of(b as usize));
                // Only the forward's blended entries are replayed, with the same arithmetic,
                // so each classifies as blended again.
                let Step::Blend(blend) = classify(t, a, params) else {
                    debug_assert!(false, "a replayed entry must blend again");
                    continue;
                };
                let pr = prepared[b as usize].as_ref().expect("binned billboards are prepared");
                scratch.blended.push(Blended {
                    slot: k as u32,
                    billboard: b,
                    blend,
                    depth: cand.depth,
                    candidate: ci as u32,
                    colour: Vec3::new(r, g, bl) + pr.rgb,
                });
                t = blend.next_transmittance;
            }
            let pixel = (px, py, ray);
            if !aux {
                // Back to front with the stage's [`CompositeBackState`]: features (r, g, b, 1,
                // depth), the colour behind starting at the background (its opacity and depth
                // are 0); the stage applies the clamp's gradient rule of `params`.
                let mut back = CompositeBackState::new(&[bg.x, bg.y, bg.z, 0.0, 0.0]);
                let d_out = [g_rgb.x, g_rgb.y, g_rgb.z, g_alpha, g_depth];
                for e in (0..scratch.blended.len()).rev() {
                    let bl = scratch.blended[e];
                    let c = bl.colour;
                    let grad = back.pop(&bl.blend, &[c.x, c.y, c.z, 1.0, bl.depth], &d_out, params);
                    let [dr, dg, db, _, d_depth] = grad.d_features;
                    let d_colour = Vec3::new(dr, dg, db);
                    sinks.apply(sums, records, candidates, &bl, pixel, (grad.d_alpha, d_colour, d_depth));
                }
                continue;
            }
            // With the normal and distortion maps: four more channels, the facing normal (3,
            // 0 behind everything) and the distortion's weight gradient (1, see
            // [`weight_gradient`]: as a feature whose upstream gradient is ∂L/∂distortion, the
            // stage's recursion gives the distortion's share of ∂L/∂α). The distortion also
            // moves each hit's depth ([`depth_gradient`]).
            let g_normal = grads_in
                .normal
                .map_or(Vec3::ZERO, |n| Vec3::from_slice(&n[3 * p..3 * p + 3]));
            let g_distortion = grads_in.distortion.map_or(0.0, |d| d[p]);
            let mut totals = DistortionTotals::default();
            for bl in &scratch.blended {
                totals.add(mapped_depth(bl.depth), bl.blend.weight);
            }
            let mut back = CompositeBackState::new(&[bg.x, bg.y, bg.z, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
            let d_out = [
                g_rgb.x,
                g_rgb.y,
                g_rgb.z,
                g_alpha,
                g_depth,
                g_normal.x,
                g_normal.y,
                g_normal.z,
                g_distortion,
            ];
            for e in (0..scratch.blended.len()).rev() {
                let bl = scratch.blended[e];
                let c = bl.colour;
                let n = prepared[bl.billboard as usize]
                    .as_ref()
                    .expect("blended entries are prepared")
                    .normal;
                let m = mapped_depth(bl.depth);
                let features = [c.x, c.y, c.z, 1.0, bl.depth, n.x, n.y, n.z, weight_gradient(m, &totals)];
                let grad = back.pop(&bl.blend, &features, &d_out, params);
                let [dr, dg, db, _, d_depth, dnx, dny, dnz, _] = grad.d_features;
                let d_depth = d_depth + depth_gradient(bl.depth, m, bl.blend.weight, &totals, g_distortion);
                let d_colour = Vec3::new(dr, dg, db);
                sinks.apply(sums, records, candidates, &bl, pixel, (grad.d_alpha, d_colour, d_depth));
                normal_records[bl.slot as usize] += Vec3::new(dnx, dny, dnz);
            }
        }
        first = end;
    }
    // The texel sums of the other entries go to the reduction.
    sums.finish(list.len(), texels, |k, span| records[k].texels = span);
    background
}

/// Back-propagates image gradients to every billboard parameter and the background, adding
/// into `grads`. Returns the indices of the billboards that received a gradient (those with at
/// least one blended pixel), in increasing order.
///
/// Deterministic: bit-identical for any number of rayon threads.
///
/// # Panics
/// When the gradient images do not match the render's size, `grads` does not match `set`, or
/// the output's tile bins were altered so that the tiles' entry ranges no longer partition the
/// entries in order.
pub fn render_backward(
    set: &ActivatedRef<'_>,
    out: &RenderOutput,
    image_grads: &ImageGradients<'_>,
    grads: &mut RenderGradients,
) -> Vec<u32> {
    let n_pix = (out.width * out.height) as usize;
    assert_eq!(image_grads.rgb.len(), 3 * n_pix, "one RGB gradient per pixel");
    assert!(
        image_grads.alpha.is_none_or(|a| a.len() == n_pix),
        "one alpha gradient per pixel"
    );
    assert!(
        image_grads.depth.is_none_or(|d| d.len() == n_pix),
        "one depth gradient per pixel"
    );
    assert!(
        image_grads.normal.is_none_or(|n| n.len() == 3 * n_pix),
        "one normal gradient (3 values) per pixel"
    );
    assert!(
        image_grads.distortion.is_none_or(|d| d.len() == n_pix),
        "one distortion gradient per pixel"
    );
    assert_eq!(
        grads.positions.len(),
        set.len(),
        "gradient buffers must match the billboard set"
    );
    let state = &out.state;
    let bins = &state.bins;
    let n_tiles = bins.tile_count();
    // The records and texel lists of the last call on this thread, reused (every tile task
    // resets its own records and texel list).
    let mut storage = BACKWARD_STORAGE.take();
    let BackwardStorage {
        records,
        normal_records,
        tile_texels,
        entry_pairs,
        owners,
    } = &mut storage;
    crate::memory::resize_for_overwrite(records, bins.entries.len(), EMPTY_RECORD);
    tile_texels.resize_with(n_tiles, Vec::new);
    let texels = set.texels();
    assert_eq!(
        grads.textures.len(),
        set.len() * texels,
        "gradient buffers must match the billboard set"
    );
    // The tile tasks write the rows of the entries that own them themselves; that each row has
    // one writer rests on the tiles' entry ranges being disjoint (`OwnedRows::owns`).
    assert!(
        bins.tile_offsets.len() == n_tiles + 1
            && bins.tile_offsets[0] == 0
            && bins.tile_offsets.windows(2).all(|w| w[0] <= w[1])
            && bins.tile_offsets[n_tiles] as usize == bins.entries.len(),
        "the tiles' entry ranges must partition the entries in order"
    );
    row_owners(state, entry_pairs, owners);
    assert_eq!(owners.len(), set.len(), "one owner per billboard");
    let owned_rows = OwnedRows {
        rows: grads.textures.as_mut_ptr(),
        texels,
        len: set.len(),
        owners,
    };
    // Per-entry normal gradients, only when a normal or distortion gradient is given (each tile
    // fills its own range; without them every tile gets an empty range).
    let aux = image_grads.has_aux();
    crate::memory::resize_for_overwrite(normal_records, if aux { bins.entries.len() } else { 0 }, Vec3::ZERO);
    let normal_lengths = (0..n_tiles).map(|t| if aux { bins.tile_range(t).len() } else { 0 });
    // Each tile's work is estimated by its blended pairs and entries; the heaviest tiles go
    // first.
    let tile_work: Vec<_> = split_by_lengths(records, (0..n_tiles).map(|t| bins.tile_range(t).len()))
        .into_iter()
        .zip(split_by_lengths(normal_records, normal_lengths))
        .zip(tile_texels.iter_mut())
        .collect();
    let backgrounds: Vec<Vec3> = map_heaviest_first(
        tile_work,
        |t| (state.tiles[t].len() + bins.tile_range(t).len()) as u64,
        Scratch::default,
        |scratch, t, ((records, normals), texels)| {
            TEXEL_SUMS.with_borrow_mut(|sums| {
                // Each tile is walked as its forward walked it (the grouping of its pairs), and
                // pixel by pixel for the normal and distortion maps; the same bits either way.
                if aux || state.tiles[t].order == PairOrder::ByPixel {
                    backward_tile(
                        set,
                        out,
                        image_grads,
                        t,
                        records,
                        normals,
                        &owned_rows,
                        scratch,
                        sums,
                        texels,
                    )
                } else {
                    backward_tile_by_entry(
                        set,
                        out,
                        image_grads,
                        t,
                        records,
                        &owned_rows,
                        &mut scratch.by_entry,
                        sums,
                        texels,
                    )
                }
            })
        },
    );
    for &background in &backgrounds {
        grads.background += background;
    }
    let (records, normal_records, tile_texels) = (&storage.records, &storage.normal_records, &storage.tile_texels);
    let camera = &state.camera;
    let centre = camera.centre_f64();
    let degree = state.settings.sh_degree;
    // The records of the entries of billboard `b`, in tile order.
    let entry_records = |b: usize| {
        let r = bins.billboard_offsets[b] as usize..bins.billboard_offsets[b + 1] as usize;
        bins.billboard_entries[r].iter().map(|&e| &records[e as usize])
    };
    // `∂L/∂normal_view` of billboard `b`: its entries' normal gradients summed in tile order
    // (zero without a normal or distortion gradient).
    let normal_gradient = |b: usize| {
        if !aux {
            return Vec3::ZERO;
        }
        let r = bins.billboard_offsets[b] as usize..bins.billboard_offsets[b + 1] as usize;
        bins.billboard_entries[r]
            .iter()
            .fold(Vec3::ZERO, |acc, &e| acc + normal_records[e as usize])
    };
    let texels_of = |rec: &EntryRecord| &tile_texels[rec.tile as usize][rec.texels.0 as usize..rec.texels.1 as usize];
    // Billboards are reduced in chunks, each chunk in index order by one task. The entry records
    // and gradient rows a billboard reads are scattered (billboards are not in screen order), so
    // each step prefetches them a few billboards ahead: the entry records 12 ahead, the texel
    // lists 8 ahead, the texture-gradient cells of the texel lists 4 ahead. The SH coefficients
    // and gradients are read in order but are most of the bytes: all their lines `SH_AHEAD`
    // ahead. Prefetches change no value.
    const CHUNK: usize = 256;
    const SH_AHEAD: usize = 8;
    let has_entries = |b: usize| bins.billboard_offsets[b + 1] > bins.billboard_offsets[b];
    let rotation_cw = camera.rotation;
    let chunks: Vec<(Vec<u32>, CameraGradient)> = (
        grads.positions.par_chunks_mut(CHUNK),
        grads.quaternions.par_chunks_mut(CHUNK),
        grads.log_scales.par_chunks_mut(CHUNK),
        grads.sh.par_chunks_mut(CHUNK * SH_FLOATS),
        grads.textures.par_chunks_mut(CHUNK * texels),
    )
        .into_par_iter()
        .enumerate()
        .map(|(c, (d_pos, d_quat, d_scale, d_sh, d_tex))| {
            let b0 = c * CHUNK;
            let len = d_pos.len();
            let mut touched = Vec::new();
            let mut d_camera = CameraGradient::default();
            for lb in 0..len {
                if lb + 12 < len {
                    for rec in entry_records(b0 + lb + 12) {
                        prefetch_ref(rec);
                    }
                }
                if lb + 8 < len {
                    for rec in entry_records(b0 + lb + 8) {
                        let tex = texels_of(rec);
                        if let (Some(first), Some(last)) = (tex.first(), tex.last()) {
                            prefetch_ref(first);
                            prefetch_ref(last);
                        }
                    }
                }
                // The SH coefficients and their gradient row, every line of both (192 bytes
                // each, over three or four lines), of a billboard with tile entries: read in
                // order, but their stream is the reduction's main memory traffic.
                if lb + SH_AHEAD < len && has_entries(b0 + lb + SH_AHEAD) {
                    let la = lb + SH_AHEAD;
                    prefetch_lines(set.sh_of(b0 + la));
                    prefetch_lines(&d_sh[la * SH_FLOATS..(la + 1) * SH_FLOATS]);
                }
                if lb + 4 < len {
                    let la = lb + 4;
                    for rec in entry_records(b0 + la) {
                        for &(idx, _) in texels_of(rec) {
                            prefetch(d_tex, la * texels + idx as usize);
                        }
                    }
                }
                let b = b0 + lb;
                let d_tex = &mut d_tex[lb * texels..(lb + 1) * texels];
                let mut d_t = ZERO_TRANSFORM;
                let mut d_rgb = Vec3::ZERO;
                let mut any = false;
                for rec in entry_records(b) {
                    if !rec.blended {
                        continue;
                    }
                    let tex = texels_of(rec);
                    any = true;
                    add_transform(&mut d_t, &rec.transform);
                    d_rgb += rec.rgb;
                    for &(idx, v) in tex {
                        let d = &mut d_tex[idx as usize];
                        for c in 0..4 {
                            d[c] += v[c];
                        }
                    }
                }
                if !any {
                    continue;
                }
                // An entry exists only for a billboard its forward prepared (not culled).
                let prepared = state.prepared[b]
                    .as_ref()
                    .expect("a billboard with tile entries was prepared");
                let normal_sign = if prepared.normal_flipped { -1.0 } else { 1.0 };
                let sg = project_splat_vjp_visible(
                    set.log_scales[b],
                    set.quaternions[b],
                    normal_sign,
                    camera,
                    &d_t,
                    normal_gradient(b),
                );
                let d_sh = &mut d_sh[lb * SH_FLOATS..(lb + 1) * SH_FLOATS];
                let d_pos_sh = sh_colour_vjp_clamped(
                    degree,
                    set.sh_of(b),
                    offset_from(centre, set.positions[b]),
                    prepared.sh_clamped,
                    d_rgb,
                    d_sh,
                );
                d_pos[lb] += sg.d_position + d_pos_sh;
                d_scale[lb] += sg.d_log_scales;
                for (q, dq) in d_quat[lb].iter_mut().zip(sg.d_quaternion) {
                    *q += dq;
                }
                if !image_grads.camera {
                    touched.push(b as u32);
                    continue;
                }
                let mut cg = camera_vjp(
                    set.positions[b],
                    set.log_scales[b],
                    set.quaternions[b],
                    camera,
                    &d_t,
                    normal_gradient(b),
                );
                // The SH direction `p − centre` follows the centre, which δ moves by `−R_cwᵀ·δ`.
                cg.translation += rotation_cw * d_pos_sh;
                d_camera += CameraGradient::from(cg);
                touched.push(b as u32);
            }
            (touched, d_camera)
        })
        .collect();
    BACKWARD_STORAGE.set(storage);
    let mut touched = Vec::new();
    for (t, d_camera) in &chunks {
        touched.extend_from_slice(t);
        grads.camera += *d_camera;
    }
    touched
}
