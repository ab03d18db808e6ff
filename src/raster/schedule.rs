//! The order in which the tile passes hand tiles to rayon's threads: the heaviest first.
//!
//! A tile is one task, and tiles differ a hundredfold in work (the middle of an object against
//! its empty surroundings). Split by index, as a parallel iterator does, a pass can end with one
//! thread finishing a heavy tile while the other waits. Handing the tiles out one at a time from
//! a list sorted by estimated work, heaviest first (greedy longest-processing-time scheduling),
//! leaves only light tiles for the end.
//!
//! The order changes no value: every tile computes into its own outputs from inputs no other
//! tile writes, and each thread's scratch is reset per tile, so the results are the same bits
//! whichever thread runs a tile and in whatever order (`bit_identical_across_runs_and_thread_counts`
//! in `tests/suite/raster.rs`: 1, 2 and 8 threads over 20 tiles; the trainer's in
//! `tests/suite/train_demo.rs`). `tests/suite/raster_schedule.rs` tests the hand-out itself.

use super::replay::{PassTrace, TRACE, heaviest_first_order};
use rayon::prelude::*;
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

/// Runs `work(scratch, index, item)` on every item of `items`, on the current rayon pool's
/// threads, handing the items out one at a time in order of decreasing `cost` (ties by index);
/// each thread makes one scratch with `init`. Returns the results in item order.
///
/// Inside [`super::replay::traced`] on the calling thread, each item's run is also timed and the
/// pass's estimated costs and times are recorded ([`PassTrace`]); nothing else changes.
pub(crate) fn map_heaviest_first<T, R, S>(
    items: Vec<T>,
    cost: impl Fn(usize) -> u64,
    init: impl Fn() -> S + Sync,
    work: impl Fn(&mut S, usize, T) -> R + Sync,
) -> Vec<R>
where
    T: Send,
    R: Send,
{
    let n = items.len();
    let estimated: Vec<u64> = (0..n).map(&cost).collect();
    let order = heaviest_first_order(&estimated);
    let inputs: Vec<Mutex<Option<T>>> = items.into_iter().map(|item| Mutex::new(Some(item))).collect();
    let outputs: Vec<Mutex<Option<R>>> = (0..n).map(|_| Mutex::new(None)).collect();
    let next = AtomicUsize::new(0);
    let workers = rayon::current_num_threads().min(n);
    let tracing = TRACE.with_borrow(Option::is_some);
    let pass_start = tracing.then(Instant::now);
    let nanos: Vec<AtomicUsize> = (0..if tracing { n } else { 0 }).map(|_| AtomicUsize::new(0)).collect();
    (0..workers).into_par_iter().for_each(|_| {
        let mut scratch = init();
        loop {
            let k = next.fetch_add(1, Ordering::Relaxed);
            let Some(&i) = order.get(k) else { break };
            let item = take(&inputs[i]).expect("each item is handed out once");
            let start = tracing.then(Instant::now);
            let result = work(&mut scratch, i, item);
            if let Some(start) = start {
                nanos[i].store(start.elapsed().as_nanos() as usize, Ordering::Relaxed);
            }
            *outputs[i].lock().unwrap_or_else(|e| e.into_inner()) = Some(result);
        }
    });
    if let Some(pass_start) = pass_start {
        let trace = PassTrace {
            wall: pass_start.elapsed().as_nanos() as u64,
            estimated,
            nanos: nanos.into_iter().map(|t| t.into_inner() as u64).collect(),
        };
        TRACE.with_borrow_mut(|traces| traces.as_mut().map(|t| t.push(trace)));
    }
    outputs
        .into_iter()
        .map(|slot| {
            slot.into_inner()
                .unwrap_or_else(|e| e.into_inner())
                .expect("every item was run")
        })
        .collect()
}

/// Takes the value out of `slot` (a poisoned lock still holds its value).
fn take<T>(slot: &Mutex<Option<T>>) -> Option<T> {
    slot.lock().unwrap_or_else(|e| e.into_inner()).take()
}

/// Splits `data` into consecutive mutable chunks of the given lengths.
pub(crate) fn split_by_lengths<T>(mut data: &mut [T], lengths: impl Iterator<Item = usize>) -> Vec<&mut [T]> {
    let mut out = Vec::new();
    for len in lengths {
        let (head, tail) = data.split_at_mut(len);
        out.push(head);
        data = tail;
    }
    out
}
