//! The forward pass of one tile, billboard by billboard: every entry of the tile's list, in
//! depth order, is applied to the pixels of its span before the next entry is read.
//!
//! Each pixel keeps its own front-to-back compositing state ([`CompositeState`], the stage's
//! own code) in a small per-tile array (about 60 bytes a pixel, 15 KiB for a 16×16 tile, which
//! stays in L1). An entry's record, plane and texture are loaded once for all its pixels, so a
//! pixel walking 20-60 billboards no longer reads 20-60 scattered records and textures; and no
//! per-pixel candidate list is built, stored and read back. Per pixel the entries still arrive
//! front to back (the list order), so every pixel sees exactly the sequence of (alpha, features)
//! the pixel-by-pixel walk gave it: the outputs are the same bit for bit (checksums of
//! `raster_stats` in docs/perf.md, and the raster tests against the brute-force reference).
//!
//! Per (entry, pixel) pair, work stops as soon as the pixel has stopped compositing
//! (transmittance threshold), which the pixel-by-pixel walk also did.

use super::forward::{EntrySpans, prefetch_record};
use super::preprocess::Prepared;
use super::{ActivatedRef, RenderSettings};
use crate::camera::Camera;
use crate::stages::bilinear;
use crate::stages::composite::{CompositeState, Step};
use crate::stages::depth_distortion::{DistortionState, mapped_depth};
use crate::stages::ray_plane::{intersect_with, pixel_ray};
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
    pub(crate) blended: u32,
    pub(crate) nan_alpha: u32,
    /// The depth-distortion value (0 unless the tile was composited with the distortion).
    pub(crate) distortion: f32,
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
    &'a [EntrySpans],
);

/// Reusable per-task scratch of [`composite_tile`] (rebuilt per tile).
#[derive(Default)]
pub(crate) struct TileComposite {
    rays: Vec<Vec3>,
    pixels: Vec<PixelState>,
    /// Per pixel: the slots it blended, front to back.
    blended: Vec<Vec<u32>>,
}

/// Composites the tile `(i0, j0, i1, j1)` whose list is `list` (with the entries' `spans`):
/// writes one [`PixelOut`] per tile-local pixel (row-major over the tile's own width) into
/// `pixels`, the blended slots of each pixel, pixel after pixel and front to back within a
/// pixel, into `blended_slots`, and adds `α·T` of each blended pair to `impact[slot]` (in pixel
/// order). With `DISTORTION` the depth distortion of each pixel is accumulated too
/// ([`DistortionState`]); without it that code is not compiled in.
pub(crate) fn composite_tile<const DISTORTION: bool>(
    scratch: &mut TileComposite,
    (camera, set, settings, prepared, list, (i0, j0, i1, j1), spans): TileInputs<'_, '_>,
    impact: &mut [f32],
    pixels: &mut Vec<PixelOut>,
    blended_slots: &mut Vec<u32>,
) {
    let params = &settings.composite;
    let ts = set.texture_size;
    let tw = (i1 - i0) as usize;
    let n = tw * (j1 - j0) as usize;
    let TileComposite {
        rays,
        pixels: states,
        blended,
    } = scratch;
    rays.clear();
    for j in j0..j1 {
        for i in i0..i1 {
            rays.push(pixel_ray(camera, i as f32 + 0.5, j as f32 + 0.5));
        }
    }
    states.clear();
    states.resize(n, PixelState::START);
    if blended.len() < n {
        blended.resize_with(n, Vec::new);
    }
    for slots in &mut blended[..n] {
        slots.clear();
    }
    for (k, (span, &b)) in spans.iter().zip(list).enumerate() {
        if let Some(&ahead) = list.get(k + 4) {
            prefetch_record(&prepared[ahead as usize]);
        }
        let p = prepared[b as usize].as_ref().expect("binned billboards are prepared");
        let plane = p.view_plane();
        let texture = set.texture_of(b as usize);
        let mut entry_impact = impact[k];
        for y in span.rows[0]..=span.rows[1] {
            let [x0, x1] = span.cols[y as usize];
            let py = (j0 + u32::from(y)) as f32 + 0.5;
            for x in x0..=x1 {
                let q = y as usize * tw + x as usize;
                let state = &mut states[q];
                if state.composite.done {
                    continue;
                }
                state.evaluated += 1;
                let px = (i0 + u32::from(x)) as f32 + 0.5;
                let ray = rays[q];
                // Hit depths by the plane equation (see `ViewPlane`), as the backward takes them.
                let Some(hit) = intersect_with(&p.transform, px, py, |_, _| plane.depth(ray)) else {
                    continue;
                };
                let Some(taps) = bilinear::taps(hit.u, hit.v, ts) else {
                    continue;
                };
                // Only the taps and weights are used (sampling needs no derivatives).
                let [r, g, bl, a] = taps.for_sampling().sample_rgba(texture);
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
                    .blend(&blend, &[c.x, c.y, c.z, 1.0, hit.depth, nv.x, nv.y, nv.z]);
                if blend.transmittance > 0.5 && blend.alpha > 0.05 {
                    state.median = hit.depth;
                }
                if DISTORTION {
                    state
                        .spread
                        .add(mapped_depth(hit.depth), blend.weight, blend.transmittance);
                }
                entry_impact += blend.weight;
                blended[q].push(k as u32);
            }
        }
        impact[k] = entry_impact;
    }
    let bg = settings.background;
    pixels.clear();
    blended_slots.clear();
    for (state, slots) in states.iter().zip(&blended[..n]) {
        let [r, g, b, alpha, depth, nx, ny, nz] = state.composite.finish(&[bg.x, bg.y, bg.z, 0.0, 0.0, 0.0, 0.0, 0.0]);
        pixels.push(PixelOut {
            rgb: Vec3::new(r, g, b),
            alpha,
            depth,
            median: state.median,
            normal: Vec3::new(nx, ny, nz),
            final_t: state.composite.transmittance,
            evaluated: state.evaluated,
            blended: slots.len() as u32,
            nan_alpha: state.nan_alpha,
            distortion: if DISTORTION { state.spread.distortion } else { 0.0 },
        });
        blended_slots.extend_from_slice(slots);
    }
}
