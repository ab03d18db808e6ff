//! A partition of the ground plane into a grid of cells balanced by a point set (camera centres
//! or billboard centres), each cell widened by a margin for what its block trains.
//!
//! The grid has `columns` along [`GroundFrame::along`] and `rows` across it. The column cuts are
//! the midpoints between consecutive points at the `k·n/columns` quantiles of the points'
//! `along` coordinates, so each column holds as near `n/columns` points as ties allow; within
//! each column its own points are cut the same way into `rows`. The outer cells are unbounded,
//! so every point of the plane lies in exactly one cell: a coordinate `x` is in the interval
//! between cuts `c₀ ≤ x < c₁`.
//!
//! The margin is one distance for every cell: `margin_fraction` times the mean column width
//! (the points' `along` span over `columns`). A cell widened by it overlaps its neighbours;
//! blocks train on their cell and margin, and the merge keeps each block's billboards inside its
//! cell only ([`mod@super::merge`]).
//!
//! ```
//! use bbsplat::blocks::{GroundFrame, Partition};
//! use glam::{Vec2, Vec3};
//! let frame = GroundFrame { origin: Vec3::ZERO, up: Vec3::Y, along: Vec3::X, across: Vec3::NEG_Z };
//! let points: Vec<Vec2> = (0..8).map(|i| Vec2::new(i as f32, 0.0)).collect();
//! let p = Partition::balanced(frame, &points, 2, 1, 0.25).unwrap();
//! assert_eq!(p.along_cuts, vec![3.5]);
//! assert_eq!(p.cell_of(Vec2::new(-100.0, 5.0)), 0);
//! assert_eq!(p.cell_of(Vec2::new(3.5, 0.0)), 1);
//! // Margin 0.25 × (7 / 2): cell 0 reaches 3.5 + 0.875 with it.
//! assert!(p.in_cell_or_margin(0, Vec2::new(4.3, 0.0)));
//! assert!(!p.in_cell_or_margin(0, Vec2::new(4.4, 0.0)));
//! ```

use super::BlocksError;
use super::ground::GroundFrame;
use glam::{Vec2, Vec3};
use serde::{Deserialize, Serialize};

/// The grid (module docs). Cell `column · rows + row`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Partition {
    /// The frame the coordinates are in.
    pub frame: GroundFrame,
    /// Cuts between the columns, increasing (`columns − 1` of them).
    pub along_cuts: Vec<f32>,
    /// Per column, the cuts between its rows, increasing (`rows − 1` each).
    pub across_cuts: Vec<Vec<f32>>,
    /// How far a cell's block reaches past its cell, world units.
    pub margin: f32,
}

/// Cuts splitting sorted `values` into `parts` runs of near-equal length.
fn quantile_cuts(values: &mut [f32], parts: usize) -> Vec<f32> {
    values.sort_by(f32::total_cmp);
    let n = values.len();
    (1..parts)
        .map(|k| {
            let i = k * n / parts;
            0.5 * (values[i - 1] + values[i])
        })
        .collect()
}

/// The interval of `cuts` that `x` lies in: the number of cuts at or below it.
fn interval_of(cuts: &[f32], x: f32) -> usize {
    cuts.partition_point(|&c| c <= x)
}

/// The bounds of interval `k` of `cuts`, unbounded at the ends.
fn interval_bounds(cuts: &[f32], k: usize) -> (f32, f32) {
    let low = if k == 0 { f32::NEG_INFINITY } else { cuts[k - 1] };
    let high = cuts.get(k).copied().unwrap_or(f32::INFINITY);
    (low, high)
}

impl Partition {
    /// A `columns × rows` grid balanced by `points` (ground coordinates), its margin
    /// `margin_fraction` of the mean column width (module docs).
    ///
    /// # Errors
    /// [`BlocksError::Grid`] for a zero dimension, fewer points than cells, non-finite points
    /// or a margin fraction that is not finite and ≥ 0.
    pub fn balanced(
        frame: GroundFrame,
        points: &[Vec2],
        columns: usize,
        rows: usize,
        margin_fraction: f32,
    ) -> Result<Self, BlocksError> {
        let grid = |problem: String| Err(BlocksError::Grid { problem });
        if columns == 0 || rows == 0 {
            return grid(format!("a {columns}×{rows} grid has no cell"));
        }
        if !(margin_fraction.is_finite() && margin_fraction >= 0.0) {
            return grid(format!(
                "the margin must be a finite fraction ≥ 0 (got {margin_fraction})"
            ));
        }
        if points.iter().any(|p| !p.is_finite()) {
            return grid("a point to balance the cells by is not finite".into());
        }
        if points.len() < columns * rows {
            return grid(format!(
                "{} points to balance {columns}×{rows} cells by: at least one per cell is needed",
                points.len()
            ));
        }
        let mut along: Vec<f32> = points.iter().map(|p| p.x).collect();
        let along_cuts = quantile_cuts(&mut along, columns);
        let span = along.last().copied().unwrap_or(0.0) - along.first().copied().unwrap_or(0.0);
        let mut per_column: Vec<Vec<f32>> = vec![Vec::new(); columns];
        for p in points {
            per_column[interval_of(&along_cuts, p.x)].push(p.y);
        }
        let mut across_cuts = Vec::with_capacity(columns);
        for (c, mut ys) in per_column.into_iter().enumerate() {
            if ys.len() < rows {
                return grid(format!(
                    "column {c} holds {} points (ties in the points' positions): too few for {rows} rows",
                    ys.len()
                ));
            }
            across_cuts.push(quantile_cuts(&mut ys, rows));
        }
        Ok(Self {
            frame,
            along_cuts,
            across_cuts,
            margin: margin_fraction * span / columns as f32,
        })
    }

    /// Rows of the grid.
    pub fn rows(&self) -> usize {
        self.across_cuts.first().map_or(1, |c| c.len() + 1)
    }

    /// Number of cells.
    pub fn cell_count(&self) -> usize {
        (self.along_cuts.len() + 1) * self.rows()
    }

    /// The cell holding ground point `q`.
    pub fn cell_of(&self, q: Vec2) -> usize {
        let column = interval_of(&self.along_cuts, q.x);
        column * self.rows() + interval_of(&self.across_cuts[column], q.y)
    }

    /// The cell holding world point `p`.
    pub fn cell_of_point(&self, p: Vec3) -> usize {
        self.cell_of(self.frame.project(p))
    }

    /// Cell `cell`'s bounds: `((along low, along high), (across low, across high))`, infinite
    /// on the grid's outer sides.
    pub fn cell_bounds(&self, cell: usize) -> ((f32, f32), (f32, f32)) {
        let (column, row) = (cell / self.rows(), cell % self.rows());
        (
            interval_bounds(&self.along_cuts, column),
            interval_bounds(&self.across_cuts[column], row),
        )
    }

    /// True when ground point `q` lies in cell `cell` widened by the margin on every side.
    pub fn in_cell_or_margin(&self, cell: usize, q: Vec2) -> bool {
        let ((a0, a1), (b0, b1)) = self.cell_bounds(cell);
        let m = self.margin;
        a0 - m <= q.x && q.x < a1 + m && b0 - m <= q.y && q.y < b1 + m
    }
}
