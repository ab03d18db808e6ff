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

mod replay {
    use bbsplat::raster::replay::{PassTrace, lower_bound, predicted_time, replay, traced};
    use proptest::prelude::*;

    proptest! {
        /// The replayed makespan lies between the lower bound and the list-scheduling bound
        /// `sum / workers + max` (every greedy hand-out meets it, whatever the order), one
        /// worker takes the sum, and as many workers as tiles take the heaviest.
        #[test]
        fn makespans_lie_between_the_bounds(
            costs in proptest::collection::vec(0u64..10_000, 1..300),
            noise in proptest::collection::vec(0u64..3_000, 300),
            workers in 1usize..70,
        ) {
            // Estimates that rank the tiles roughly: cost plus noise.
            let estimated: Vec<u64> = costs.iter().zip(&noise).map(|(c, e)| c + e).collect();
            let r = replay(&estimated, &costs, workers);
            let (sum, max) = (costs.iter().sum::<u64>(), *costs.iter().max().unwrap());
            prop_assert!(r.makespan >= lower_bound(&costs, workers));
            prop_assert!(r.makespan <= sum / r.workers as u64 + max);
            prop_assert_eq!(r.busy, sum);
            prop_assert!(r.efficiency() <= 1.0 + 1e-12);
            prop_assert_eq!(replay(&estimated, &costs, 1).makespan, sum);
            prop_assert_eq!(replay(&estimated, &costs, costs.len()).makespan, max);
        }
    }

    #[test]
    fn tiles_go_heaviest_estimate_first_to_the_first_free_worker() {
        // Estimated order 1, 0, 2, 3 (ties by index); costs differ from the estimates.
        let estimated = [5, 9, 5, 1];
        let costs = [4, 10, 6, 3];
        // 2 workers: w0 ← tile 1 (0-10), w1 ← tile 0 (0-4), w1 ← tile 2 (4-10), w0 ← tile 3
        // (10-13): makespan 13.
        assert_eq!(replay(&estimated, &costs, 2).makespan, 13);
        // A wrong estimate costs time: the heavy tile last.
        assert_eq!(replay(&[1, 1, 1, 1], &[1, 1, 1, 9], 2).makespan, 10);
        assert_eq!(replay(&[1, 1, 1, 9], &[1, 1, 1, 9], 2).makespan, 9);
        assert_eq!(replay(&[], &[], 8).makespan, 0);
        assert_eq!(replay(&[], &[], 8).efficiency(), 1.0);
    }

    #[test]
    fn predicted_time_adds_the_serial_part_the_scaling_part_and_each_pass() {
        let pass = |c: Vec<u64>| PassTrace {
            estimated: c.clone(),
            nanos: c,
            wall: 0,
        };
        let passes = [pass(vec![8, 8, 8, 8]), pass(vec![20, 1, 1, 1, 1])];
        assert_eq!(predicted_time(100, 64, &passes, 1), 100 + 64 + 32 + 24);
        assert_eq!(predicted_time(100, 64, &passes, 4), 100 + 16 + 8 + 20);
        assert_eq!(predicted_time(100, 64, &passes, 64), 100 + 1 + 8 + 20);
    }

    #[test]
    fn a_traced_render_records_its_passes_and_changes_no_bit() {
        use bbsplat::billboards::{TrainedLikeConfig, random_scene_camera, trained_like_scene};
        let set = trained_like_scene(&TrainedLikeConfig::object(3000, 160, 128));
        let camera = random_scene_camera(160, 128);
        let settings = bbsplat::raster::RenderSettings::default();
        let plain = bbsplat::raster::render(&set.borrowed(), &camera, &settings);
        let (out, passes) = traced(|| bbsplat::raster::render(&set.borrowed(), &camera, &settings));
        assert_eq!(plain.rgb, out.rgb);
        assert_eq!(passes.len(), 1, "one tile pass in a forward render");
        let tiles = plain.state.bins.tile_count();
        assert_eq!((passes[0].estimated.len(), passes[0].nanos.len()), (tiles, tiles));
        // The tiles' times add up to at most the pass's time on every thread.
        let threads = rayon::current_num_threads() as u64;
        assert!(passes[0].nanos.iter().sum::<u64>() <= threads * passes[0].wall);
        assert!(passes[0].nanos.iter().any(|&t| t > 0));
        // Outside `traced`, nothing is recorded; nested calls keep their own passes.
        let ((_, inner), outer) = traced(|| {
            bbsplat::raster::render(&set.borrowed(), &camera, &settings);
            traced(|| bbsplat::raster::render(&set.borrowed(), &camera, &settings))
        });
        assert_eq!((inner.len(), outer.len()), (1, 1));
    }
}
