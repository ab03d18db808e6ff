//! The image rasterizer: every billboard of a view, forward and backward, tiled, parallel and
//! deterministic.
//!
//! Pipeline (method: the BBSplat spec, §3-§4):
//! 1. [`preprocess`]: per billboard, the ray-splat transform, the facing normal, the centre
//!    depth, the SH colour and a tight screen bounding box of the texture support.
//! 2. [`binning`]: square tiles of [`TILE_SIZE`] pixels; each tile lists the billboards whose
//!    box touches it, sorted by centre view depth (ties by billboard index, as the reference's
//!    stable radix sort).
//! 3. [`forward`]: per pixel, front-to-back compositing over its tile's list.
//! 4. [`backward`]: per pixel, the same list re-walked to rebuild the transmittances, then a
//!    back-to-front pass giving gradients without dividing by `1 − alpha`; per-tile partial sums
//!    are reduced per billboard in tile order, so results do not depend on the thread count.
//!
//! [`reference`](mod@reference) holds a plain brute-force renderer (every pixel against every billboard) that
//! the tiled renderer is tested against.
//!
//! Files: [`forward`] and [`backward`] are the drivers; the tile walks (`tile_forward*.rs`,
//! `tile_backward*.rs`) import only the leaves below them (the shared tile types, spans,
//! prefetches and gradient sinks), and this file only declares and re-exports: no file imports
//! a file that imports it (ARCHITECTURE.md, "Module layering"; `tests/suite/layering.rs`).
//!
//! Conventions: camera and pixel conventions of [`crate::camera`]; textures are *activated*
//! values (colour and alpha in `[0, 1]`), `TS × TS` RGBA texels `[r, g, b, alpha]` per billboard,
//! row-major (`[billboard][row][col]`); SH coefficients `[coeff][rgb]`, 48 floats per billboard.
//! Output images are interleaved row-major.

pub mod backward;
pub mod binning;
mod candidates;
pub mod forward;
mod gradients;
pub(crate) mod input;
pub mod lanes;
mod output;
pub(crate) mod prefetch;
pub mod preprocess;
pub mod reference;
pub mod replay;
pub(crate) mod row_spans;
pub(crate) mod schedule;
mod texel_prefetch;
mod tile_backward;
mod tile_backward_avx2;
mod tile_backward_pixels;
mod tile_forward;
pub(crate) mod tile_forward_avx2;
mod tile_forward_pixels;
pub(crate) mod tile_gradients;
pub(crate) mod tile_spans;
mod tile_types;
pub mod workload;

pub use backward::{BackwardScratch, render_backward, render_backward_with};
pub use binning::TILE_SIZE;
pub use forward::{render, render_with};
pub use gradients::RenderGradients;
pub use input::{ActivatedRef, RenderSettings};
pub use output::{ForwardState, RenderBuffers, RenderOutput, RenderStats};
pub use tile_types::{PairOrder, TileBlended};
pub use workload::WorkloadStats;

/// SH storage per billboard: 16 coefficients × 3 channels, `[coeff][rgb]` (defined by the SH stage).
pub use crate::stages::sh::{SH_COEFFS, SH_FLOATS};
