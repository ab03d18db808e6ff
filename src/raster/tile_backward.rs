//! The backward pass of one tile, billboard by billboard, back to front: each entry of the
//! tile's list, from the last to the first, is applied to the pixels that blended it before the
//! next (nearer) entry is read.
//!
//! Each pixel keeps its own back-to-front state ([`CompositeBackState`], the stage's own code:
//! the colour behind, starting at the background) in a small per-tile array; visiting the
//! entries in reverse list order visits every pixel's blended entries back to front, as the
//! per-pixel recursion needs. The transmittance in front of each blended pair comes from the
//! forward pass (kept in its [`super::TileBlended`], grouped by entry), so no pixel's
//! compositing is replayed from the front. The alpha of each pair is sampled again and classified with the
//! stored transmittance, which gives the forward's [`Blend`](crate::stages::composite::Blend)
//! record bit for bit.
//!
//! Every sum keeps its order: an entry's geometric gradients, its texel sums and the texel rows
//! of billboards' owning entries receive their pixels' contributions in pixel order, as in the
//! pixel-by-pixel walk ([`super::tile_backward_pixels`], which still serves the normal and distortion maps), so
//! the gradients are the same bits (checksums of `raster_stats`; the raster tests).

use super::binning::tile_pixels;
use super::gradients::ImageGradients;
use super::input::ActivatedRef;
use super::output::RenderOutput;
use super::prefetch::prefetch_record;
use super::preprocess::Prepared;
use super::texel_prefetch::{TexelRect, prefetch_texel_rect, prefetch_texel_rect_l2, texel_footprint};
#[cfg(target_arch = "x86_64")]
use super::tile_backward_avx2::{add_lanes_in_order, chunk_backward, chunk_lanes};
use super::tile_gradients::{
    BackwardInputs, EMPTY_RECORD, EntryRecord, OwnedRows, PixelBack, TexelSums, TexelTarget, TileOutputs, TileTexels,
    add_transform,
};
use super::tile_types::{EntryPair, PairOrder};
use crate::stages::bilinear::RowTaps;
use crate::stages::composite::{CompositeBackState, Step, classify};
use crate::stages::ray_plane::{LANES, intersect_lanes, intersect_vjp_lanes};
use glam::Vec3;

/// Reusable per-task scratch of [`backward_tile_by_entry`] (rebuilt per tile).
#[derive(Default)]
pub(super) struct EntryScratch {
    pixels: Vec<PixelBack>,
    /// Per slot: the tile adds the entry's texture gradients to its billboard's row itself.
    direct: Vec<bool>,
    /// The touched flags of a gradient row's texels: set by the adds, never read (a row has
    /// no flags; the sums' slots do).
    row_flags: Vec<u8>,
}

/// The backward pass of tile `tile` without the normal and distortion maps: fills the tile's
/// entry records and the texel sums of the entries that do not own their billboard's row in
/// `outputs` and returns the tile's background gradient; texel gradients of owning entries go
/// straight to their rows through `inputs.owned_rows`. Bit for bit what the
/// pixel-by-pixel walk gives.
pub(super) fn backward_tile_by_entry(
    inputs: &BackwardInputs<'_, '_>,
    tile: usize,
    outputs: TileOutputs<'_>,
    scratch: &mut EntryScratch,
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
    debug_assert!(
        normals.is_empty(),
        "the entry walk takes no normal or distortion gradients"
    );
    by_entry(set, out, grads_in, tile, records, owned_rows, scratch, sums, texels)
}

/// [`backward_tile_by_entry`] on the widest instruction set the CPU has. The walk's inputs and
/// outputs are separate parameters here, as in the instruction-set variants, not fields of
/// [`BackwardInputs`] and [`TileOutputs`]: the compiler may assume that a function's `&mut`
/// parameters alias nothing, but not that of references read from a struct: with the structs
/// passed through to the body, the AVX2 walk ran 5.9 % more instructions (cachegrind of
/// `raster_stats object 400 10000 loop 2`, one thread: 1.451 G → 1.536 G; 1.449 G as here).
#[allow(clippy::too_many_arguments)]
fn by_entry(
    set: &ActivatedRef<'_>,
    out: &RenderOutput,
    grads_in: &ImageGradients<'_>,
    tile: usize,
    records: &mut [EntryRecord],
    owned_rows: &OwnedRows<'_>,
    scratch: &mut EntryScratch,
    sums: &mut TexelSums,
    texels: &mut TileTexels,
) -> Vec3 {
    #[cfg(target_arch = "x86_64")]
    if out.state.settings.simd.avx2_fma() {
        // SAFETY: the CPU has AVX2 and FMA (a `Simd` at that level exists only on such a CPU).
        return unsafe { by_entry_avx2(set, out, grads_in, tile, records, owned_rows, scratch, sums, texels) };
    }
    by_entry_body::<false>(set, out, grads_in, tile, records, owned_rows, scratch, sums, texels)
}

/// [`by_entry_body`] compiled for AVX2 and FMA, with each chunk's compositing backward in
/// explicit AVX2 ([`super::tile_backward_avx2`]; same bits).
///
/// # Safety
/// The CPU must support AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[allow(clippy::too_many_arguments)]
unsafe fn by_entry_avx2(
    set: &ActivatedRef<'_>,
    out: &RenderOutput,
    grads_in: &ImageGradients<'_>,
    tile: usize,
    records: &mut [EntryRecord],
    owned_rows: &OwnedRows<'_>,
    scratch: &mut EntryScratch,
    sums: &mut TexelSums,
    texels: &mut TileTexels,
) -> Vec3 {
    by_entry_body::<true>(set, out, grads_in, tile, records, owned_rows, scratch, sums, texels)
}

/// The body of [`backward_tile_by_entry`], inlined into each instruction-set variant; with
/// `WIDE` (AVX2 and FMA enabled by the caller) each chunk's compositing backward runs in
/// explicit AVX2 ([`super::tile_backward_avx2::chunk_backward`]), else pair by pair with the
/// stages' code below (the reference).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn by_entry_body<const WIDE: bool>(
    set: &ActivatedRef<'_>,
    out: &RenderOutput,
    grads_in: &ImageGradients<'_>,
    tile: usize,
    records: &mut [EntryRecord],
    owned_rows: &OwnedRows<'_>,
    scratch: &mut EntryScratch,
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
    let camera = &state.camera;
    let ts = set.texture_size;
    let width = out.width;
    let (i0, j0, i1, j1) = tile_pixels(bins, tile, width, out.height);
    let tw = (i1 - i0) as usize;
    let n_q = tw * (j1 - j0) as usize;
    debug_assert_eq!(records.len(), list.len());
    records.fill(EntryRecord {
        tile: tile as u32,
        ..EMPTY_RECORD
    });
    // One slot of sums for every entry that does not own its gradient row: each entry's
    // contributions are complete once its pairs are done, so they are read out then, while
    // their cells are still in cache, and the slot is reset for the next entry.
    sums.start(1, ts * ts);
    texels.clear();
    let EntryScratch {
        pixels,
        direct,
        row_flags,
    } = scratch;
    row_flags.resize(ts * ts, 0);
    direct.clear();
    direct.extend(
        list.iter()
            .enumerate()
            .map(|(k, &b)| owned_rows.owns(b, range.start + k)),
    );
    // Per pixel: the upstream gradients, the state behind the last blended entry (the
    // background), and the background's gradient `Σ g·T_final` in pixel order.
    let bg = settings.background;
    let mut background = Vec3::ZERO;
    pixels.clear();
    for q in 0..n_q {
        let (i, j) = (i0 + (q % tw) as u32, j0 + (q / tw) as u32);
        let p = (j * width + i) as usize;
        let g_rgb = Vec3::from_slice(&grads_in.rgb[3 * p..3 * p + 3]);
        background += g_rgb * state.final_transmittance[p];
        pixels.push(PixelBack {
            back: CompositeBackState::new(&[bg.x, bg.y, bg.z, 0.0, 0.0]),
            d_out: [
                g_rgb.x,
                g_rgb.y,
                g_rgb.z,
                grads_in.alpha.map_or(0.0, |a| a[p]),
                grads_in.depth.map_or(0.0, |d| d[p]),
            ],
        });
    }
    // The tile's blended pairs, grouped by entry by its forward (pixel order within an entry):
    // those of slot `k` are `pairs[starts[k]..starts[k + 1]]`.
    let blended = &state.tiles[tile];
    debug_assert_eq!(blended.order, PairOrder::ByEntry, "the tile was walked by entry");
    debug_assert_eq!(blended.offsets.len(), list.len() + 1, "one group per entry");
    let (starts, pairs): (&[u32], &[EntryPair]) = (&blended.offsets, &blended.entry_pairs);
    // The tile-local rectangle of the pixels of an entry's pairs.
    let pair_rect = |k: usize| {
        let of = &pairs[starts[k] as usize..starts[k + 1] as usize];
        let (first, last) = (of.first()?.y, of.last()?.y);
        let (mut x0, mut x1) = (u8::MAX, 0);
        for pair in of {
            x0 = x0.min(pair.x);
            x1 = x1.max(pair.x);
        }
        Some((x0, first, x1, last))
    };
    // The record of an entry `RECORD_AHEAD` ahead (nearer). The texels of one `L2_AHEAD` ahead
    // (and its gradient row's, when the entry owns it) into the second-level cache, their
    // rectangle kept in a ring, and into the first-level cache `L1_AHEAD` ahead, from the ring.
    // (Fetched into the first level three entries ahead, they were presumably evicted again by
    // the entries in between: this form is 7 % faster, docs/perf.md; the eviction itself was
    // not measured, this host has no cache counters.)
    const RECORD_AHEAD: usize = 8;
    const L2_AHEAD: usize = 6;
    const L1_AHEAD: usize = 1;
    const RING: usize = 8;
    const { assert!(L1_AHEAD < L2_AHEAD && L2_AHEAD - L1_AHEAD < RING) };
    // Slot `k % RING`: entry `k`'s billboard, whether the entry owns its gradient row, and its
    // texel rectangle (none when its footprint is not prefetched).
    let mut footprints: [Option<(usize, bool, TexelRect)>; RING] = [None; RING];
    // Entry `ahead`'s footprint, its lines asked into the second level.
    let fetch_into_l2 = |ahead: usize| {
        let b = list[ahead] as usize;
        let rect = prepared[b].as_ref().and_then(|pa| {
            let pixels = (starts[ahead + 1] - starts[ahead]) as usize;
            pair_rect(ahead).and_then(|r| texel_footprint(pa, r, (i0, j0), ts, pixels))
        })?;
        prefetch_texel_rect_l2(set.texture_of(b).as_ptr(), ts, rect);
        if direct[ahead] {
            prefetch_texel_rect_l2(owned_rows.row_start(b), ts, rect);
        }
        Some((b, direct[ahead], rect))
    };
    // The entries walked before the first `L2_AHEAD` ahead (the last of the list).
    for ahead in (list.len().saturating_sub(L2_AHEAD)..list.len()).rev() {
        footprints[ahead % RING] = fetch_into_l2(ahead);
    }
    // The taps of a chunk of pairs, refilled in place.
    let mut lane_taps = RowTaps::default();
    for k in (0..list.len()).rev() {
        if let Some(ahead) = k.checked_sub(RECORD_AHEAD) {
            prefetch_record(&prepared[list[ahead] as usize]);
        }
        if let Some(ahead) = k.checked_sub(L2_AHEAD) {
            footprints[ahead % RING] = fetch_into_l2(ahead);
        }
        if let Some(ahead) = k.checked_sub(L1_AHEAD)
            && let Some((b, owns, rect)) = footprints[ahead % RING]
        {
            prefetch_texel_rect(set.texture_of(b).as_ptr(), ts, rect);
            if owns {
                prefetch_texel_rect(owned_rows.row_start(b), ts, rect);
            }
        }
        let of = &pairs[starts[k] as usize..starts[k + 1] as usize];
        if of.is_empty() {
            continue;
        }
        let b = list[k] as usize;
        let pr = prepared[b].as_ref().expect("blended entries are prepared");
        let plane = pr.view_plane();
        let texture = set.texture_of(b);
        let record = &mut records[k];
        // Where the entry's texel gradients go: its billboard's gradient row when the entry
        // owns it, else the shared slot of sums (read out below).
        let (cells, flags) = if direct[k] {
            // SAFETY: `owns` holds for entry `range.start + k`, and this task is the only one
            // processing it; the row is reached only through `cells` until the next entry.
            (unsafe { owned_rows.row_mut(b) }, &mut row_flags[..])
        } else {
            sums.slot_mut(0)
        };
        let mut target = TexelTarget { cells, flags };
        for chunk in of.chunks(LANES) {
            // Hits and taps lane-wise (unused lanes repeat the last pair), then the pairs one by
            // one in pixel order.
            #[cfg(target_arch = "x86_64")]
            if WIDE {
                // SAFETY: `WIDE` is only set by `by_entry_avx2`, whose caller checked AVX2 and
                // FMA.
                let lanes = unsafe { chunk_lanes(chunk, (i0, j0)) };
                let (px, py) = (&lanes.px, &lanes.py);
                let hits = intersect_lanes(&pr.transform, &plane, camera, px, py);
                lane_taps.refill::<true>(&hits.u, &hits.v, ts);
                // SAFETY: `WIDE` is only set by `by_entry_avx2`, whose caller checked AVX2 and
                // FMA.
                let g = unsafe {
                    chunk_backward(
                        &lanes,
                        &lane_taps,
                        &hits,
                        texture,
                        pr.rgb,
                        params,
                        pixels,
                        &mut record.rgb,
                        &mut target,
                    )
                };
                record.blended |= g.blended;
                let d_t = intersect_vjp_lanes(&pr.transform, &hits, (px, py), (&g.d_u, &g.d_v, &g.d_depth));
                // SAFETY: as above.
                unsafe { add_lanes_in_order(&mut record.transform, &d_t, chunk.len()) };
                continue;
            }
            let pair_of = |l: usize| &chunk[l.min(chunk.len() - 1)];
            let px: [f32; LANES] = std::array::from_fn(|l| (i0 + u32::from(pair_of(l).x)) as f32 + 0.5);
            let py: [f32; LANES] = std::array::from_fn(|l| (j0 + u32::from(pair_of(l).y)) as f32 + 0.5);
            let hits = intersect_lanes(&pr.transform, &plane, camera, &px, &py);
            lane_taps.refill::<true>(&hits.u, &hits.v, ts);
            // Per pair in pixel order: the compositing backward, then the texel gradients; then
            // the hits' gradients lane-wise, added to the record in pixel order.
            let mut d_depth = [0.0f32; LANES];
            // The samples of the chunk's pairs first, so that their texel reads overlap.
            // (A loop: `array::from_fn` here was compiled out of line, for the baseline.)
            let mut samples: [Option<[f32; 4]>; LANES] = [None; LANES];
            for (lane, sample) in samples.iter_mut().enumerate().take(chunk.len()) {
                *sample = lane_taps.sample_rgba(lane, texture);
            }
            // The compositing backward of the chunk's pairs in pixel order, then their texel
            // gradients in the same order: two loops, each with fewer values live at once (one
            // loop doing both spilled them to the stack), and the texel loop's destination
            // chosen once per chunk. Each sum still receives its terms in the same order.
            let mut d_rgba = [[0.0f32; 4]; LANES];
            let mut has_grad = [false; LANES];
            for (lane, pair) in chunk.iter().enumerate() {
                debug_assert!(hits.valid[lane], "a blended pair hits its billboard");
                let depth = hits.depth[lane];
                let Some([r, g, bl, a]) = samples[lane] else {
                    debug_assert!(false, "a blended pair has taps");
                    continue;
                };
                let Step::Blend(blend) = classify(pair.transmittance, a, params) else {
                    debug_assert!(false, "a replayed entry must blend again");
                    continue;
                };
                let colour = Vec3::new(r, g, bl) + pr.rgb;
                let pixel = &mut pixels[pair.pixel as usize];
                let grad = pixel.back.pop(
                    &blend,
                    &[colour.x, colour.y, colour.z, 1.0, depth],
                    &pixel.d_out,
                    params,
                );
                let [dr, dg, db, _, dz] = grad.d_features;
                d_rgba[lane] = [dr, dg, db, grad.d_alpha];
                has_grad[lane] = true;
                d_depth[lane] = dz;
                record.rgb += Vec3::new(dr, dg, db);
                record.blended = true;
            }
            let (d_u, d_v) = lane_taps.vjp_rgba_lanes(texture, &d_rgba, &has_grad, |texel, g| target.add(texel, g));
            let d_t = intersect_vjp_lanes(&pr.transform, &hits, (&px, &py), (&d_u, &d_v, &d_depth));
            for lane in 0..chunk.len() {
                add_transform(&mut record.transform, &d_t.lane(lane));
            }
        }
        // The texel sums of an entry that does not own its row go to the reduction.
        if !direct[k] {
            record.texels = sums.read_out(0, texels);
        }
    }
    background
}
