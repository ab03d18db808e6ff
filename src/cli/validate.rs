//! Range checks of every numeric flag, run before anything is loaded or allocated: a value out
//! of range is refused with a message naming the flag, never a panic or an abort later. Memory
//! checks compare [`bbsplat::train::footprint`] estimates with the memory available.

use super::train_args::TrainArgs;
use anyhow::Result;
use bbsplat::memory::{available_bytes, human_bytes};

/// Largest texture side a model folder can hold
/// ([`bbsplat::model_file::MAX_TEXTURE_SIZE`]): larger would train and then fail to save.
pub use bbsplat::model_file::MAX_TEXTURE_SIZE;

/// Largest `bbsplat demo --resolution` (square images).
pub const MAX_DEMO_RESOLUTION: u32 = 8192;

/// Largest `demo --views` (the memory check bounds it further by the resolution).
pub const MAX_DEMO_VIEWS: usize = 100_000;

/// `--texture-size`: 2 to [`MAX_TEXTURE_SIZE`].
pub fn texture_size(ts: usize) -> Result<()> {
    anyhow::ensure!(ts >= 2, "--texture-size must be at least 2 (got {ts})");
    anyhow::ensure!(
        ts <= MAX_TEXTURE_SIZE,
        "--texture-size must be at most {MAX_TEXTURE_SIZE} (got {ts}): a model folder cannot store larger textures"
    );
    Ok(())
}

/// `--billboards`: at least 1 (the memory check bounds it from above).
pub fn billboards(n: usize) -> Result<()> {
    anyhow::ensure!(n >= 1, "--billboards must be at least 1");
    Ok(())
}

/// `--threads` ([`super::common::check_threads`], checked where the pool starts).
pub use super::common::check_threads as threads;

/// Every numeric flag of `bbsplat train`: the library's ranges of the request they make
/// ([`bbsplat::plan::TrainRequest::check`], named by their flags), then `--threads`,
/// `--downscale` and `--max-width`.
pub fn train_args(args: &TrainArgs) -> Result<()> {
    args.request().check().map_err(|e| anyhow::anyhow!("--{e}"))?;
    threads(args.threads)?;
    anyhow::ensure!(args.scene_args.downscale >= 1, "--downscale must be at least 1 (got 0)");
    anyhow::ensure!(args.scene_args.max_width != Some(0), "--max-width must be at least 1");
    Ok(())
}

/// Every numeric flag of `bbsplat demo`.
pub fn demo_args(iterations: usize, billboards_flag: usize, ts: usize, resolution: u32, views: usize) -> Result<()> {
    texture_size(ts)?;
    billboards(billboards_flag)?;
    anyhow::ensure!(iterations >= 1, "--iterations must be at least 1");
    anyhow::ensure!(views >= 1, "--views must be at least 1");
    anyhow::ensure!(
        views <= MAX_DEMO_VIEWS,
        "--views must be at most {MAX_DEMO_VIEWS} (got {views})"
    );
    anyhow::ensure!(resolution >= 8, "--resolution must be at least 8 (got {resolution})");
    anyhow::ensure!(
        resolution <= MAX_DEMO_RESOLUTION,
        "--resolution must be at most {MAX_DEMO_RESOLUTION} (got {resolution})"
    );
    Ok(())
}

/// Refuses `what` when its estimated `needed` bytes exceed the memory available (skipped where
/// the available memory is unknown). The limit can be raised for a test or a machine whose
/// swap should be used: `BBSPLAT_MEMORY_LIMIT=<bytes>` replaces the measured figure.
pub fn memory(what: &str, needed: u64) -> Result<()> {
    let available = std::env::var("BBSPLAT_MEMORY_LIMIT")
        .ok()
        .and_then(|v| v.parse::<u64>().ok())
        .or_else(available_bytes);
    if let Some(available) = available {
        anyhow::ensure!(
            needed <= available,
            "{what} needs {}, {} available: lower it",
            human_bytes(needed),
            human_bytes(available)
        );
    }
    Ok(())
}
