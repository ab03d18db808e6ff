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
//!
//! This file is the pass's driver: [`render_backward`] checks its inputs, runs the tile pass
//! (each tile walked by `tile_backward.rs`, entry by entry, or by `tile_backward_pixels.rs`,
//! pixel by pixel, as its forward walked it) and then the per-billboard reduction.

use super::input::ActivatedRef;
use super::output::{ForwardState, RenderOutput};
use super::prefetch::{prefetch, prefetch_lines, prefetch_ref};
use super::schedule::{map_heaviest_first, split_by_lengths};
use super::tile_backward::{EntryScratch, backward_tile_by_entry};
use super::tile_backward_pixels::{PixelScratch, backward_tile_by_pixel};
use super::tile_gradients::{
    BackwardInputs, EMPTY_RECORD, EntryRecord, OwnedRows, TexelSums, TileOutputs, TileTexels, ZERO_TRANSFORM,
    add_transform,
};
use super::tile_types::PairOrder;
use crate::camera::offset_from;
use crate::stages::sh::{SH_FLOATS, sh_colour_vjp_clamped};
use crate::stages::splat_transform::{SplatTransform, camera_vjp, project_splat_vjp_visible};
use glam::Vec3;
use rayon::prelude::*;

// The gradient types, at their paths here too.
pub use super::gradients::{CameraGradient, ImageGradients, RenderGradients};

/// Reusable per-task scratch of the tile backward, one per walk.
#[derive(Default)]
struct Scratch {
    by_pixel: PixelScratch,
    by_entry: EntryScratch,
}

/// The large arrays of a backward pass, owned by the caller and passed to every
/// [`render_backward_with`] call so that their pages are faulted in and zeroed by the kernel
/// once, not per call (they are several megabytes: freed, they go back to the system and come
/// back as fresh pages). Every value is written before it is read: what a call leaves in it
/// never changes the next call's result.
#[derive(Default)]
pub struct BackwardScratch {
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
}

/// Back-propagates image gradients to every billboard parameter and the background, adding
/// into `grads`. Returns the indices of the billboards that received a gradient (those with at
/// least one blended pixel), in increasing order. Allocates its scratch afresh: a caller
/// running many backward passes keeps a [`BackwardScratch`] and calls
/// [`render_backward_with`].
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
    render_backward_with(set, out, image_grads, grads, &mut BackwardScratch::default())
}

/// [`render_backward`] with its large arrays in the caller's `scratch` (the same bits whatever
/// it holds).
///
/// # Panics
/// As [`render_backward`].
pub fn render_backward_with(
    set: &ActivatedRef<'_>,
    out: &RenderOutput,
    image_grads: &ImageGradients<'_>,
    grads: &mut RenderGradients,
    scratch: &mut BackwardScratch,
) -> Vec<u32> {
    check_inputs(set, out, image_grads, grads);
    // Every tile task resets its own records and texel list.
    let storage = scratch;
    let backgrounds = tile_pass(set, out, image_grads, &mut grads.textures, storage);
    for &background in &backgrounds {
        grads.background += background;
    }
    let reduction = Reduction {
        set,
        state: &out.state,
        records: &storage.records,
        normal_records: &storage.normal_records,
        tile_texels: &storage.tile_texels,
        aux: image_grads.has_aux(),
        camera_gradient: image_grads.camera,
        centre: out.state.camera.centre_f64(),
        texels: set.texels(),
    };
    let chunks = reduction.reduce(grads);
    let mut touched = Vec::new();
    for (t, d_camera) in &chunks {
        touched.extend_from_slice(t);
        grads.camera += *d_camera;
    }
    touched
}

/// The checks of [`render_backward`]'s arguments (see its panics).
fn check_inputs(set: &ActivatedRef<'_>, out: &RenderOutput, image_grads: &ImageGradients<'_>, grads: &RenderGradients) {
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
    assert_eq!(
        grads.textures.len(),
        set.len() * set.texels(),
        "gradient buffers must match the billboard set"
    );
    // The tile tasks write the rows of the entries that own them themselves; that each row has
    // one writer rests on the tiles' entry ranges being disjoint (`OwnedRows::owns`).
    let bins = &out.state.bins;
    let n_tiles = bins.tile_count();
    assert!(
        bins.tile_offsets.len() == n_tiles + 1
            && bins.tile_offsets[0] == 0
            && bins.tile_offsets.windows(2).all(|w| w[0] <= w[1])
            && bins.tile_offsets[n_tiles] as usize == bins.entries.len(),
        "the tiles' entry ranges must partition the entries in order"
    );
}

/// The tile pass: every tile's backward, heaviest tiles first, each walked as its forward
/// walked it. Fills `storage`'s entry records, normal records and tile texel lists (and the
/// rows of `textures`, the texture gradients, that owning entries write) and returns each
/// tile's background gradient, in tile order.
fn tile_pass(
    set: &ActivatedRef<'_>,
    out: &RenderOutput,
    image_grads: &ImageGradients<'_>,
    textures: &mut [[f32; 4]],
    storage: &mut BackwardScratch,
) -> Vec<Vec3> {
    let state = &out.state;
    let bins = &state.bins;
    let n_tiles = bins.tile_count();
    let BackwardScratch {
        records,
        normal_records,
        tile_texels,
        entry_pairs,
        owners,
    } = storage;
    crate::memory::resize_for_overwrite(records, bins.entries.len(), EMPTY_RECORD);
    tile_texels.resize_with(n_tiles, Vec::new);
    row_owners(state, entry_pairs, owners);
    assert_eq!(owners.len(), set.len(), "one owner per billboard");
    let owned_rows = OwnedRows {
        rows: textures.as_mut_ptr(),
        texels: set.texels(),
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
    let inputs = BackwardInputs {
        set,
        out,
        grads: image_grads,
        owned_rows: &owned_rows,
    };
    map_heaviest_first(
        tile_work,
        |t| (state.tiles[t].len() + bins.tile_range(t).len()) as u64,
        Scratch::default,
        |scratch, t, ((records, normals), texels)| {
            TEXEL_SUMS.with_borrow_mut(|sums| {
                // Each tile is walked as its forward walked it (the grouping of its pairs), and
                // pixel by pixel for the normal and distortion maps; the same bits either way.
                let outputs = TileOutputs {
                    records,
                    normals,
                    texels,
                    sums,
                };
                if aux || state.tiles[t].order == PairOrder::ByPixel {
                    backward_tile_by_pixel(&inputs, t, outputs, &mut scratch.by_pixel)
                } else {
                    backward_tile_by_entry(&inputs, t, outputs, &mut scratch.by_entry)
                }
            })
        },
    )
}

/// Billboards per task of the reduction, each chunk in index order.
const CHUNK: usize = 256;
/// How far ahead the reduction fetches a billboard's SH coefficients and gradients.
const SH_AHEAD: usize = 8;

/// The per-billboard reduction after the tile pass: each billboard's entries summed in tile
/// order, then chained through its projection and SH colour to its parameters (and to the
/// camera). Reads the tile pass's records, normal records and texel lists.
struct Reduction<'a, 's> {
    set: &'a ActivatedRef<'s>,
    state: &'a ForwardState,
    records: &'a [EntryRecord],
    normal_records: &'a [Vec3],
    tile_texels: &'a [TileTexels],
    /// Normal or distortion gradients were given (the entries have normal gradients).
    aux: bool,
    /// Camera gradients were asked for ([`ImageGradients::camera`]).
    camera_gradient: bool,
    /// The camera centre in f64 (for the SH view direction).
    centre: glam::DVec3,
    /// Texels per billboard (`TS²`).
    texels: usize,
}

impl Reduction<'_, '_> {
    /// Reduces every billboard into `grads` (its rows; the camera's gradient is returned), in
    /// chunks of [`CHUNK`] billboards, each chunk in index order by one task: per chunk, the
    /// billboards that received a gradient and the chunk's camera gradient.
    fn reduce(&self, grads: &mut RenderGradients) -> Vec<(Vec<u32>, CameraGradient)> {
        let texels = self.texels;
        (
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
                    self.prefetch_ahead(b0, lb, len, d_sh, d_tex);
                    let b = b0 + lb;
                    let Some((d_t, d_rgb)) = self.entry_sums(b, &mut d_tex[lb * texels..(lb + 1) * texels]) else {
                        continue;
                    };
                    let rows = BillboardRows {
                        d_pos: &mut d_pos[lb],
                        d_scale: &mut d_scale[lb],
                        d_quat: &mut d_quat[lb],
                        d_sh: &mut d_sh[lb * SH_FLOATS..(lb + 1) * SH_FLOATS],
                    };
                    if let Some(cg) = self.chain(b, &d_t, d_rgb, rows) {
                        d_camera += cg;
                    }
                    touched.push(b as u32);
                }
                (touched, d_camera)
            })
            .collect()
    }

    /// The records of the entries of billboard `b`, in tile order.
    #[inline]
    fn entry_records(&self, b: usize) -> impl Iterator<Item = &EntryRecord> {
        let bins = &self.state.bins;
        let r = bins.billboard_offsets[b] as usize..bins.billboard_offsets[b + 1] as usize;
        bins.billboard_entries[r].iter().map(|&e| &self.records[e as usize])
    }

    /// `∂L/∂normal_view` of billboard `b`: its entries' normal gradients summed in tile order
    /// (zero without a normal or distortion gradient).
    #[inline]
    fn normal_gradient(&self, b: usize) -> Vec3 {
        if !self.aux {
            return Vec3::ZERO;
        }
        let bins = &self.state.bins;
        let r = bins.billboard_offsets[b] as usize..bins.billboard_offsets[b + 1] as usize;
        bins.billboard_entries[r]
            .iter()
            .fold(Vec3::ZERO, |acc, &e| acc + self.normal_records[e as usize])
    }

    /// The texel sums an entry left for the reduction (empty for an owning entry).
    #[inline]
    fn texels_of(&self, rec: &EntryRecord) -> &[(u32, [f32; 4])] {
        &self.tile_texels[rec.tile as usize][rec.texels.0 as usize..rec.texels.1 as usize]
    }

    /// Billboard `b` has tile entries.
    #[inline]
    fn has_entries(&self, b: usize) -> bool {
        let bins = &self.state.bins;
        bins.billboard_offsets[b + 1] > bins.billboard_offsets[b]
    }

    /// The prefetches before billboard `lb` of the chunk starting at billboard `b0` (`len`
    /// billboards; `d_sh` and `d_tex` its gradient rows). The entry records and gradient rows a
    /// billboard reads are scattered (billboards are not in screen order), so each step
    /// prefetches them a few billboards ahead: the entry records 12 ahead, the texel lists 8
    /// ahead, the texture-gradient cells of the texel lists 4 ahead. The SH coefficients and
    /// gradients are read in order but are most of the bytes: all their lines [`SH_AHEAD`]
    /// ahead. Prefetches change no value.
    #[inline(always)]
    fn prefetch_ahead(&self, b0: usize, lb: usize, len: usize, d_sh: &[f32], d_tex: &[[f32; 4]]) {
        let texels = self.texels;
        if lb + 12 < len {
            for rec in self.entry_records(b0 + lb + 12) {
                prefetch_ref(rec);
            }
        }
        if lb + 8 < len {
            for rec in self.entry_records(b0 + lb + 8) {
                let tex = self.texels_of(rec);
                if let (Some(first), Some(last)) = (tex.first(), tex.last()) {
                    prefetch_ref(first);
                    prefetch_ref(last);
                }
            }
        }
        // The SH coefficients and their gradient row, every line of both (192 bytes
        // each, over three or four lines), of a billboard with tile entries: read in
        // order, but their stream is the reduction's main memory traffic.
        if lb + SH_AHEAD < len && self.has_entries(b0 + lb + SH_AHEAD) {
            let la = lb + SH_AHEAD;
            prefetch_lines(self.set.sh_of(b0 + la));
            prefetch_lines(&d_sh[la * SH_FLOATS..(la + 1) * SH_FLOATS]);
        }
        if lb + 4 < len {
            let la = lb + 4;
            for rec in self.entry_records(b0 + la) {
                for &(idx, _) in self.texels_of(rec) {
                    prefetch(d_tex, la * texels + idx as usize);
                }
            }
        }
    }

    /// Billboard `b`'s blended entries summed in tile order: their transform and colour
    /// gradients (returned; `None` when no entry was blended) and their texel sums, added to
    /// `d_tex`, the billboard's texture-gradient row.
    #[inline(always)]
    fn entry_sums(&self, b: usize, d_tex: &mut [[f32; 4]]) -> Option<(SplatTransform, Vec3)> {
        let mut d_t = ZERO_TRANSFORM;
        let mut d_rgb = Vec3::ZERO;
        let mut any = false;
        for rec in self.entry_records(b) {
            if !rec.blended {
                continue;
            }
            let tex = self.texels_of(rec);
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
        any.then_some((d_t, d_rgb))
    }

    /// The chain of billboard `b` from its summed transform and colour gradients (`d_t`,
    /// `d_rgb`) through its projection and SH colour to its parameters, added to `rows`; the
    /// billboard's camera gradient when camera gradients were asked for.
    #[inline(always)]
    fn chain(&self, b: usize, d_t: &SplatTransform, d_rgb: Vec3, rows: BillboardRows<'_>) -> Option<CameraGradient> {
        let (set, camera) = (self.set, &self.state.camera);
        // An entry exists only for a billboard its forward prepared (not culled).
        let prepared = self.state.prepared[b]
            .as_ref()
            .expect("a billboard with tile entries was prepared");
        let normal_sign = if prepared.normal_flipped { -1.0 } else { 1.0 };
        let sg = project_splat_vjp_visible(
            set.log_scales[b],
            set.quaternions[b],
            normal_sign,
            camera,
            d_t,
            self.normal_gradient(b),
        );
        let d_pos_sh = sh_colour_vjp_clamped(
            self.state.settings.sh_degree,
            set.sh_of(b),
            offset_from(self.centre, set.positions[b]),
            prepared.sh_clamped,
            d_rgb,
            rows.d_sh,
        );
        *rows.d_pos += sg.d_position + d_pos_sh;
        *rows.d_scale += sg.d_log_scales;
        for (q, dq) in rows.d_quat.iter_mut().zip(sg.d_quaternion) {
            *q += dq;
        }
        if !self.camera_gradient {
            return None;
        }
        let mut cg = camera_vjp(
            set.positions[b],
            set.log_scales[b],
            set.quaternions[b],
            camera,
            d_t,
            self.normal_gradient(b),
        );
        // The SH direction `p − centre` follows the centre, which δ moves by `−R_cwᵀ·δ`.
        cg.translation += camera.rotation * d_pos_sh;
        Some(CameraGradient::from(cg))
    }
}

/// One billboard's gradient rows of the geometry and SH colour.
struct BillboardRows<'a> {
    d_pos: &'a mut Vec3,
    d_scale: &'a mut glam::Vec2,
    d_quat: &'a mut [f32; 4],
    d_sh: &'a mut [f32],
}
