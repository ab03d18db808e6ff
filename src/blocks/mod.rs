//! A large scene trained as spatial blocks and merged (docs/cluster.md, "Tier 2").
//!
//! The chain, each stage a `bbsplat` command that can run as its own job:
//! 1. a coarse run of the whole scene (`bbsplat train`, few steps);
//! 2. the partition ([`Partition`]): the ground plane of the cameras ([`GroundFrame`]) cut into
//!    a grid of cells balanced by camera or billboard centres, each widened by a margin; each
//!    block's views, chosen by the share of their rendered impact that falls in the block's cell
//!    and margin ([`impact_shares`], [`choose_views`]); each block's initial billboards, the
//!    coarse model's in its cell and margin ([`block_init`]) (`bbsplat blocks split`);
//! 3. each block trained on its own views from its own billboards (`bbsplat train --views
//!    --init-model`), what lies past its margin learned by the margin's billboards;
//! 4. the merge: each block's billboards inside its own cell, joined ([`merge()`]; `bbsplat
//!    blocks merge`);
//! 5. a short polish of the merged model on all views (`bbsplat train --init-model`), and eval;
//! 6. the report (`bbsplat blocks report`): each stage's time and figures, and the chain's wall
//!    time on `K` machines ([`wall_time`]); `bbsplat blocks seams` the quality in the bands
//!    where cells meet ([`mod@seams`]), of the chain's model and of any other model of the scene.
//!
//! `bbsplat blocks run` runs the chain stage after stage, or writes it as Slurm jobs.
//!
//! Conventions: ground coordinates are `(along, across)` offsets from the mean camera centre in
//! world units; cells are numbered `column · rows + row`, columns along the cameras' main spread;
//! a billboard belongs to the cell holding its centre.

pub mod ground;
pub mod merge;
pub mod partition;
pub mod seams;
pub mod visibility;
pub mod wall_time;

pub use ground::GroundFrame;
pub use merge::{block_init, merge, own_cell};
pub use partition::Partition;
pub use seams::{distance_to_seam, seam_band_mask};
pub use visibility::{choose_views, impact_shares, overlap_factor};

/// What can go wrong partitioning a scene or merging its blocks.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum BlocksError {
    /// The grid cannot be built as asked.
    #[error("cannot partition the scene: {problem}")]
    Grid {
        /// What is wrong.
        problem: String,
    },
    /// The block models do not fit the partition.
    #[error("cannot merge the blocks: {problem}")]
    Merge {
        /// What is wrong.
        problem: String,
    },
}
