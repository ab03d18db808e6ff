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

use super::forward::{EntryPair, PairOrder, TileBlended};
use super::input::{ActivatedRef, RenderSettings};
use super::prefetch::{prefetch_ptr, prefetch_ptr_l2, prefetch_record};
use super::preprocess::Prepared;
use super::tile_spans::{EntrySpans, TileSpans};
use crate::camera::Camera;
use crate::stages::bilinear::RowTaps;
use crate::stages::composite::{CompositeState, Step};
use crate::stages::depth_distortion::{DistortionState, mapped_depth};
use crate::stages::ray_plane::{LANES, intersect_lanes, row_centres};
use glam::Vec3;

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

/// What [`composite_tile`] reads: the camera, the set, the settings, the prepared records, the
/// tile's list, its pixel rectangle `(i0, j0, i1, j1)` (exclusive ends) and its entries' spans.
pub(crate) type TileInputs<'a, 's> = (
    &'a Camera,
    &'a ActivatedRef<'s>,
    &'a RenderSettings,
    &'a [Option<Prepared>],
    &'a [u32],
    (u32, u32, u32, u32),
    &'a TileSpans,
);

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
/// the CPU has that, see [`super::lanes::avx512_lanes`]); elsewhere, and when
/// [`super::lanes::force_baseline`] is on, the body below, pixel after pixel with the stages'
/// own code, which is the reference the vector one is tested against bit for bit.
pub(crate) fn composite_tile<const DISTORTION: bool>(
    scratch: &mut TileComposite,
    inputs: TileInputs<'_, '_>,
    impact: &mut [f32],
    pixels: &mut Vec<PixelOut>,
    blended: &mut TileBlended,
) {
    #[cfg(target_arch = "x86_64")]
    if super::lanes::wide_lanes() {
        let lanes = &mut scratch.lanes;
        if super::lanes::avx512_lanes() {
            // SAFETY: the CPU has AVX2, FMA and the AVX-512 subsets (checked at run time by
            // `avx512_lanes`).
            unsafe {
                super::tile_forward_avx2::composite_tile_avx512::<DISTORTION>(lanes, inputs, impact, pixels, blended);
            }
        } else {
            // SAFETY: the CPU has AVX2 and FMA (checked at run time by `wide_lanes`).
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
    (camera, set, settings, prepared, list, (i0, j0, i1, j1), spans): TileInputs<'_, '_>,
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

/// A texel rectangle `(c0, r0, c1, r1)` (inclusive columns and rows) of a `ts × ts` texture.
pub(crate) type TexelRect = (usize, usize, usize, usize);

/// The texel prefetches of the forward tile loops: before entry `k` of a tile, the texels of
/// the entry [`Self::L2_AHEAD`] ahead into the second-level cache, and those of the next entry
/// into the first level, from the rectangle found then (kept in a ring). Texels fetched into
/// the first level six entries ahead were presumably evicted again by the entries in between
/// (this form is 7 % faster, docs/perf.md; the eviction itself was not measured). No effect
/// on values.
#[derive(Default)]
pub(crate) struct TexelPrefetch {
    /// Slot `k % RING`: entry `k`'s billboard and texel rectangle (none when not prefetched).
    footprints: [Option<(usize, TexelRect)>; Self::RING],
}

impl TexelPrefetch {
    const L2_AHEAD: usize = 6;
    const RING: usize = 8;

    /// The prefetches before entry `k` of a tile at `(i0, j0)` with list `list` and spans
    /// `spans` (`k` from 0 up, in order; a new tile starts at `k = 0`): the record of the
    /// entry 12 ahead, the texels of the one [`Self::L2_AHEAD`] ahead into the second level
    /// (and at `k = 0` those of the entries before it), and those of entry `k + 1` into the
    /// first level.
    #[inline(always)]
    pub(crate) fn ahead(
        &mut self,
        set: &ActivatedRef<'_>,
        prepared: &[Option<Prepared>],
        list: &[u32],
        spans: &[EntrySpans],
        k: usize,
        (i0, j0): (u32, u32),
    ) {
        const { assert!(Self::L2_AHEAD < Self::RING, "the ring holds the entries in flight") };
        let ts = set.texture_size;
        if let Some(&ahead) = list.get(k + 12) {
            prefetch_record(&prepared[ahead as usize]);
        }
        let footprint = |e: usize| {
            let (&b, span) = (list.get(e)?, spans.get(e)?);
            let pa = prepared[b as usize].as_ref()?;
            let rect = span_rect(span).and_then(|r| texel_footprint(pa, r, (i0, j0), ts, usize::from(span.pixels)))?;
            prefetch_texel_rect_l2(set.texture_of(b as usize).as_ptr(), ts, rect);
            Some((b as usize, rect))
        };
        let first = if k == 0 { 1 } else { k + Self::L2_AHEAD };
        for e in first..=k + Self::L2_AHEAD {
            self.footprints[e % Self::RING] = footprint(e);
        }
        if let Some((b, rect)) = self.footprints[(k + 1) % Self::RING] {
            prefetch_texel_rect(set.texture_of(b).as_ptr(), ts, rect);
        }
    }
}

/// The tile-local pixel rectangle `(x0, y0, x1, y1)` (inclusive) holding an entry's span, or
/// `None` when the span is empty.
fn span_rect(span: &EntrySpans) -> Option<(u8, u8, u8, u8)> {
    let ([x0, x1], [y0, y1]) = (span.columns, span.rows);
    (x0 <= x1).then_some((x0, y0, x1, y1))
}

/// The texel rectangle `(c0, r0, c1, r1)` (inclusive) that the pixels of the tile-local
/// rectangle `(x0, y0, x1, y1)` of the tile at `(i0, j0)` read from the texture of `p`: the
/// rectangle of the plane coordinates of its corners (a projective map sends the rectangle into
/// the hull of its corners' images while the plane stays in front of the camera), widened by
/// the second tap. For prefetches only: a wrong rectangle only wastes them. `None` when a
/// corner has no finite plane coordinates, or when the rectangle holds more than
/// [`FOOTPRINT_TEXELS_PER_PIXEL`] texels per sampling pixel (`pixels` of them): a billboard a
/// few pixels wide has a footprint of the whole texture of which its pixels read a few texels,
/// and fetching all of it costs more than the misses it saves.
pub(crate) fn texel_footprint(
    p: &Prepared,
    (x0, y0, x1, y1): (u8, u8, u8, u8),
    (i0, j0): (u32, u32),
    ts: usize,
    pixels: usize,
) -> Option<TexelRect> {
    let t = &p.transform;
    let (mut u_lo, mut u_hi, mut v_lo, mut v_hi) = (f32::INFINITY, f32::NEG_INFINITY, f32::INFINITY, f32::NEG_INFINITY);
    // One corner when the rectangle is a single pixel (the common case of small billboards).
    let corners = if (x0, y0) == (x1, y1) { 1 } else { 4 };
    for (x, y) in [(x0, y0), (x1, y0), (x0, y1), (x1, y1)].into_iter().take(corners) {
        let px = (i0 + u32::from(x)) as f32 + 0.5;
        let py = (j0 + u32::from(y)) as f32 + 0.5;
        let h = (px * t.tw - t.tu).cross(py * t.tw - t.tv);
        let (u, v) = (h.x / h.z, h.y / h.z);
        u_lo = u_lo.min(u);
        u_hi = u_hi.max(u);
        v_lo = v_lo.min(v);
        v_hi = v_hi.max(v);
    }
    if !(u_lo.is_finite() && u_hi.is_finite() && v_lo.is_finite() && v_hi.is_finite()) {
        return None;
    }
    let last = (ts - 1) as f32;
    let texel = |c: f32| (((c.clamp(-1.0, 1.0) + 1.0) * 0.5 * last) as usize).min(ts - 1);
    let (c0, r0) = (texel(u_lo), texel(v_lo));
    let (c1, r1) = ((texel(u_hi) + 1).min(ts - 1), (texel(v_hi) + 1).min(ts - 1));
    ((c1 - c0 + 1) * (r1 - r0 + 1) <= FOOTPRINT_TEXELS_PER_PIXEL * pixels).then_some((c0, r0, c1, r1))
}

/// See [`texel_footprint`]: a bilinear sample reads 4 texels, so 8 per pixel allows for the
/// rectangle's slack around the pixels' samples.
pub(crate) const FOOTPRINT_TEXELS_PER_PIXEL: usize = 8;

/// Hints the CPU to fetch the cache lines of the texel rectangle `(c0, r0, c1, r1)` of a
/// row-major `ts × ts` per-texel array starting at `texels` (a texture, a gradient row, a cell
/// index). `texels` is never dereferenced.
#[inline]
pub(crate) fn prefetch_texel_rect<T>(texels: *const T, ts: usize, rect: TexelRect) {
    prefetch_rect_with(texels, ts, rect, prefetch_ptr);
}

/// [`prefetch_texel_rect`] into the second-level cache only ([`prefetch_ptr_l2`]).
#[inline]
pub(crate) fn prefetch_texel_rect_l2<T>(texels: *const T, ts: usize, rect: TexelRect) {
    prefetch_rect_with(texels, ts, rect, prefetch_ptr_l2);
}

/// `prefetch` on the first byte of every cache line of the rectangle (see
/// [`prefetch_texel_rect`]).
#[inline(always)]
fn prefetch_rect_with<T>(texels: *const T, ts: usize, (c0, r0, c1, r1): TexelRect, prefetch: fn(*const u8)) {
    let per_line = (64 / size_of::<T>().max(1)).max(1);
    for r in r0..=r1 {
        let row = texels.wrapping_add(r * ts);
        let mut c = c0;
        while c <= c1 {
            prefetch(row.wrapping_add(c).cast::<u8>());
            c += per_line;
        }
        prefetch(row.wrapping_add(c1).cast::<u8>());
    }
}
