//! Range checks of every numeric flag, run before anything is loaded or allocated: a value out
//! of range is refused with a message naming the flag, never a panic or an abort later. Memory
//! checks compare [`bbsplat::train::footprint`] estimates with the memory available.

use super::train::TrainArgs;
use anyhow::Result;
use bbsplat::memory::{available_bytes, human_bytes};

/// Largest texture side a model folder can hold
/// ([`bbsplat::model_file::MAX_TEXTURE_SIZE`]): larger would train and then fail to save.
pub use bbsplat::model_file::MAX_TEXTURE_SIZE;

/// Largest `--hull-resolution` (1024³ voxels is already 1.1 G voxels, each projected into every
/// view).
pub const MAX_HULL_RESOLUTION: usize = 1024;

/// Largest `--threads`.
pub const MAX_THREADS: usize = 4096;

/// Largest `--coarse-factor`.
pub const MAX_COARSE_FACTOR: u32 = 64;

/// Largest `bbsplat demo --resolution` (square images).
pub const MAX_DEMO_RESOLUTION: u32 = 8192;

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

/// `--threads`: 1 to [`MAX_THREADS`].
pub fn threads(n: Option<usize>) -> Result<()> {
    if let Some(n) = n {
        anyhow::ensure!(
            (1..=MAX_THREADS).contains(&n),
            "--threads must be between 1 and {MAX_THREADS} (got {n})"
        );
    }
    Ok(())
}

/// Every numeric flag of `bbsplat train`.
pub fn train_args(args: &TrainArgs) -> Result<()> {
    texture_size(args.texture_size)?;
    if let Some(n) = args.billboards {
        billboards(n)?;
    }
    threads(args.threads)?;
    anyhow::ensure!(
        args.sh_degree <= 3,
        "--sh-degree must be 0, 1, 2 or 3 (got {})",
        args.sh_degree
    );
    anyhow::ensure!(
        args.iterations.is_none_or(|n| n >= 1),
        "--iterations must be at least 1"
    );
    anyhow::ensure!(
        (1..=MAX_COARSE_FACTOR).contains(&args.coarse_factor),
        "--coarse-factor must be between 1 and {MAX_COARSE_FACTOR} (got {})",
        args.coarse_factor
    );
    anyhow::ensure!(
        (0.0..=1.0).contains(&args.coarse_until),
        "--coarse-until must be a fraction between 0 and 1 (got {})",
        args.coarse_until
    );
    anyhow::ensure!(
        args.texture_threshold.is_finite() && args.texture_threshold >= 0.0,
        "--texture-threshold must be a finite number ≥ 0 (got {})",
        args.texture_threshold
    );
    anyhow::ensure!(
        (2..=MAX_HULL_RESOLUTION).contains(&args.hull_resolution),
        "--hull-resolution must be between 2 and {MAX_HULL_RESOLUTION} (got {})",
        args.hull_resolution
    );
    anyhow::ensure!(args.scene_args.downscale >= 1, "--downscale must be at least 1 (got 0)");
    anyhow::ensure!(args.scene_args.max_width != Some(0), "--max-width must be at least 1");
    Ok(())
}

/// Every numeric flag of `bbsplat demo`.
pub fn demo_args(iterations: usize, billboards_flag: usize, ts: usize, resolution: u32) -> Result<()> {
    texture_size(ts)?;
    billboards(billboards_flag)?;
    anyhow::ensure!(iterations >= 1, "--iterations must be at least 1");
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
