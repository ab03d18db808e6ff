//! What a render returns: its images and counters ([`RenderOutput`], [`RenderStats`]), what the
//! backward pass needs of it ([`ForwardState`]), and its storage for the next render
//! ([`RenderBuffers`]).

use super::binning::{BinScratch, TileBins};
use super::input::RenderSettings;
use super::preprocess::Prepared;
use super::row_spans::BillboardRows;
use super::tile_types::{PixelOut, TileBlended};
use crate::camera::Camera;

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

/// The storage of a [`RenderOutput`] and of the forward pass's temporaries, handed back by
/// [`RenderOutput::into_buffers`] for the next [`render_with`](super::render_with) call.
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
    pub(super) images: [Vec<f32>; 7],
    pub(super) impact: Vec<f32>,
    pub(super) visible: Vec<bool>,
    pub(super) prepared: Vec<Option<Prepared>>,
    pub(super) bins: TileBins,
    pub(super) tiles: Vec<TileBlended>,
    pub(super) spare: ForwardSpare,
}

/// Temporaries of the forward pass, kept with its output so that [`RenderBuffers`] can hand
/// them to the next render.
#[derive(Clone, Debug, Default)]
pub(crate) struct ForwardSpare {
    pub(super) bin_scratch: BinScratch,
    pub(super) entry_impact: Vec<f32>,
    /// Per tile: its pixels' outputs.
    pub(super) tile_outputs: Vec<Vec<PixelOut>>,
    /// Per tile: its pixels' distortion (empty unless [`RenderSettings::distortion`]).
    pub(super) tile_distortion: Vec<Vec<f32>>,
    /// Per billboard: the columns of its box's rows that its support quad can reach.
    pub(super) billboard_rows: BillboardRows,
}

impl RenderOutput {
    /// The output's storage, for the next [`render_with`](super::render_with); its values are discarded.
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
