//! The candidates of the backward's pixel-by-pixel tile walk: per pixel of a run, the tile
//! entries whose texture support its ray hits, with their hits and taps, computed (and their
//! texels prefetched) before the run is composited.

use super::input::ActivatedRef;
use super::prefetch::prefetch_taps;
use super::preprocess::Prepared;
use crate::camera::Camera;
use crate::stages::bilinear::{self, BilinearTaps};
use crate::stages::ray_plane::{intersect_with, pixel_ray};

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
