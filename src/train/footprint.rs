//! The memory a training run needs, estimated from its sizes before anything large is
//! allocated, so that a run that cannot fit is refused with a message ("needs 41.0 GB, 23.0 GB
//! available") instead of aborting on a failed allocation after seconds of work.
//!
//! The estimate is a sum of three terms and a base, fitted to the measured peaks of runs from
//! 200 to 1600 px, 10 000 to 300 000 billboards and 58 to 808 views, which it meets within
//! 1.00-1.20× (calibration in `docs/training.md`, "Memory"):
//!
//! - per billboard: the raw parameters, the activated copy, the gradients, the two Adam moments
//!   and, at the end, the re-loaded model and its encoded files: [`BYTES_PER_BILLBOARD_FLOAT`]
//!   bytes per float of a billboard's row (`57 + 4·TS²` floats);
//! - per pixel of every loaded view (train and test): [`BYTES_PER_VIEW_PIXEL`];
//! - per pixel of the largest view, the renderer's and the loss's buffers:
//!   [`BYTES_PER_RENDER_PIXEL`].
//!
//! Arithmetic saturates: an absurd flag gives `u64::MAX`, never an overflow.
//!
//! ```
//! use bbsplat::train::footprint::training_bytes;
//! let small = training_bytes(1_000, 16, 100 * 800 * 800, 800 * 800);
//! let huge = training_bytes(usize::MAX, 16, 0, 0);
//! assert!(small < 1 << 30);
//! assert_eq!(huge, u64::MAX);
//! ```

use crate::raster::SH_FLOATS;

/// Floats of a billboard's geometry and SH (position 3, quaternion 4, log-scales 2, SH 48).
pub const GEOMETRY_FLOATS: u64 = 3 + 4 + 2 + SH_FLOATS as u64;

/// Bytes per float of a billboard's row (raw, activated, gradients, two Adam moments, the
/// re-loaded model and the encoding buffers of the final save); measured 29-30.
pub const BYTES_PER_BILLBOARD_FLOAT: u64 = 32;

/// Bytes per pixel of a loaded view: the 8-bit RGB image (and its alpha coverage); measured 3
/// (lego's PNGs) to 5.6 (the demo's).
pub const BYTES_PER_VIEW_PIXEL: u64 = 5;

/// Bytes per pixel of the largest view for the render, backward and loss buffers; measured
/// 410-490.
pub const BYTES_PER_RENDER_PIXEL: u64 = 512;

/// A fixed allowance for the program itself, its thread stacks and small tables.
pub const BASE_BYTES: u64 = 64 << 20;

/// Estimated peak memory, in bytes, of training `billboards` billboards with `texture_size`
/// textures on views totalling `view_pixels` pixels, the largest `largest_view_pixels`.
pub fn training_bytes(billboards: usize, texture_size: usize, view_pixels: u64, largest_view_pixels: u64) -> u64 {
    let ts = texture_size as u128;
    let row = GEOMETRY_FLOATS as u128 + 4 * ts * ts;
    let total = (billboards as u128) * row * BYTES_PER_BILLBOARD_FLOAT as u128
        + view_pixels as u128 * BYTES_PER_VIEW_PIXEL as u128
        + largest_view_pixels as u128 * BYTES_PER_RENDER_PIXEL as u128
        + BASE_BYTES as u128;
    total.min(u64::MAX as u128) as u64
}

/// [`training_bytes`] of a run on the train and test views of `scene` that starts from
/// `billboards` billboards and may grow to `growth_cap` (0: no growth): the larger count is the
/// one its arrays reach.
pub fn scene_training_bytes(
    billboards: usize,
    growth_cap: usize,
    texture_size: usize,
    scene: &crate::scene::Scene,
) -> u64 {
    let views = scene.train.iter().chain(&scene.test);
    let view_pixels: u64 = views.clone().map(|v| v.camera.pixel_count() as u64).sum();
    let largest_view = views.map(|v| v.camera.pixel_count() as u64).max().unwrap_or(0);
    let Some(cache) = scene.image_cache() else {
        return training_bytes(billboards.max(growth_cap), texture_size, view_pixels, largest_view);
    };
    // On demand: the cache's budget, the masks and coverage held, and each view's record.
    let held: u64 = scene
        .train
        .iter()
        .chain(&scene.test)
        .map(|v| {
            let extra = v.mask.as_ref().map_or(0, Vec::len) + v.coverage.as_ref().map_or(0, Vec::len);
            extra as u64 + ON_DEMAND_VIEW_BYTES
        })
        .sum();
    training_bytes(billboards.max(growth_cap), texture_size, 0, largest_view)
        .saturating_add(cache.budget())
        .saturating_add(held)
}

/// Bytes of an on-demand view's record (name, paths, camera, recipe) and its share of the
/// cache's table; an allowance, above the few hundred bytes they take.
pub const ON_DEMAND_VIEW_BYTES: u64 = 4096;

/// Estimated size, in bytes, of the files a run writes: the checkpoint (raw parameters and two
/// Adam moments as f32, 3 row copies) and the model folder (60 floats of PLY and `4·TS²`
/// texture bytes per billboard, before compression).
pub fn output_bytes(billboards: usize, texture_size: usize) -> u64 {
    let ts = texture_size as u128;
    let row = GEOMETRY_FLOATS as u128 + 4 * ts * ts;
    let checkpoint = 3 * row * 4 + 64;
    let model = 60 * 4 + 4 * ts * ts;
    let total = billboards as u128 * (checkpoint + model) + (1 << 20);
    total.min(u64::MAX as u128) as u64
}
