//! The files of a block-wise chain that its stages share (`bbsplat blocks split` writes them,
//! `merge`, `run` and `report` read them), and the `--grid` syntax: a leaf of the `blocks`
//! commands (`cli/blocks.rs`, `cli/blocks_chain.rs`, `cli/blocks_report.rs`).

use anyhow::{Context, Result};
use bbsplat::blocks::Partition;
use clap::ValueEnum;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The plan file `split` writes into the blocks folder and `merge` reads.
pub const PLAN_FILE: &str = "blocks.json";

/// What the cells are balanced by.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Balance {
    /// Training camera centres: as many views' worth of ground per cell.
    Cameras,
    /// The coarse model's billboard centres: as much scene per cell.
    Billboards,
}

/// `CxR`, e.g. `3x1`.
pub fn grid(text: &str) -> Result<(usize, usize), String> {
    let (c, r) = text
        .split_once(['x', 'X'])
        .ok_or_else(|| format!("{text:?}: expected COLUMNSxROWS, e.g. 3x1"))?;
    let parse = |s: &str| match s.trim().parse::<usize>() {
        Ok(n) if (1..=64).contains(&n) => Ok(n),
        _ => Err(format!("{text:?}: each side must be a whole number from 1 to 64")),
    };
    Ok((parse(c)?, parse(r)?))
}

/// One block of the plan file.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct BlockEntry {
    /// Its cell.
    pub cell: usize,
    /// Coarse billboards in its cell and margin (its initial model).
    pub init_billboards: usize,
    /// Its training views, by name.
    pub train_views: Vec<String>,
    /// Its test views, by name.
    pub test_views: Vec<String>,
}

/// The plan file (`blocks.json`).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct BlocksPlan {
    /// The dataset partitioned.
    pub scene: PathBuf,
    /// The coarse model it was partitioned from.
    pub coarse: PathBuf,
    /// Columns and rows.
    pub grid: (usize, usize),
    /// `--margin`.
    pub margin_fraction: f32,
    /// `--min-share`.
    pub min_share: f64,
    /// `--balance`.
    pub balance: Balance,
    /// The cells.
    pub partition: Partition,
    /// Training views per block summed over the blocks, over the training views.
    pub overlap_factor: f64,
    /// The blocks, in cell order.
    pub blocks: Vec<BlockEntry>,
    /// Wall seconds the split took (loading, rendering the coarse model, writing).
    pub seconds: f64,
}

/// What `merge` writes beside the plan (`merge.json`).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct MergeRecord {
    /// Per block, its billboards inside its cell (kept).
    pub kept: Vec<usize>,
    /// Per block, its billboards.
    pub trained: Vec<usize>,
    /// Wall seconds the merge took.
    pub seconds: f64,
}

/// The file of [`MergeRecord`] in the blocks folder.
pub const MERGE_FILE: &str = "merge.json";

/// `BLOCKS/block_K`.
pub fn block_dir(blocks: &Path, cell: usize) -> PathBuf {
    blocks.join(format!("block_{cell}"))
}

/// Reads `BLOCKS/blocks.json`.
pub fn read_plan(blocks: &Path) -> Result<BlocksPlan> {
    let path = blocks.join(PLAN_FILE);
    let text = bbsplat::file_io::read_text_bounded(&path, bbsplat::file_io::JSON_FILE)?;
    let plan: BlocksPlan =
        serde_json::from_str(&text).with_context(|| format!("{}: not a blocks plan", path.display()))?;
    anyhow::ensure!(
        plan.blocks.len() == plan.partition.cell_count(),
        "{}: {} blocks for {} cells",
        path.display(),
        plan.blocks.len(),
        plan.partition.cell_count()
    );
    Ok(plan)
}
