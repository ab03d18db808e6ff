//! Tiled forward pass: front-to-back compositing of every pixel over its tile's list.
//!
//! This file is the pass's driver: [`render_with`] preprocesses and bins the billboards, cuts
//! each tile's spans (`tile_spans.rs`), composites the tiles heaviest first (each billboard by
//! billboard, `tile_forward.rs`, or pixel by pixel, `tile_forward_pixels.rs`, as
//! [`SMALL_ENTRY_PIXELS`] decides) and assembles the images and per-billboard impact.

use super::binning::{TILE_SIZE, bin_into, tile_pixels};
use super::input::{ActivatedRef, RenderSettings};
use super::preprocess::preprocess_into;
use super::schedule::{map_heaviest_first, split_by_lengths};
use super::tile_forward::{TileComposite, composite_tile};
use super::tile_forward_pixels::{PixelWalk, composite_tile_by_pixel};
use super::tile_spans::{TileSpans, local_spans};
use super::tile_types::TileInputs;
use crate::camera::Camera;
use crate::memory::{refill, resize_for_overwrite};
use rayon::prelude::*;

// The forward's two size thresholds, defined where they are used (the tile-walk choice, the
// rows of a wide box), also at their paths here.
pub use super::lanes::SMALL_ENTRY_PIXELS;
pub use super::row_spans::QUAD_MIN_COLUMNS;
// The tile types of the forward's output, at their paths here too.
pub use super::tile_types::{PairOrder, TileBlended};
// What a render returns, at its paths here too.
pub use super::output::{ForwardState, RenderBuffers, RenderOutput, RenderStats};

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
    spare.billboard_rows.build(&prepared, half_side, settings.simd);
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
            let tile = TileInputs {
                camera,
                set,
                settings,
                prepared: &prepared,
                list,
                rect,
                spans,
            };
            let blended = &mut *blended_pairs;
            // Tiles of small billboards go pixel by pixel (the same bits; see
            // `tile_forward_pixels`).
            let by_pixel = settings.tile_walk.by_pixel(
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
