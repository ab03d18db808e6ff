//! The forward pass of one tile, pixel by pixel: the path for tiles of small billboards.
//!
//! Where most entries of a tile cover a pixel or two (dense views of small billboards, such as
//! the 256²/50k benchmark scene), the billboard-by-billboard pass ([`super::tile_forward`])
//! spends more on each entry's set-up than on its pixels. This path samples every (pixel,
//! entry) pair of the tile entry by entry into per-pixel lists, issuing the texel reads of a
//! run of pairs ahead of their use (so that their cache misses overlap), then composites each
//! pixel over its list front to back with the compositing stage's own code. Same values, bit
//! for bit, as the billboard-by-billboard pass (the per-pixel sequence of alphas and features is
//! the same); the choice is made per tile ([`composite_tile`](super::tile_forward::composite_tile))
//! and tested in `tests/suite/raster_lanes.rs`.

use super::candidates::CANDIDATE_CHUNK;
use super::input::{ActivatedRef, RenderSettings};
use super::prefetch::{prefetch_record, prefetch_taps};
use super::preprocess::Prepared;
use super::tile_spans::TileSpans;
use super::tile_types::{FORWARD_FEATURES, PairOrder, PixelOut, TileBlended, TileInputs};
use crate::camera::Camera;
use crate::memory::resize_for_overwrite;
use crate::stages::bilinear::{self, SampleTaps};
use crate::stages::composite::{CompositeState, Step};
use crate::stages::depth_distortion::{DistortionState, mapped_depth};
use crate::stages::ray_plane::{intersect_with, pixel_ray};
use glam::Vec3;

/// Reusable per-task scratch of [`composite_tile_by_pixel`] (rebuilt per tile).
#[derive(Default)]
pub(crate) struct PixelWalk {
    lists: PixelLists,
    samples: TileSamples,
}

/// The tile of `inputs` composited pixel by pixel: the outputs of
/// [`composite_tile`](super::tile_forward::composite_tile), bit for bit, except that the
/// blended pairs are grouped pixel by pixel ([`PairOrder::ByPixel`]).
pub(crate) fn composite_tile_by_pixel<const DISTORTION: bool>(
    scratch: &mut PixelWalk,
    TileInputs {
        camera,
        set,
        settings,
        prepared,
        list,
        rect: rect @ (i0, j0, i1, j1),
        spans,
    }: TileInputs<'_, '_>,
    impact: &mut [f32],
    pixels: &mut Vec<PixelOut>,
    blended: &mut TileBlended,
) {
    let tw = (i1 - i0) as usize;
    let n_q = tw * (j1 - j0) as usize;
    let PixelWalk { lists, samples } = scratch;
    lists.build(spans, tw, (j1 - j0) as usize);
    samples.build(camera, set, prepared, list, rect, spans, lists);
    pixels.clear();
    blended.start(PairOrder::ByPixel);
    let TileBlended {
        slots,
        transmittance,
        offsets,
        ..
    } = blended;
    offsets.push(0);
    for q in 0..n_q {
        pixels.push(shade_pixel::<DISTORTION>(
            settings,
            &samples.entry_features,
            lists.of(q),
            samples.of(lists, q),
            impact,
            (&mut *slots, &mut *transmittance),
        ));
        offsets.push(slots.len() as u32);
    }
}

/// Composites one pixel of a tile over its sampled candidates (see [`TileSamples`]) with the
/// compositing stage ([`CompositeState`]: the clamp, skip and stop decisions and the weighted
/// sums are the stage's own code, the code its property tests prove); adds `α·T` of each
/// blended entry to `impact` and appends its slot to `blended_slots`. `entry_features` holds
/// each tile entry's colour and normal ([`TileSamples::entry_features`]); `own` is the pixel's
/// entry list (for the work counters). With `DISTORTION` the pixel's depth distortion
/// ([`DistortionState`]) is accumulated too; without it (the default render) that code is not
/// compiled in.
#[inline]
#[allow(clippy::too_many_arguments)]
fn shade_pixel<const DISTORTION: bool>(
    settings: &RenderSettings,
    entry_features: &[[Vec3; 2]],
    own: &[u32],
    candidates: &[SampledCandidate],
    impact: &mut [f32],
    (blended_slots, blended_transmittance): (&mut Vec<u32>, &mut Vec<f32>),
) -> PixelOut {
    let params = &settings.composite;
    let mut state = CompositeState::<FORWARD_FEATURES>::new();
    let mut spread = DistortionState::default();
    let mut median = 0.0;
    let mut evaluated = own.len() as u32;
    let mut nan_alpha = 0;
    for cand in candidates {
        let k = cand.slot as usize;
        let [r, g, bl, a] = cand.rgba;
        let blend = match state.step(a, params) {
            Step::Skip => {
                nan_alpha += u32::from(a.is_nan());
                continue;
            }
            Step::Stop => {
                // The entries up to and including this one were evaluated.
                evaluated = own.partition_point(|&x| x as usize <= k) as u32;
                state.stop();
                break;
            }
            Step::Blend(blend) => blend,
        };
        let [rgb, n] = entry_features[k];
        let c = Vec3::new(r, g, bl) + rgb;
        state.blend(&blend, &[c.x, c.y, c.z, 1.0, cand.depth, n.x, n.y, n.z]);
        if blend.transmittance > 0.5 && blend.alpha > 0.05 {
            median = cand.depth;
        }
        if DISTORTION {
            spread.add(mapped_depth(cand.depth), blend.weight, blend.transmittance);
        }
        impact[k] += blend.weight;
        blended_slots.push(k as u32);
        blended_transmittance.push(blend.transmittance);
    }
    let distortion = if DISTORTION { spread.distortion } else { 0.0 };
    PixelOut::of(&state, settings.background, median, (evaluated, nan_alpha), distortion)
}

/// One (pixel, entry) pair of a tile whose ray hits the billboard's texture support, sampled:
/// the entry's slot in the tile list, the view depth of the hit and the bilinear RGBA sample.
#[derive(Clone, Copy)]
pub(crate) struct SampledCandidate {
    slot: u32,
    depth: f32,
    rgba: [f32; 4],
}

/// The sampled candidates of every pixel of a tile, computed entry by entry: each billboard's
/// record, plane and texture are loaded once for all the pixels of its span (its texels stay in
/// L1 while its pixels are sampled), instead of once per pixel as a pixel-by-pixel walk over 10-60
/// billboards would. Per pixel the candidates come out in tile-list (depth) order, since the
/// entries are visited in that order. Same arithmetic per pair as [`TileCandidates`](super::candidates::TileCandidates) followed by
/// [`BilinearTaps::sample_rgba`](bilinear::BilinearTaps::sample_rgba) (whose [`SampleTaps`] part it keeps), so the forward pass's outputs are unchanged bit for bit.
/// The candidates of tile-local pixel `q` are `items[offsets[q]..ends[q]]`.
#[derive(Default)]
pub(crate) struct TileSamples {
    rays: Vec<Vec3>,
    ends: Vec<u32>,
    /// Per tile entry (its slot): its record's SH colour and normal, `[rgb, normal]`, copied
    /// while the record is at hand, so that compositing reads them from one small table rather
    /// than from records scattered over the prepared array (a 48-px tile of small billboards
    /// lists a thousand of them, more than the L1 cache holds).
    entry_features: Vec<[Vec3; 2]>,
    items: Vec<SampledCandidate>,
    /// Candidates whose texels are being prefetched: (item, billboard, taps), sampled in runs of
    /// [`CANDIDATE_CHUNK`] (see [`TileCandidates`](super::candidates::TileCandidates) for why the reads are issued ahead).
    pending: Vec<(u32, u32, SampleTaps)>,
}

impl TileSamples {
    /// Samples every (pixel, entry) pair of the tile `(i0, j0, i1, j1)` whose pixel lies in the
    /// entry's span, into room reserved per pixel by `lists` (one slot per pair of its list).
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn build(
        &mut self,
        camera: &Camera,
        set: &ActivatedRef<'_>,
        prepared: &[Option<Prepared>],
        list: &[u32],
        (i0, j0, i1, j1): (u32, u32, u32, u32),
        spans: &TileSpans,
        lists: &PixelLists,
    ) {
        let ts = set.texture_size;
        let tw = (i1 - i0) as usize;
        let n = tw * (j1 - j0) as usize;
        self.rays.clear();
        for j in j0..j1 {
            for i in i0..i1 {
                self.rays.push(pixel_ray(camera, i as f32 + 0.5, j as f32 + 0.5));
            }
        }
        self.ends.clear();
        self.ends.extend_from_slice(&lists.offsets[..n]);
        let pairs = lists.offsets[n] as usize;
        resize_for_overwrite(
            &mut self.items,
            pairs,
            SampledCandidate {
                slot: 0,
                depth: 0.0,
                rgba: [0.0; 4],
            },
        );
        self.entry_features.clear();
        for (k, (span, &b)) in spans.entries.iter().zip(list).enumerate() {
            if let Some(&ahead) = list.get(k + 4) {
                prefetch_record(&prepared[ahead as usize]);
            }
            let Some(p) = prepared[b as usize].as_ref() else {
                // Never read (an entry without a record has no candidate).
                self.entry_features.push([Vec3::ZERO; 2]);
                continue;
            };
            self.entry_features.push([p.rgb, p.normal]);
            let plane = p.view_plane();
            let texture = set.texture_of(b as usize);
            for (y, &[x0, x1]) in (span.rows[0]..).zip(spans.row_cols(span)) {
                let py = (j0 + u32::from(y)) as f32 + 0.5;
                for x in x0..=x1 {
                    let q = y as usize * tw + x as usize;
                    let px = (i0 + u32::from(x)) as f32 + 0.5;
                    let ray = self.rays[q];
                    let Some(hit) = intersect_with(&p.transform, px, py, |_, _| plane.depth(ray)) else {
                        continue;
                    };
                    let Some(taps) = bilinear::taps(hit.u, hit.v, ts) else {
                        continue;
                    };
                    // Only the taps and weights are kept (sampling needs no derivatives).
                    let taps = taps.for_sampling();
                    prefetch_taps(texture.as_ptr(), taps.indices());
                    let end = &mut self.ends[q];
                    self.items[*end as usize] = SampledCandidate {
                        slot: k as u32,
                        depth: hit.depth,
                        rgba: [0.0; 4],
                    };
                    self.pending.push((*end, b, taps));
                    *end += 1;
                }
            }
            if self.pending.len() >= CANDIDATE_CHUNK {
                self.sample_pending(set);
            }
        }
        self.sample_pending(set);
    }

    /// Samples the pending candidates (their texels were prefetched when they were found).
    fn sample_pending(&mut self, set: &ActivatedRef<'_>) {
        for (item, b, taps) in self.pending.drain(..) {
            self.items[item as usize].rgba = taps.sample_rgba(set.texture_of(b as usize));
        }
    }

    /// The sampled candidates of tile-local pixel `q`, front to back.
    #[inline]
    pub(crate) fn of(&self, lists: &PixelLists, q: usize) -> &[SampledCandidate] {
        &self.items[lists.offsets[q] as usize..self.ends[q] as usize]
    }
}

/// Per-pixel entry lists of one tile (per-pixel culling): the entries of tile-local pixel `q`
/// (row-major over the tile's own width, as [`TileCandidates`](super::candidates::TileCandidates) numbers them) are
/// `items[offsets[q]..offsets[q + 1]]`, in tile-list (depth) order. Built by a counting sort over
/// the entries' spans, `O(entries + pairs)`, so that a pixel visits only the billboards whose
/// span contains it.
#[derive(Default)]
pub(crate) struct PixelLists {
    pub(crate) offsets: Vec<u32>,
    pub(crate) items: Vec<u32>,
    /// Write cursors of [`PixelLists::build`].
    cursor: Vec<u32>,
}

impl PixelLists {
    /// The lists of a tile `width × height` pixels whose entries have the given spans (every
    /// span inside the tile: the pixel boxes are clipped to the image).
    pub(crate) fn build(&mut self, spans: &TileSpans, width: usize, height: usize) {
        let pixels = width * height;
        self.offsets.clear();
        self.offsets.resize(pixels + 1, 0);
        for e in &spans.entries {
            for (y, &[x0, x1]) in (e.rows[0]..).zip(spans.row_cols(e)) {
                debug_assert!((y as usize) < height && (x1 < x0 || (x1 as usize) < width));
                for x in x0..=x1 {
                    self.offsets[y as usize * width + x as usize + 1] += 1;
                }
            }
        }
        for p in 0..pixels {
            self.offsets[p + 1] += self.offsets[p];
        }
        self.items.clear();
        self.items.resize(self.offsets[pixels] as usize, 0);
        let cursor = &mut self.cursor;
        cursor.clear();
        cursor.extend_from_slice(&self.offsets[..pixels]);
        for (k, e) in spans.entries.iter().enumerate() {
            for (y, &[x0, x1]) in (e.rows[0]..).zip(spans.row_cols(e)) {
                for x in x0..=x1 {
                    let p = y as usize * width + x as usize;
                    self.items[cursor[p] as usize] = k as u32;
                    cursor[p] += 1;
                }
            }
        }
    }

    /// The entries of tile-local pixel `q`.
    #[inline]
    pub(crate) fn of(&self, q: usize) -> &[u32] {
        &self.items[self.offsets[q] as usize..self.offsets[q + 1] as usize]
    }
}
