//! The backward pass of one tile, pixel by pixel: per pixel, its blended entries are rebuilt
//! front to back (their transmittances replayed with the compositing stage's own decision),
//! then walked back to front with the stage's [`CompositeBackState`]. It serves the tiles the
//! forward walked pixel by pixel, and every tile when normal or distortion gradients are given
//! (the entry walk, [`super::tile_backward`], serves the rest; the same bits either way).

use super::binning::tile_pixels;
use super::candidates::{Candidate, TileCandidates};
use super::gradients::ImageGradients;
use super::input::ActivatedRef;
use super::output::RenderOutput;
use super::prefetch::{prefetch_record, prefetch_taps};
use super::preprocess::Prepared;
use super::tile_gradients::{
    BackwardInputs, EMPTY_RECORD, EntryRecord, OwnedRows, TexelSums, TileOutputs, TileTexels, add_transform,
};
use super::tile_types::{PairOrder, TileBlended};
use crate::stages::bilinear::BilinearTaps;
use crate::stages::composite::{Blend, CompositeBackState, Step, classify};
use crate::stages::depth_distortion::{DistortionTotals, depth_gradient, mapped_depth, weight_gradient};
use crate::stages::ray_plane::{intersect_vjp_with, pixel_ray};
use glam::Vec3;

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

/// Reusable per-task scratch of [`backward_tile_by_pixel`] (rebuilt per tile).
#[derive(Default)]
pub(super) struct PixelScratch {
    blended: Vec<Blended>,
    candidates: TileCandidates,
    /// Per tile-list slot: the tile adds the entry's texture gradients to its billboard's row
    /// itself (see [`OwnedRows`]).
    direct: Vec<bool>,
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
            // `slot` (`backward_tile_by_pixel` builds it), and this task is the only one processing it.
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

/// The backward pass of tile `tile` walked pixel by pixel (see the module documentation): fills
/// the tile's entry records (and their normal gradients, with normal or distortion gradients)
/// and the texel sums of the entries that do not own their billboard's row in `outputs`, and
/// returns the tile's background gradient; texel gradients of owning entries go straight to
/// their rows through `inputs.owned_rows`.
pub(super) fn backward_tile_by_pixel(
    inputs: &BackwardInputs<'_, '_>,
    tile: usize,
    outputs: TileOutputs<'_>,
    scratch: &mut PixelScratch,
) -> Vec3 {
    let BackwardInputs {
        set,
        out,
        grads: grads_in,
        owned_rows,
    } = *inputs;
    let TileOutputs {
        records,
        normals,
        texels,
        sums,
    } = outputs;
    by_pixel(
        set, out, grads_in, tile, records, normals, owned_rows, scratch, sums, texels,
    )
}

/// The body of [`backward_tile_by_pixel`], its inputs and outputs as separate parameters, which
/// the compiler may assume alias nothing (see `tile_backward::by_entry`).
#[allow(clippy::too_many_arguments)]
fn by_pixel(
    set: &ActivatedRef<'_>,
    out: &RenderOutput,
    grads_in: &ImageGradients<'_>,
    tile: usize,
    records: &mut [EntryRecord],
    normal_records: &mut [Vec3],
    owned_rows: &OwnedRows<'_>,
    scratch: &mut PixelScratch,
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
