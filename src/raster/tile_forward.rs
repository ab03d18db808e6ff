//! The forward pass of one tile, billboard by billboard: every entry of the tile's list, in
//! depth order, is applied to the pixels of its span before the next entry is read.
//!
//! Each pixel keeps its own front-to-back compositing state ([`CompositeState`], the stage's
//! own code) in a per-tile array (about 60 bytes a pixel, 135 KiB for a 48×48 tile, which
//! stays in L2). An entry's record, plane and texture are loaded once for all its pixels, so a
//! pixel walking 20-60 billboards no longer reads 20-60 scattered records and textures; and no
//! per-pixel candidate list is built, stored and read back. Per pixel the entries still arrive
//! front to back (the list order), so every pixel sees exactly the sequence of (alpha, features)
//! the pixel-by-pixel walk gave it: the outputs are the same bit for bit (checksums of
//! `raster_stats` in docs/perf.md, and the raster tests against the brute-force reference).
//!
//! Per (entry, pixel) pair, work stops as soon as the pixel has stopped compositing
//! (transmittance threshold), which the pixel-by-pixel walk also did.

use super::texel_prefetch::TexelPrefetch;
use super::tile_types::{EntryPair, FORWARD_FEATURES, PairOrder, PixelOut, TileBlended, TileInputs};
use crate::stages::bilinear::RowTaps;
use crate::stages::composite::{CompositeState, Step};
use crate::stages::depth_distortion::{DistortionState, mapped_depth};
use crate::stages::ray_plane::{LANES, intersect_lanes, row_centres};
use glam::Vec3;

/// The running state of one pixel while the tile's entries are applied.
#[derive(Clone, Copy, Debug)]
struct PixelState {
    composite: CompositeState<FORWARD_FEATURES>,
    spread: DistortionState,
    median: f32,
    evaluated: u32,
    nan_alpha: u32,
}

impl PixelState {
    const START: Self = Self {
        composite: CompositeState {
            transmittance: 1.0,
            features: [0.0; FORWARD_FEATURES],
            done: false,
        },
        spread: DistortionState {
            s1: 0.0,
            s2: 0.0,
            distortion: 0.0,
        },
        median: 0.0,
        evaluated: 0,
        nan_alpha: 0,
    };
}

/// Reusable per-task scratch of [`composite_tile`] (rebuilt per tile).
#[derive(Default)]
pub(crate) struct TileComposite {
    pixels: Vec<PixelState>,
    /// The states of the AVX2 build ([`super::tile_forward_avx2`]).
    #[cfg(target_arch = "x86_64")]
    lanes: super::tile_forward_avx2::LaneStates,
}

/// Composites the tile `(i0, j0, i1, j1)` whose list is `list` (with the entries' `spans`):
/// writes one [`PixelOut`] per tile-local pixel (row-major over the tile's own width) into
/// `pixels`, the blended pairs into `blended` entry by entry ([`PairOrder::ByEntry`], the
/// order found), and adds `α·T` of each blended pair to `impact[slot]` (in pixel order). With
/// `DISTORTION` the depth distortion of each pixel is accumulated too ([`DistortionState`]);
/// without it that code is not compiled in.
///
/// On a CPU with AVX2 and FMA this runs the explicit vector implementation of
/// [`super::tile_forward_avx2`] (eight pixels of a run side by side; its AVX-512 build where
/// [`crate::cpu::Simd::avx512`] holds); elsewhere, and when
/// [`super::RenderSettings::simd`] is the baseline, the body below, pixel after pixel with the stages'
/// own code, which is the reference the vector one is tested against bit for bit.
pub(crate) fn composite_tile<const DISTORTION: bool>(
    scratch: &mut TileComposite,
    inputs: TileInputs<'_, '_>,
    impact: &mut [f32],
    pixels: &mut Vec<PixelOut>,
    blended: &mut TileBlended,
) {
    #[cfg(target_arch = "x86_64")]
    if inputs.settings.simd.avx2_fma() {
        let lanes = &mut scratch.lanes;
        if inputs.settings.simd.avx512() {
            // SAFETY: the CPU has AVX2, FMA and the AVX-512 subsets (a `Simd` at that level
            // exists only on such a CPU).
            unsafe {
                super::tile_forward_avx2::composite_tile_avx512::<DISTORTION>(lanes, inputs, impact, pixels, blended);
            }
        } else {
            // SAFETY: the CPU has AVX2 and FMA (a `Simd` at that level exists only on such a
            // CPU).
            unsafe {
                super::tile_forward_avx2::composite_tile_avx2::<DISTORTION>(lanes, inputs, impact, pixels, blended);
            }
        }
        return;
    }
    composite_tile_body::<DISTORTION>(scratch, inputs, impact, pixels, blended);
}

/// The body of [`composite_tile`] on the baseline instruction set (the scalar reference).
#[inline(always)]
fn composite_tile_body<const DISTORTION: bool>(
    scratch: &mut TileComposite,
    TileInputs {
        camera,
        set,
        settings,
        prepared,
        list,
        rect: (i0, j0, i1, j1),
        spans,
    }: TileInputs<'_, '_>,
    impact: &mut [f32],
    pixels: &mut Vec<PixelOut>,
    out: &mut TileBlended,
) {
    let params = &settings.composite;
    let ts = set.texture_size;
    let tw = (i1 - i0) as usize;
    let n = tw * (j1 - j0) as usize;
    let states = &mut scratch.pixels;
    states.clear();
    states.resize(n, PixelState::START);
    out.start(PairOrder::ByEntry);
    let TileBlended {
        entry_pairs: blended,
        offsets,
        ..
    } = out;
    // The taps of a chunk of lanes, refilled in place (for sampling only: no derivatives).
    let mut taps = RowTaps::default();
    let mut texel_prefetch = TexelPrefetch::default();
    for (k, (span, &b)) in spans.entries.iter().zip(list).enumerate() {
        offsets.push(blended.len() as u32);
        texel_prefetch.ahead(set, prepared, list, &spans.entries, k, (i0, j0));
        let p = prepared[b as usize].as_ref().expect("binned billboards are prepared");
        let plane = p.view_plane();
        let texture = set.texture_of(b as usize);
        let mut entry_impact = impact[k];
        for (y, &[x0, x1]) in (span.rows[0]..).zip(spans.row_cols(span)) {
            let (x0, x1) = (usize::from(x0), usize::from(x1));
            let py = (j0 + u32::from(y)) as f32 + 0.5;
            let row = y as usize * tw;
            // The span's pixels of this row, `LANES` at a time: hits and taps lane-wise, then
            // sampling and compositing pixel by pixel.
            let mut x = x0;
            while x <= x1 {
                let count = LANES.min(x1 + 1 - x);
                let lanes = row + x..row + x + count;
                x += count;
                if states[lanes.clone()].iter().all(|s| s.composite.done) {
                    continue;
                }
                // In u32: a 64-bit integer's conversion to f32 is a long instruction sequence.
                let first = i0 + (lanes.start - row) as u32;
                let px = row_centres(first);
                let hits = intersect_lanes(&p.transform, &plane, camera, &px, &[py; LANES]);
                taps.refill::<false>(&hits.u, &hits.v, ts);
                // The samples of the chunk's pixels first, so that their texel reads overlap
                // instead of each waiting behind the previous pixel's compositing.
                let mut samples = [None; LANES];
                for (lane, q) in lanes.clone().enumerate() {
                    if !states[q].composite.done && hits.valid[lane] {
                        samples[lane] = taps.sample_rgba(lane, texture);
                    }
                }
                for (lane, q) in lanes.enumerate() {
                    let state = &mut states[q];
                    if state.composite.done {
                        continue;
                    }
                    state.evaluated += 1;
                    let Some([r, g, bl, a]) = samples[lane] else {
                        continue;
                    };
                    let depth = hits.depth[lane];
                    let blend = match state.composite.step(a, params) {
                        Step::Skip => {
                            state.nan_alpha += u32::from(a.is_nan());
                            continue;
                        }
                        Step::Stop => {
                            state.composite.stop();
                            continue;
                        }
                        Step::Blend(blend) => blend,
                    };
                    let c = Vec3::new(r, g, bl) + p.rgb;
                    let nv = p.normal;
                    state
                        .composite
                        .blend(&blend, &[c.x, c.y, c.z, 1.0, depth, nv.x, nv.y, nv.z]);
                    if blend.transmittance > 0.5 && blend.alpha > 0.05 {
                        state.median = depth;
                    }
                    if DISTORTION {
                        state.spread.add(mapped_depth(depth), blend.weight, blend.transmittance);
                    }
                    entry_impact += blend.weight;
                    blended.push(EntryPair {
                        pixel: q as u16,
                        x: (q - row) as u8,
                        y,
                        transmittance: blend.transmittance,
                    });
                }
            }
        }
        impact[k] = entry_impact;
    }
    offsets.push(blended.len() as u32);
    let bg = settings.background;
    pixels.clear();
    for state in states.iter() {
        let distortion = if DISTORTION { state.spread.distortion } else { 0.0 };
        pixels.push(PixelOut::of(
            &state.composite,
            bg,
            state.median,
            (state.evaluated, state.nan_alpha),
            distortion,
        ));
    }
}
