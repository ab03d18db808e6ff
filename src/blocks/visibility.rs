//! Which views a block trains on: the share of each view's rendered impact that falls in the
//! block's cell and margin, from a coarse model of the whole scene.
//!
//! A view's impact is its render's per-billboard `Σ α·T` over the view's pixels
//! ([`RenderOutput::impact`](crate::raster::RenderOutput::impact)): what each billboard puts
//! into that image. The share of cell `k` is the impact of the billboards whose centres lie in
//! the cell or its margin ([`Partition::in_cell_or_margin`]) over the view's whole impact (sums
//! in f64, billboards in order). A view goes to every block whose share is at least
//! `min_share`; one that reaches it nowhere goes to the block of its largest share, and one
//! that sees nothing of the coarse model to the cell under its camera, so that every view is
//! trained on by some block.
//!
//! The margin's billboards count for a block because the block trains them (and discards them
//! at the merge): a view that sees only a cell's margin still teaches the block what lies at
//! its border.

use super::partition::Partition;
use crate::camera::Camera;
use crate::model::RawBillboards;
use crate::raster::{RenderBuffers, RenderSettings, render_with};

/// Per view, the share of its impact in each cell with its margin (module docs); all zeros for
/// a view that sees nothing of `coarse`. Views are rendered one after the other, each on every
/// thread of the current rayon pool; the result does not depend on their number.
pub fn impact_shares(
    coarse: &RawBillboards,
    cameras: &[Camera],
    settings: &RenderSettings,
    partition: &Partition,
) -> Vec<Vec<f64>> {
    let set = coarse.activate();
    let cells = partition.cell_count();
    // The cells (with margins) each billboard counts for.
    let member: Vec<Vec<bool>> = coarse
        .positions
        .iter()
        .map(|&p| {
            let q = partition.frame.project(p);
            (0..cells).map(|k| partition.in_cell_or_margin(k, q)).collect()
        })
        .collect();
    let mut buffers = RenderBuffers::default();
    cameras
        .iter()
        .map(|camera| {
            let out = render_with(&set.borrowed(), camera, settings, std::mem::take(&mut buffers));
            let mut per_cell = vec![0.0f64; cells];
            let mut total = 0.0f64;
            for (impact, cells_of) in out.impact.iter().zip(&member) {
                let impact = f64::from(*impact);
                total += impact;
                for (sum, &inside) in per_cell.iter_mut().zip(cells_of) {
                    if inside {
                        *sum += impact;
                    }
                }
            }
            buffers = out.into_buffers();
            if total > 0.0 {
                per_cell.iter_mut().for_each(|s| *s /= total);
            }
            per_cell
        })
        .collect()
}

/// The views of each block: per cell, the indices of the views whose share there is at least
/// `min_share`, in view order; a view reaching it nowhere goes to its largest share (the lowest
/// cell among equals), and a view of no impact to the cell under its camera (module docs).
pub fn choose_views(shares: &[Vec<f64>], cameras: &[Camera], partition: &Partition, min_share: f64) -> Vec<Vec<usize>> {
    let mut blocks = vec![Vec::new(); partition.cell_count()];
    for (v, (view_shares, camera)) in shares.iter().zip(cameras).enumerate() {
        let mut placed = false;
        for (k, &share) in view_shares.iter().enumerate() {
            if share > 0.0 && share >= min_share {
                blocks[k].push(v);
                placed = true;
            }
        }
        if !placed {
            let best = view_shares
                .iter()
                .enumerate()
                .fold((0, 0.0), |(bk, bs), (k, &s)| if s > bs { (k, s) } else { (bk, bs) });
            let k = if best.1 > 0.0 {
                best.0
            } else {
                partition.cell_of_point(camera.centre())
            };
            blocks[k].push(v);
        }
    }
    blocks
}

/// Views per block summed over the blocks, over the number of views: 1 when no view is shared,
/// the number of blocks when every block trains on every view.
pub fn overlap_factor(blocks: &[Vec<usize>], views: usize) -> f64 {
    blocks.iter().map(Vec::len).sum::<usize>() as f64 / views.max(1) as f64
}
