//! A block-wise chain's wall time on `K` machines, from the measured time of each stage: the
//! stages before the blocks (coarse run, split) and after them (merge, polish) run one after the
//! other; the block jobs run `K` at a time, handed out longest first to the first machine free
//! (the tile passes' schedule, [`crate::raster::replay::replay`], on the blocks' times), so
//!
//! `T(K) = before + makespan_K(blocks) + after`.
//!
//! Not modelled: queueing, the time to move files between machines, machines of unequal speed.
//!
//! ```
//! use bbsplat::blocks::wall_time::chain_wall_time;
//! // 3 blocks of 10, 10 and 5 s: on 1 machine 25 s, on 2 machines 15, on 3 or more 10.
//! let blocks = [10.0, 10.0, 5.0];
//! assert_eq!(chain_wall_time(2.0, &blocks, 1.0, 1), 28.0);
//! assert_eq!(chain_wall_time(2.0, &blocks, 1.0, 2), 18.0);
//! assert_eq!(chain_wall_time(2.0, &blocks, 1.0, 8), 13.0);
//! ```

/// `T(K)` of the module docs, seconds (stage times in seconds; `machines` at least 1).
pub fn chain_wall_time(before: f64, blocks: &[f64], after: f64, machines: usize) -> f64 {
    // In microseconds, the unit the schedule replay counts in.
    let micros: Vec<u64> = blocks.iter().map(|&s| (s.max(0.0) * 1e6).round() as u64).collect();
    let makespan = crate::raster::replay::replay(&micros, &micros, machines.max(1)).makespan;
    before + makespan as f64 / 1e6 + after
}
