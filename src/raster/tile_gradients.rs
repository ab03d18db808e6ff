//! What the backward tile walks share: what every tile task of a pass reads
//! ([`BackwardInputs`]), and where a tile puts its gradients ([`TileOutputs`]): each tile
//! entry's record ([`EntryRecord`]), the per-(entry, texel) sums of the entries that do not own
//! their billboard's gradient row ([`TexelSums`], read out as [`TileTexels`]), and the rows the
//! owning entries write directly ([`OwnedRows`]); with the back-to-front state of a pixel
//! ([`PixelBack`]) and the texel target ([`TexelTarget`]) the entry walk and its AVX2 chunks
//! share.

use super::gradients::ImageGradients;
use super::input::ActivatedRef;
use super::output::RenderOutput;
use super::prefetch::prefetch_taps;
use crate::stages::bilinear::BilinearTaps;
use crate::stages::composite::CompositeBackState;
use crate::stages::splat_transform::SplatTransform;
use glam::{Vec3, Vec4};

/// What every tile task of one backward pass reads: the billboards, the forward's output, the
/// loss's image gradients, and the texture-gradient rows the owning entries write.
#[derive(Clone, Copy)]
pub(super) struct BackwardInputs<'a, 's> {
    pub(super) set: &'a ActivatedRef<'s>,
    pub(super) out: &'a RenderOutput,
    pub(super) grads: &'a ImageGradients<'a>,
    pub(super) owned_rows: &'a OwnedRows<'a>,
}

/// What the backward of one tile writes: its entries' records, their normal gradients (one per
/// entry with normal or distortion gradients, which only the pixel walk takes; else empty), the
/// texel sums of the entries that do not own their row (for the reduction), and the thread's
/// texel-sum cells it adds them in.
pub(super) struct TileOutputs<'a> {
    pub(super) records: &'a mut [EntryRecord],
    pub(super) normals: &'a mut [Vec3],
    pub(super) texels: &'a mut TileTexels,
    pub(super) sums: &'a mut TexelSums,
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
/// in tile order on a tie; `backward::row_owners`).
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
/// Rounding: into a zero row (a fresh [`RenderGradients`](super::RenderGradients)) this gives the sums bit for bit
/// (`((0 + g₁) + g₂) + …` equals `0 + ((g₁ + g₂) + …)` in IEEE arithmetic, signed zeros
/// included, which is what adding the owning entry's sum to the zero row gives); into a row
/// that already holds other views' gradients, the owning entry's contributions are added one at
/// a time rather than as one sum. Either way the order is fixed (the owning entry in pixel
/// order, then the others in tile order, each summed in pixel order; which entry owns depends
/// on the forward's blended pairs only), so the result does not depend on the thread count.
pub(super) struct OwnedRows<'a> {
    /// Start of `RenderGradients::textures`.
    pub(super) rows: *mut [f32; 4],
    /// Texels per billboard (`TS²`).
    pub(super) texels: usize,
    /// Number of billboards.
    pub(super) len: usize,
    /// Per billboard: the global index of its owning entry (`backward::row_owners`).
    pub(super) owners: &'a [u32],
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
    /// `owners` names), so with disjoint tile ranges (checked by [`render_backward`](super::backward::render_backward)) at most
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
    pub(super) fn prefetch(&self, b: usize, taps: &BilinearTaps) {
        if b < self.len {
            prefetch_taps(self.rows.wrapping_add(b * self.texels), taps.indices());
        }
    }
}

pub(super) const ZERO_TRANSFORM: SplatTransform = SplatTransform {
    tu: Vec3::ZERO,
    tv: Vec3::ZERO,
    tw: Vec3::ZERO,
};

#[inline]
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
/// thread processes (see `backward::TEXEL_SUMS`). The pixel-by-pixel walk interleaves its entries'
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
    /// (cleared first; its storage is kept, see `backward::BackwardScratch`), resetting the cells and
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

/// Channels of the back-to-front recursion: colour (3), opacity (1), depth (1).
pub(super) const CHANNELS: usize = 5;

/// The back-to-front state of one pixel and its upstream gradient.
#[derive(Clone, Copy, Debug)]
pub(super) struct PixelBack {
    pub(super) back: CompositeBackState<CHANNELS>,
    pub(super) d_out: [f32; CHANNELS],
}

/// Where the texel gradients of one entry are added: one cell per texel of the texture (its
/// billboard's gradient row, or the one slot of sums the tile's other entries share, read out
/// after each of them) and a flag per cell, set to 1 by every add (the sums read them; a
/// gradient row's flags are scratch that nothing reads).
pub(super) struct TexelTarget<'a> {
    pub(super) cells: &'a mut [[f32; 4]],
    pub(super) flags: &'a mut [u8],
}

impl TexelTarget<'_> {
    /// Adds `g` to texel `texel`'s cell ([`add_texel`]) and flags it.
    #[inline(always)]
    pub(super) fn add(&mut self, texel: u32, g: [f32; 4]) {
        add_texel(&mut self.cells[texel as usize], g);
        self.flags[texel as usize] = 1;
    }
}
