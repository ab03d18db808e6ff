//! The tile passes' schedule replayed on more workers than this machine has: how well their
//! heaviest-first hand-out (`raster::schedule`) would use 4 to 64 cores, estimated from the
//! measured cost of every tile of a real render.
//!
//! [`traced`] runs a render (or a forward and backward) and records, for every tile pass it
//! makes on the calling thread, each tile's estimated cost (what the hand-out sorts by) and its
//! measured time ([`PassTrace`]). Measured on one thread, the times are the tiles' own costs,
//! free of contention. [`replay`] then hands the tiles out as the pass does, in order of
//! decreasing estimate, each to the first worker free, on `workers` simulated workers; its
//! makespan is the pass's time on that many cores when the tiles cost what they cost alone.
//! [`predicted_time`] adds the work outside the tile passes, split into a serial part and a
//! part that scales (measured from one and two threads; Amdahl's law), to predict a whole
//! render's time on `N` cores.
//!
//! ```
//! use bbsplat::raster::replay::{lower_bound, replay};
//! // Estimates that rank the tiles rightly: 4 tiles on 2 workers, 9+1 and 5+5.
//! let costs = [9, 5, 5, 1];
//! let r = replay(&costs, &costs, 2);
//! assert_eq!((r.makespan, r.busy), (10, 20));
//! assert_eq!(r.efficiency(), 1.0);
//! // One tile heavier than the rest together bounds every schedule.
//! assert_eq!(lower_bound(&[30, 1, 1, 1], 4), 30);
//! assert_eq!(replay(&[30, 1, 1, 1], &[30, 1, 1, 1], 4).makespan, 30);
//! ```

use std::cell::RefCell;
use std::cmp::Reverse;
use std::collections::BinaryHeap;

thread_local! {
    /// The passes recorded on this thread inside [`traced`]; `None` outside it.
    pub(crate) static TRACE: RefCell<Option<Vec<PassTrace>>> = const { RefCell::new(None) };
}

/// One tile pass of a render: each tile's estimated cost (the sort key of the hand-out) and its
/// measured time in nanoseconds, by tile index, and the pass's own time.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PassTrace {
    /// The estimate the pass sorted the tiles by.
    pub estimated: Vec<u64>,
    /// The time each tile took, in nanoseconds.
    pub nanos: Vec<u64>,
    /// The pass's wall time (hand-out, tiles, joining the workers), in nanoseconds.
    pub wall: u64,
}

/// Runs `f` and returns its result with the tile passes it made on this thread, in order (the
/// forward pass, then the backward's, ...). The passes time their tiles only inside; the results
/// are the same bits. Nested calls each get their own passes.
pub fn traced<R>(f: impl FnOnce() -> R) -> (R, Vec<PassTrace>) {
    let outer = TRACE.with_borrow_mut(|t| t.replace(Vec::new()));
    let result = f();
    let passes = TRACE
        .with_borrow_mut(|t| std::mem::replace(t, outer))
        .unwrap_or_default();
    (result, passes)
}

/// The order the passes hand tiles out in: decreasing estimate, ties by index.
pub(crate) fn heaviest_first_order(estimated: &[u64]) -> Vec<usize> {
    let mut order: Vec<usize> = (0..estimated.len()).collect();
    order.sort_by_key(|&i| (Reverse(estimated[i]), i));
    order
}

/// A pass replayed on simulated workers.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Replay {
    /// Simulated workers (at most the number of tiles, at least 1).
    pub workers: usize,
    /// When the last worker finishes.
    pub makespan: u64,
    /// The sum of the tiles' costs.
    pub busy: u64,
}

impl Replay {
    /// The share of the workers' time spent on tiles: `busy / (workers · makespan)` (1 for an
    /// empty pass).
    pub fn efficiency(&self) -> f64 {
        if self.makespan == 0 {
            1.0
        } else {
            self.busy as f64 / (self.workers as f64 * self.makespan as f64)
        }
    }
}

/// Tiles of costs `costs` handed out as the tile passes do (decreasing `estimated`, ties by
/// index), each to the first of `workers` workers to be free (the lowest-numbered among equals).
///
/// # Panics
/// When `estimated` and `costs` differ in length.
pub fn replay(estimated: &[u64], costs: &[u64], workers: usize) -> Replay {
    assert_eq!(estimated.len(), costs.len(), "one estimate per tile");
    let workers = workers.clamp(1, costs.len().max(1));
    let mut free: BinaryHeap<Reverse<(u64, usize)>> = (0..workers).map(|w| Reverse((0, w))).collect();
    let mut makespan = 0;
    for i in heaviest_first_order(estimated) {
        let Reverse((at, w)) = free.pop().expect("at least one worker");
        let done = at + costs[i];
        makespan = makespan.max(done);
        free.push(Reverse((done, w)));
    }
    Replay {
        workers,
        makespan,
        busy: costs.iter().sum(),
    }
}

/// No schedule of `costs` on `workers` workers ends before the heaviest tile or before the
/// work shared out evenly: `max(max cost, ⌈sum / workers⌉)`.
pub fn lower_bound(costs: &[u64], workers: usize) -> u64 {
    let sum: u64 = costs.iter().sum();
    let max = costs.iter().copied().max().unwrap_or(0);
    max.max(sum.div_ceil(workers.max(1) as u64))
}

/// A render's predicted time on `workers` cores: `serial + scaling / workers` for the work
/// outside the tile passes, plus each pass's [`replay`] makespan.
pub fn predicted_time(serial: u64, scaling: u64, passes: &[PassTrace], workers: usize) -> u64 {
    let tiles: u64 = passes
        .iter()
        .map(|p| replay(&p.estimated, &p.nanos, workers).makespan)
        .sum();
    serial + scaling / workers.max(1) as u64 + tiles
}
