//! The blocks' models joined into one: each block keeps the billboards whose centres lie in its
//! own cell (its margin's are discarded: the neighbouring block trained that ground as its own),
//! blocks in cell order, rows in their order within a block. A block's initial model is the
//! coarse model's billboards in its cell and margin ([`block_init`]).
//!
//! ```
//! use bbsplat::blocks::{GroundFrame, Partition, block_init, merge};
//! use bbsplat::model::RawBillboards;
//! use glam::{Vec2, Vec3};
//! let frame = GroundFrame { origin: Vec3::ZERO, up: Vec3::Y, along: Vec3::X, across: Vec3::NEG_Z };
//! let cameras: Vec<Vec2> = (0..4).map(|i| Vec2::new(i as f32, 0.0)).collect();
//! let grid = Partition::balanced(frame, &cameras, 2, 1, 0.5).unwrap(); // cut at 1.5, margin 0.75
//! let points: Vec<Vec3> = (0..4).map(|i| Vec3::new(i as f32, 0.0, 0.0)).collect();
//! let coarse = RawBillboards::from_points(&points, &[[0.5; 3]; 4], 4, 0);
//! let blocks = [block_init(&grid, &coarse, 0), block_init(&grid, &coarse, 1)];
//! // Billboards at x = 0, 1, 2 for the first block (2 < 1.5 + 0.75), 1, 2, 3 for the second.
//! assert_eq!((blocks[0].len(), blocks[1].len()), (3, 3));
//! let (merged, kept) = merge(&grid, &blocks).unwrap();
//! assert_eq!((merged.positions, kept), (points, vec![2, 2]));
//! ```

use super::BlocksError;
use super::partition::Partition;
use crate::model::RawBillboards;

/// The billboards of `coarse` in cell `cell` or its margin.
pub fn block_init(partition: &Partition, coarse: &RawBillboards, cell: usize) -> RawBillboards {
    coarse.rows_where(|i| partition.in_cell_or_margin(cell, partition.frame.project(coarse.positions[i])))
}

/// The billboards of `block` (the model trained for cell `cell`) whose centres lie in that cell:
/// what the merge keeps of it. A caller merging models too large to hold together takes each
/// block's share in turn and appends it ([`crate::train::grow::append_rows`]), as `bbsplat
/// blocks merge` does.
pub fn own_cell(partition: &Partition, block: &RawBillboards, cell: usize) -> RawBillboards {
    block.rows_where(|i| partition.cell_of_point(block.positions[i]) == cell)
}

/// Block `k`'s billboards in cell `k`, for every block, joined (module docs), and how many
/// each block kept.
///
/// # Errors
/// [`BlocksError::Merge`] when the number of models is not the number of cells, or their
/// texture sizes differ.
pub fn merge(partition: &Partition, blocks: &[RawBillboards]) -> Result<(RawBillboards, Vec<usize>), BlocksError> {
    if blocks.len() != partition.cell_count() {
        return Err(BlocksError::Merge {
            problem: format!("{} block models for {} cells", blocks.len(), partition.cell_count()),
        });
    }
    let mut merged: Option<RawBillboards> = None;
    let mut counts = Vec::with_capacity(blocks.len());
    for (k, block) in blocks.iter().enumerate() {
        let kept = own_cell(partition, block, k);
        counts.push(kept.len());
        match &mut merged {
            None => merged = Some(kept),
            Some(m) => {
                if m.texture_size != kept.texture_size {
                    return Err(BlocksError::Merge {
                        problem: format!(
                            "block {k} has texture size {}, block 0 {}",
                            kept.texture_size, m.texture_size
                        ),
                    });
                }
                crate::train::grow::append_rows(m, &kept);
            }
        }
    }
    Ok((merged.expect("a partition has at least one cell"), counts))
}
