//! The tile passes' scheduling: every tile run once, results in tile order, heaviest first.

use bbsplat::testing_internals::schedule::map_heaviest_first;
use std::sync::Mutex;

#[test]
fn results_come_back_in_item_order_whatever_the_costs() {
    let items: Vec<u64> = (0..200).map(|i| (i * 7919) % 211).collect();
    for threads in [1, 2, 3] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("pool");
        let got = pool.install(|| map_heaviest_first(items.clone(), |i| items[i], || 0u32, |_, i, x| (i, x * 2)));
        let want: Vec<(usize, u64)> = items.iter().enumerate().map(|(i, &x)| (i, x * 2)).collect();
        assert_eq!(got, want, "{threads} threads");
    }
}

#[test]
fn items_start_heaviest_first_ties_by_index() {
    let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build().expect("pool");
    let costs = [3u64, 9, 1, 9, 5];
    let started = Mutex::new(Vec::new());
    pool.install(|| {
        map_heaviest_first(
            vec![(); costs.len()],
            |i| costs[i],
            || (),
            |_, i, ()| started.lock().expect("lock").push(i),
        )
    });
    assert_eq!(started.into_inner().expect("lock"), vec![1, 3, 4, 0, 2]);
}

#[test]
fn each_thread_makes_one_scratch_and_every_item_runs_once() {
    use std::sync::atomic::{AtomicUsize, Ordering};
    let pool = rayon::ThreadPoolBuilder::new().num_threads(2).build().expect("pool");
    let (made, runs) = (AtomicUsize::new(0), AtomicUsize::new(0));
    let got = pool.install(|| {
        map_heaviest_first(
            (0..500u32).collect(),
            |i| (i % 17) as u64,
            || made.fetch_add(1, Ordering::Relaxed),
            |_, _, x| {
                runs.fetch_add(1, Ordering::Relaxed);
                x
            },
        )
    });
    assert_eq!(got, (0..500u32).collect::<Vec<_>>());
    assert_eq!(runs.into_inner(), 500, "each item run once");
    assert!((1..=2).contains(&made.into_inner()), "one scratch per worker");
}

#[test]
fn no_items_gives_no_results() {
    let got: Vec<u8> = map_heaviest_first(Vec::<u8>::new(), |_| 0, || (), |_, _, x| x);
    assert!(got.is_empty());
}
