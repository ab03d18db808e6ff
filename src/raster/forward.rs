//! Tiled forward pass: front-to-back compositing of every pixel over its tile's list.

use super::binning::{BinScratch, TILE_SIZE, TileBins, bin_into, tile_pixels};
use super::input::{ActivatedRef, RenderSettings};
use super::prefetch::prefetch_taps;
use super::preprocess::{Prepared, preprocess_into};
use super::row_spans::BillboardRows;
use super::schedule::{map_heaviest_first, split_by_lengths};
use super::tile_forward::{TileComposite, composite_tile};
use super::tile_forward_pixels::{PixelWalk, composite_tile_by_pixel};
use super::tile_spans::{TileSpans, local_spans};
use super::tile_types::PixelOut;
use crate::camera::Camera;
use crate::memory::{refill, resize_for_overwrite};
use crate::stages::bilinear::{self, BilinearTaps};
use crate::stages::ray_plane::{intersect_with, pixel_ray};
use rayon::prelude::*;

// The forward's two size thresholds, defined where they are used (the tile-walk choice, the
// rows of a wide box), also at their paths here.
pub use super::lanes::SMALL_ENTRY_PIXELS;
pub use super::row_spans::QUAD_MIN_COLUMNS;
// The tile types of the forward's output, at their paths here too.
pub use super::tile_types::{PairOrder, TileBlended};

/// Everything the backward pass needs from the forward pass.
#[derive(Clone, Debug)]
pub struct ForwardState {
    /// The camera that was rendered.
    pub camera: Camera,
    /// The settings of the render.
    pub settings: RenderSettings,
    /// Per billboard: its prepared data, `None` when culled.
    pub prepared: Vec<Option<Prepared>>,
    /// Tile lists.
    pub bins: TileBins,
    /// Per pixel: transmittance left after the last blended billboard.
    pub final_transmittance: Vec<f32>,
    /// Per tile (the index of [`TileBins::tile_range`]): the entries its pixels blended
    /// ([`TileBlended`]). Kept where each tile's task wrote them, so that the backward pass
    /// reads them without a copy into one image-wide list.
    pub tiles: Vec<TileBlended>,
    /// The forward pass's temporaries, kept for [`RenderOutput::into_buffers`].
    pub(crate) spare: ForwardSpare,
}

/// The images and per-billboard statistics of a render.
#[derive(Clone, Debug)]
pub struct RenderOutput {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Colour, interleaved RGB row-major: `Σ c·α·T + T_final·background`. Not clamped.
    pub rgb: Vec<f32>,
    /// Accumulated opacity `1 − T_final` per pixel (computed as `Σ α·T`).
    pub alpha: Vec<f32>,
    /// Alpha-weighted depth `Σ α·T·z` per pixel, z the view depth of the hit. Divide by
    /// [`RenderOutput::alpha`] for the expected depth of the visible surface.
    pub depth: Vec<f32>,
    /// Median depth per pixel: view depth of the last blended hit with `T > 0.5` before it and
    /// `α > 0.05` (the reference's rule); 0 where there is none. Not differentiable.
    pub median_depth: Vec<f32>,
    /// Alpha-weighted view-space normal `Σ α·T·n`, interleaved xyz, normals facing the camera.
    pub normal: Vec<f32>,
    /// Depth-distortion map per pixel ([`crate::stages::depth_distortion`]) when
    /// [`RenderSettings::distortion`] asked for it; empty otherwise.
    pub distortion: Vec<f32>,
    /// Per billboard: `Σ α·T` over all pixels of this view (the "impact"); 0 when culled.
    pub impact: Vec<f32>,
    /// Per billboard: true when it was not culled by preprocessing (it touches the screen).
    pub visible: Vec<bool>,
    /// Work counters of this render.
    pub stats: RenderStats,
    /// What the backward pass needs.
    pub state: ForwardState,
}

/// Work counters of one render, for performance reports.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RenderStats {
    /// (tile, billboard) entries after binning.
    pub tile_entries: u64,
    /// (pixel, billboard) pairs whose ray-plane intersection was evaluated (the pixel centre was
    /// inside the billboard's screen box and, for billboards with a support quad, inside its
    /// row span).
    pub evaluated_pairs: u64,
    /// (pixel, billboard) pairs that were blended.
    pub blended_pairs: u64,
    /// Billboards with a non-finite position, log-scale or quaternion component: culled (they
    /// have no place on screen), and counted here so that a caller can tell them from billboards
    /// that are merely out of view. Non-finite SH coefficients or colour texels are not counted:
    /// they make the pixels the billboard covers NaN.
    pub non_finite_billboards: u64,
    /// (pixel, billboard) pairs whose sampled alpha was NaN: skipped, as the compositing stage
    /// skips NaN alphas, and counted here.
    pub nan_alpha_pairs: u64,
}

/// One (pixel, entry) pair of a tile whose ray hits the billboard's texture support: the entry's
/// slot in the tile list, the view depth of the hit and the bilinear taps.
#[derive(Clone, Copy)]
pub(crate) struct Candidate {
    pub(crate) slot: u32,
    pub(crate) depth: f32,
    pub(crate) taps: BilinearTaps,
}

/// The candidates of a run of pixels of a tile (the backward pass's walk; the forward pass samples
/// entry by entry, [`TileSamples`](super::tile_forward_pixels::TileSamples)), computed before they are used so that
/// the texels they read can be prefetched: the texture reads are scattered over the whole texture
/// arrays (one random cache line per tap row and channel), and issuing them up front lets the
/// misses overlap instead of stalling the compositing loop one at a time. A run is cut once it
/// holds [`CANDIDATE_CHUNK`] candidates, so that the prefetched lines are still in cache when
/// they are read, whatever the overlap per pixel. The candidates of tile-local pixel `q`
/// (row-major over the tile's own width) are `items[offsets[q - first]..offsets[q - first + 1]]`,
/// in list (depth) order. Same arithmetic as evaluating them inside the compositing loop.
#[derive(Default)]
pub(crate) struct TileCandidates {
    first: usize,
    offsets: Vec<u32>,
    items: Vec<Candidate>,
}

/// Candidates per run of [`TileCandidates`]: 256 candidates prefetch at most 4096 lines
/// (256 KiB), which stay in a 512 KiB L2 until they are composited.
pub(crate) const CANDIDATE_CHUNK: usize = 256;

impl TileCandidates {
    /// Fills the candidates of the tile-local pixels `first..` of the tile `(i0, j0, i1, j1)`,
    /// stopping after the pixel that brings the run to [`CANDIDATE_CHUNK`] candidates or at the
    /// tile's end; returns the end of the run (exclusive). Pixel `q` considers the tile-list
    /// slots `slots(q)`, in order. `also(slot, taps)` is called for every candidate, where its
    /// texels are prefetched (the backward pass prefetches gradient rows there; it must not
    /// change any value).
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn build<'a>(
        &mut self,
        camera: &Camera,
        set: &ActivatedRef<'_>,
        prepared: &[Option<Prepared>],
        list: &[u32],
        (i0, j0, i1, j1): (u32, u32, u32, u32),
        first: usize,
        slots: impl Fn(usize) -> &'a [u32],
        also: impl Fn(u32, &BilinearTaps),
    ) -> usize {
        let ts = set.texture_size;
        let tw = (i1 - i0) as usize;
        let n = tw * (j1 - j0) as usize;
        self.first = first;
        self.offsets.clear();
        self.items.clear();
        self.offsets.push(0);
        let mut q = first;
        // The pixel of `q`, advanced row-major (no division per pixel).
        let (mut i, mut j) = (i0 + (first % tw) as u32, j0 + (first / tw) as u32);
        while q < n && self.items.len() < CANDIDATE_CHUNK {
            let (px, py) = (i as f32 + 0.5, j as f32 + 0.5);
            let ray = pixel_ray(camera, px, py);
            for &k in slots(q) {
                let b = list[k as usize] as usize;
                let Some(p) = prepared[b].as_ref() else {
                    continue;
                };
                // Hit depths by the plane equation (see `ViewPlane`), as the backward's near-plane
                // test takes them.
                let plane = p.view_plane();
                let Some(hit) = intersect_with(&p.transform, px, py, |_, _| plane.depth(ray)) else {
                    continue;
                };
                let Some(taps) = bilinear::taps(hit.u, hit.v, ts) else {
                    continue;
                };
                // One 16-byte RGBA texel per tap: the two taps of a row share a cache line unless
                // they straddle a 64-byte boundary (one row pair in four).
                prefetch_taps(set.texture_of(b).as_ptr(), taps.indices());
                also(k, &taps);
                self.items.push(Candidate {
                    slot: k,
                    depth: hit.depth,
                    taps,
                });
            }
            self.offsets.push(self.items.len() as u32);
            q += 1;
            i += 1;
            if i == i1 {
                (i, j) = (i0, j + 1);
            }
        }
        q
    }

    /// The candidates of tile-local pixel `q` (within the last run built).
    #[inline]
    pub(crate) fn of(&self, q: usize) -> &[Candidate] {
        let r = q - self.first;
        &self.items[self.offsets[r] as usize..self.offsets[r + 1] as usize]
    }
}

/// Reusable per-task scratch of the forward tile pass (every field is rebuilt per tile).
#[derive(Default)]
struct TileScratch {
    spans: TileSpans,
    composite: TileComposite,
    walk: PixelWalk,
}

/// Renders the billboards seen by `camera`.
///
/// Deterministic: the same inputs give bit-identical outputs for any number of rayon threads.
/// Allocates every buffer afresh; a caller rendering many views should recycle them with
/// [`render_with`].
///
/// # Panics
/// When the slices of `set` have inconsistent lengths (see [`ActivatedRef::assert_consistent`]).
pub fn render(set: &ActivatedRef<'_>, camera: &Camera, settings: &RenderSettings) -> RenderOutput {
    render_with(set, camera, settings, RenderBuffers::default())
}

/// The storage of a [`RenderOutput`] and of the forward pass's temporaries, handed back by
/// [`RenderOutput::into_buffers`] for the next [`render_with`] call.
///
/// Holds no result: every value a render produces is written afresh, so recycling changes no
/// bit of any output (tested). What it saves is fresh allocations: the per-billboard records,
/// tile lists and images of a render are several megabytes, and whether the allocator keeps
/// freed memory between calls or returns it to the kernel (a page fault and a page clear per
/// 4 KiB on the next call) depends on the process: measured about 2000 faults per call in one
/// harness and none in another (`docs/perf-log.md`). Recycled buffers do not fault in either.
#[derive(Clone, Debug, Default)]
pub struct RenderBuffers {
    /// rgb, alpha, depth, median depth, normal, final transmittance, distortion.
    images: [Vec<f32>; 7],
    impact: Vec<f32>,
    visible: Vec<bool>,
    prepared: Vec<Option<Prepared>>,
    bins: TileBins,
    tiles: Vec<TileBlended>,
    spare: ForwardSpare,
}

/// Temporaries of the forward pass, kept with its output so that [`RenderBuffers`] can hand
/// them to the next render.
#[derive(Clone, Debug, Default)]
pub(crate) struct ForwardSpare {
    bin_scratch: BinScratch,
    entry_impact: Vec<f32>,
    /// Per tile: its pixels' outputs.
    tile_outputs: Vec<Vec<PixelOut>>,
    /// Per tile: its pixels' distortion (empty unless [`RenderSettings::distortion`]).
    tile_distortion: Vec<Vec<f32>>,
    /// Per billboard: the columns of its box's rows that its support quad can reach.
    billboard_rows: BillboardRows,
}

impl RenderOutput {
    /// The output's storage, for the next [`render_with`]; its values are discarded.
    pub fn into_buffers(self) -> RenderBuffers {
        let state = self.state;
        RenderBuffers {
            images: [
                self.rgb,
                self.alpha,
                self.depth,
                self.median_depth,
                self.normal,
                state.final_transmittance,
                self.distortion,
            ],
            impact: self.impact,
            visible: self.visible,
            prepared: state.prepared,
            bins: state.bins,
            tiles: state.tiles,
            spare: state.spare,
        }
    }
}

/// [`render`] into recycled storage (see [`RenderBuffers`]): bit-identical outputs, fewer
/// fresh pages.
///
/// ```
/// use bbsplat::billboards::{RandomSceneConfig, random_scene, random_scene_camera};
/// use bbsplat::raster::{RenderBuffers, RenderSettings, render, render_with};
/// let scene = random_scene(&RandomSceneConfig::benchmark(200, 32, 32));
/// let (set, camera, settings) = (scene.borrowed(), random_scene_camera(32, 32), RenderSettings::default());
/// let mut buffers = RenderBuffers::default();
/// for _ in 0..3 {
///     let out = render_with(&set, &camera, &settings, buffers);
///     assert_eq!(out.rgb, render(&set, &camera, &settings).rgb);
///     buffers = out.into_buffers();
/// }
/// ```
///
/// # Panics
/// When the slices of `set` have inconsistent lengths (see [`ActivatedRef::assert_consistent`]).
pub fn render_with(
    set: &ActivatedRef<'_>,
    camera: &Camera,
    settings: &RenderSettings,
    buffers: RenderBuffers,
) -> RenderOutput {
    set.assert_consistent();
    let RenderBuffers {
        images:
            [
                mut rgb,
                mut alpha,
                mut depth,
                mut median_depth,
                mut normal,
                mut final_transmittance,
                mut distortion,
            ],
        mut impact,
        mut visible,
        mut prepared,
        mut bins,
        mut tiles,
        mut spare,
    } = buffers;
    let (w, h) = (camera.width, camera.height);
    let n_pix = camera.pixel_count();
    let non_finite_billboards = preprocess_into(set, camera, settings, &mut prepared);
    bin_into(&prepared, w, h, &mut bins, &mut spare.bin_scratch);
    let n_tiles = bins.tile_count();
    let half_side = crate::stages::splat_transform::support_half_side(set.texture_size);
    spare.billboard_rows.build(&prepared, half_side);
    let billboard_rows = &spare.billboard_rows;
    refill(&mut spare.entry_impact, bins.entries.len(), 0.0);
    let impact_chunks = split_by_lengths(&mut spare.entry_impact, (0..n_tiles).map(|t| bins.tile_range(t).len()));
    tiles.resize_with(n_tiles, Default::default);
    let tile_outputs = &mut spare.tile_outputs;
    tile_outputs.resize_with(n_tiles, Default::default);
    // Per tile a distortion buffer, left empty unless the map is asked for.
    let with_distortion = settings.distortion;
    let tile_distortion = &mut spare.tile_distortion;
    tile_distortion.resize_with(n_tiles, Default::default);
    // Each tile's work is estimated by its entry count; the heaviest tiles go first.
    let tile_work: Vec<_> = impact_chunks
        .into_iter()
        .zip(tiles.iter_mut().zip(tile_outputs.iter_mut()))
        .zip(tile_distortion.iter_mut())
        .collect();
    map_heaviest_first(
        tile_work,
        |t| bins.tile_range(t).len() as u64,
        TileScratch::default,
        |scratch, t, ((impact, (blended_pairs, pixels)), tile_distortion)| {
            let list = &bins.entries[bins.tile_range(t)];
            let rect @ (i0, j0, _, _) = tile_pixels(&bins, t, w, h);
            let TileScratch { spans, composite, walk } = scratch;
            local_spans(&prepared, billboard_rows, list, (i0, j0), half_side, spans);
            let tile = (camera, set, settings, &*prepared, list, rect, &*spans);
            let blended = &mut *blended_pairs;
            // Tiles of small billboards go pixel by pixel (the same bits; see
            // `tile_forward_pixels`).
            let by_pixel = super::lanes::walk_by_pixel(
                spans.entries.iter().map(|s| usize::from(s.pixels)).sum(),
                spans.entries.len(),
            );
            match (with_distortion, by_pixel) {
                (true, true) => composite_tile_by_pixel::<true>(walk, tile, impact, pixels, blended),
                (true, false) => composite_tile::<true>(composite, tile, impact, pixels, blended),
                (false, true) => composite_tile_by_pixel::<false>(walk, tile, impact, pixels, blended),
                (false, false) => composite_tile::<false>(composite, tile, impact, pixels, blended),
            }
            if with_distortion {
                tile_distortion.clear();
                tile_distortion.extend(pixels.iter().map(|px| px.distortion));
            }
        },
    );
    let tile_outputs = &spare.tile_outputs;
    let blended_count: u64 = tiles.iter().map(|tile| tile.len() as u64).sum();
    let (evaluated_pairs, nan_alpha_pairs): (u64, u64) = tile_outputs
        .par_iter()
        .map(|pixels| {
            pixels.iter().fold((0u64, 0u64), |(e, n), px| {
                (e + u64::from(px.evaluated), n + u64::from(px.nan_alpha))
            })
        })
        .reduce(|| (0, 0), |a, b| (a.0 + b.0, a.1 + b.1));
    // Images, one band of tile rows per task; every pixel is written (the tiles cover the
    // image), so recycled storage is not reset first.
    let band = TILE_SIZE as usize * w as usize;
    for (image, channels) in [
        (&mut rgb, 3),
        (&mut alpha, 1),
        (&mut depth, 1),
        (&mut median_depth, 1),
        (&mut normal, 3),
        (&mut final_transmittance, 1),
    ] {
        resize_for_overwrite(image, n_pix * channels, 0.0);
    }
    (
        rgb.par_chunks_mut(3 * band),
        alpha.par_chunks_mut(band),
        depth.par_chunks_mut(band),
        median_depth.par_chunks_mut(band),
        normal.par_chunks_mut(3 * band),
        final_transmittance.par_chunks_mut(band),
    )
        .into_par_iter()
        .enumerate()
        .for_each(|(ty, (rgb, alpha, depth, median, normal, final_t))| {
            for tx in 0..bins.tiles_x as usize {
                let t = ty * bins.tiles_x as usize + tx;
                let (i0, _, i1, _) = tile_pixels(&bins, t, w, h);
                let tw = (i1 - i0) as usize;
                for (row, pixels) in tile_outputs[t].chunks(tw).enumerate() {
                    for (column, px) in pixels.iter().enumerate() {
                        // Pixel index within the band.
                        let p = row * w as usize + i0 as usize + column;
                        rgb[3 * p..3 * p + 3].copy_from_slice(&px.rgb.to_array());
                        alpha[p] = px.alpha;
                        depth[p] = px.depth;
                        median[p] = px.median;
                        normal[3 * p..3 * p + 3].copy_from_slice(&px.normal.to_array());
                        final_t[p] = px.final_t;
                    }
                }
            }
        });
    // The distortion map, when asked for: as the images above, one band of tile rows per task.
    if with_distortion {
        resize_for_overwrite(&mut distortion, n_pix, 0.0);
        let tile_distortion = &spare.tile_distortion;
        distortion
            .par_chunks_mut(band)
            .enumerate()
            .for_each(|(ty, distortion)| {
                for tx in 0..bins.tiles_x as usize {
                    let t = ty * bins.tiles_x as usize + tx;
                    let (i0, _, i1, _) = tile_pixels(&bins, t, w, h);
                    let tw = (i1 - i0) as usize;
                    for (row, values) in tile_distortion[t].chunks(tw).enumerate() {
                        let p = row * w as usize + i0 as usize;
                        distortion[p..p + values.len()].copy_from_slice(values);
                    }
                }
            });
    } else {
        distortion.clear();
    }
    // Per-billboard impact: entries summed in tile order (fixed, thread-independent).
    resize_for_overwrite(&mut impact, set.len(), 0.0);
    resize_for_overwrite(&mut visible, set.len(), false);
    let entry_impact = &spare.entry_impact;
    impact
        .par_iter_mut()
        .zip(visible.par_iter_mut())
        .zip(prepared.par_iter())
        .enumerate()
        .for_each(|(b, ((imp, vis), p))| {
            let r = bins.billboard_offsets[b] as usize..bins.billboard_offsets[b + 1] as usize;
            *imp = bins.billboard_entries[r]
                .iter()
                .map(|&e| entry_impact[e as usize])
                .sum();
            *vis = p.is_some();
        });
    RenderOutput {
        width: w,
        height: h,
        rgb,
        alpha,
        depth,
        median_depth,
        normal,
        distortion,
        impact,
        visible,
        stats: RenderStats {
            tile_entries: bins.entries.len() as u64,
            evaluated_pairs,
            blended_pairs: blended_count,
            non_finite_billboards,
            nan_alpha_pairs,
        },
        state: ForwardState {
            camera: *camera,
            settings: *settings,
            prepared,
            bins,
            final_transmittance,
            tiles,
            spare,
        },
    }
}
