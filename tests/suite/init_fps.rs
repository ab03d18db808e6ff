//! Farthest point sampling: the greedy rule against brute force, the edge cases (k ≥ N, k = 0,
//! N = 0, duplicates, non-finite points) and determinism across thread counts.

use bbsplat::init::fps::{
    DENSE_CHUNK, FpsError, PARALLEL_MIN_POINTS, farthest_point_sampling, farthest_point_sampling_dense,
};
use bbsplat::rng::Rng;
use bbsplat::strategies::box_cloud as cloud;
use bbsplat::strategies::{point_cloud, seeded_config};
use bbsplat::testing_internals::fps::{better, bucket_lower_bound, spread_bits, squared, to_f64};
use glam::Vec3;
use proptest::prelude::*;

/// Squared distance in f64, the same arithmetic the sampler documents.
fn d2(a: Vec3, b: Vec3) -> f64 {
    let (dx, dy, dz) = (
        a.x as f64 - b.x as f64,
        a.y as f64 - b.y as f64,
        a.z as f64 - b.z as f64,
    );
    dx * dx + dy * dy + dz * dz
}

/// Checks every step of `chosen` by brute force: step t picks, among the points not chosen
/// yet, one whose minimum squared distance to the first t chosen points is the largest, and
/// the lowest index among those.
fn assert_greedy(points: &[Vec3], chosen: &[usize]) {
    if chosen.is_empty() {
        return;
    }
    assert_eq!(chosen[0], 0, "starts at index 0");
    let mut taken = vec![false; points.len()];
    taken[0] = true;
    for t in 1..chosen.len() {
        let dist = |i: usize| {
            chosen[..t]
                .iter()
                .map(|&j| d2(points[i], points[j]))
                .fold(f64::INFINITY, f64::min)
        };
        let (best_i, best_d) = (0..points.len()).filter(|&i| !taken[i]).map(|i| (i, dist(i))).fold(
            (usize::MAX, f64::NEG_INFINITY),
            |acc, (i, d)| if d > acc.1 { (i, d) } else { acc },
        );
        assert_eq!(
            chosen[t], best_i,
            "step {t}: expected index {best_i} at squared distance {best_d}"
        );
        assert!(!taken[chosen[t]], "index {} chosen twice", chosen[t]);
        taken[chosen[t]] = true;
    }
}

#[test]
fn small_example() {
    let p = [
        Vec3::new(0.0, 0.0, 0.0),
        Vec3::new(1.0, 0.0, 0.0),
        Vec3::new(10.0, 0.0, 0.0),
        Vec3::new(5.0, 0.1, 0.0),
        Vec3::new(0.0, 3.0, 0.0),
    ];
    assert_eq!(farthest_point_sampling(&p, 4).unwrap(), vec![0, 2, 3, 4]);
    assert_greedy(&p, &farthest_point_sampling(&p, 4).unwrap());
}

#[test]
fn sizes_at_the_edges() {
    let p: Vec<Vec3> = (0..5).map(|i| Vec3::splat(i as f32)).collect();
    assert_eq!(farthest_point_sampling(&p, 0).unwrap(), Vec::<usize>::new());
    assert_eq!(farthest_point_sampling(&p, 1).unwrap(), vec![0]);
    assert_eq!(farthest_point_sampling(&p, 5).unwrap(), vec![0, 1, 2, 3, 4]);
    assert_eq!(farthest_point_sampling(&p, 1000).unwrap(), vec![0, 1, 2, 3, 4]);
    assert_eq!(farthest_point_sampling(&p, 4).unwrap(), vec![0, 4, 2, 1]);
    assert_eq!(farthest_point_sampling(&[], 0).unwrap(), Vec::<usize>::new());
    assert_eq!(farthest_point_sampling(&[], 3).unwrap(), Vec::<usize>::new());
    assert_eq!(farthest_point_sampling(&[Vec3::ONE], 1).unwrap(), vec![0]);
}

#[test]
fn duplicates_are_taken_last_in_index_order() {
    let (a, b, c) = (Vec3::ZERO, Vec3::X, Vec3::new(0.0, 2.0, 0.0));
    let p = [a, b, a, b, c, a];
    // 0 (a), then c (4), then b at index 1 (ties with 3: lowest index); then every remaining
    // point is a duplicate at distance 0: 2, 3, 5 in index order.
    assert_eq!(farthest_point_sampling(&p, 3).unwrap(), vec![0, 4, 1]);
    assert_eq!(farthest_point_sampling(&p, 5).unwrap(), vec![0, 4, 1, 2, 3]);
    // All points identical.
    let same = vec![Vec3::splat(2.5); 7];
    assert_eq!(farthest_point_sampling(&same, 4).unwrap(), vec![0, 1, 2, 3]);
}

#[test]
fn non_finite_points_are_rejected_by_index() {
    let mut p: Vec<Vec3> = (0..10).map(|i| Vec3::splat(i as f32)).collect();
    p[3].y = f32::NAN;
    p[7].x = f32::INFINITY;
    for k in [0, 2, 10, 20] {
        let err = farthest_point_sampling(&p, k).unwrap_err();
        assert!(matches!(err, FpsError::NonFinitePoint { index: 3, .. }), "{err:?}");
        let msg = err.to_string();
        assert!(msg.contains("point 3"), "{msg}");
        assert!(msg.contains("NaN"), "{msg}");
    }
    p[3].y = 0.0;
    let err = farthest_point_sampling(&p, 5).unwrap_err();
    assert_eq!(
        err,
        FpsError::NonFinitePoint {
            index: 7,
            point: [f32::INFINITY, 7.0, 7.0]
        }
    );
}

fn random_cloud(n: usize, seed: u64) -> Vec<Vec3> {
    let mut rng = Rng::new(seed);
    (0..n)
        .map(|_| Vec3::new(rng.range(-50.0, 50.0), rng.range(-50.0, 50.0), rng.range(-5.0, 5.0)))
        .collect()
}

/// An integer lattice: a great many exactly equal distances, so every step is a tie-break.
fn lattice(side: usize) -> Vec<Vec3> {
    let mut p = Vec::with_capacity(side * side * side);
    for z in 0..side {
        for y in 0..side {
            for x in 0..side {
                p.push(Vec3::new(x as f32, y as f32, z as f32));
            }
        }
    }
    p
}

#[test]
fn identical_for_any_thread_count() {
    for (cloud, k) in [(random_cloud(5 * DENSE_CHUNK + 123, 1), 300), (lattice(34), 150)] {
        // Several dense chunks, and early steps large enough for the parallel bucket update.
        assert!(cloud.len() > 2 * DENSE_CHUNK && cloud.len() > 2 * PARALLEL_MIN_POINTS);
        let run = |threads: usize| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| {
                    (
                        farthest_point_sampling(&cloud, k).unwrap(),
                        farthest_point_sampling_dense(&cloud, k).unwrap(),
                    )
                })
        };
        let one = run(1);
        assert_eq!(one.0.len(), k);
        assert_eq!(one.0, one.1, "pruned and dense agree");
        assert_eq!(run(2), one);
        assert_eq!(run(4), one);
    }
}

#[test]
fn ties_across_chunks_go_to_the_lowest_index() {
    // 27 000 lattice points over 4 chunks: check the greedy rule and the tie rule exactly.
    let cloud = lattice(30);
    let chosen = farthest_point_sampling(&cloud, 40).unwrap();
    assert_greedy(&cloud, &chosen);
    // The first pick is the far corner (29, 29, 29), the last index.
    assert_eq!(chosen[1], cloud.len() - 1);
}

#[test]
fn prefix_property() {
    // Sampling fewer points gives a prefix of sampling more (for k < N).
    let cloud = random_cloud(3000, 9);
    let long = farthest_point_sampling(&cloud, 500).unwrap();
    for k in [1, 2, 17, 499] {
        assert_eq!(farthest_point_sampling(&cloud, k).unwrap(), long[..k]);
    }
}

#[test]
fn coverage_radius_decreases() {
    // The covering radius after t picks (the distance of the next pick) never increases.
    let cloud = random_cloud(4000, 2);
    let chosen = farthest_point_sampling(&cloud, 200).unwrap();
    let mut last = f64::INFINITY;
    for t in 1..chosen.len() {
        let r = chosen[..t]
            .iter()
            .map(|&j| d2(cloud[chosen[t]], cloud[j]))
            .fold(f64::INFINITY, f64::min);
        assert!(r <= last, "step {t}: {r} > {last}");
        last = r;
    }
}

proptest! {
    #![proptest_config(seeded_config(128))]

    #[test]
    fn greedy_rule_holds_on_random_clouds(points in point_cloud(0..60, 10.0), k in 0usize..70) {
        let chosen = farthest_point_sampling(&points, k).unwrap();
        prop_assert_eq!(chosen.len(), k.min(points.len()));
        if k >= points.len() {
            prop_assert_eq!(chosen, (0..points.len()).collect::<Vec<_>>());
        } else {
            assert_greedy(&points, &chosen);
        }
    }

    #[test]
    fn greedy_rule_holds_on_random_clouds_dense(points in point_cloud(0..60, 10.0), k in 0usize..70) {
        let chosen = farthest_point_sampling_dense(&points, k).unwrap();
        prop_assert_eq!(chosen.len(), k.min(points.len()));
        if k < points.len() {
            assert_greedy(&points, &chosen);
        }
    }

    #[test]
    fn greedy_rule_holds_with_duplicates(
        distinct in point_cloud(1..8, 3.0),
        picks in proptest::collection::vec(0usize..8, 1..40),
        k in 1usize..45,
    ) {
        let points: Vec<Vec3> = picks.iter().map(|&i| distinct[i % distinct.len()]).collect();
        let chosen = farthest_point_sampling(&points, k).unwrap();
        prop_assert_eq!(chosen.len(), k.min(points.len()));
        if k < points.len() {
            assert_greedy(&points, &chosen);
            // Every distinct position is taken before any repeat of an earlier one.
            let mut seen: Vec<Vec3> = Vec::new();
            let mut repeats_started = false;
            for &i in &chosen {
                let new = !seen.contains(&points[i]);
                prop_assert!(!(repeats_started && new), "a new position after a repeat: {:?}", chosen);
                repeats_started |= !new;
                seen.push(points[i]);
            }
        }
    }
}

proptest! {
    #![proptest_config(seeded_config(64))]

    /// Larger clouds (many buckets, some with duplicates): the bucket-pruned sampler returns
    /// exactly what the dense one does.
    #[test]
    fn pruned_equals_dense(mut points in point_cloud(256..3000, 10.0), dup_every in 2usize..50, k in 1usize..400) {
        let n = points.len();
        for i in (dup_every..n).step_by(dup_every) {
            points[i] = points[i / dup_every];
        }
        prop_assert_eq!(farthest_point_sampling(&points, k).unwrap(), farthest_point_sampling_dense(&points, k).unwrap());
    }
}

#[test]
fn better_is_a_total_order() {
    let cands = [(1.0, 3), (1.0, 2), (2.0, 9), (f64::NEG_INFINITY, usize::MAX)];
    for &a in &cands {
        for &b in &cands {
            assert_eq!(better(a, b), better(b, a));
        }
    }
    assert_eq!(better((1.0, 3), (1.0, 2)), (1.0, 2));
}

#[test]
fn spread_bits_interleaves() {
    assert_eq!(spread_bits(0b111), 0b1001001);
    assert_eq!(spread_bits(0x1f_ffff).count_ones(), 21);
    assert_eq!(spread_bits(1 << 20), 1 << 60);
}

#[test]
fn bound_never_exceeds_a_point_distance() {
    let mut rng = Rng::new(8);
    for _ in 0..200 {
        let pts: Vec<[f64; 3]> = (0..20)
            .map(|_| to_f64(Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0)) * 1e3))
            .collect();
        let order: Vec<usize> = (0..20).collect();
        let c = to_f64(Vec3::new(rng.range(-3.0, 3.0), rng.range(-3.0, 3.0), rng.range(-3.0, 3.0)) * 1e3);
        let lb = bucket_lower_bound(&pts, &order, c);
        for p in &pts {
            assert!(lb <= squared(p[0] - c[0], p[1] - c[1], p[2] - c[2]));
        }
    }
}

#[test]
fn pruned_matches_dense() {
    let mut clouds = vec![
        cloud(20_000, 1, [10.0, 10.0, 10.0]),
        cloud(5_000, 2, [10.0, 10.0, 0.0]), // planar
        cloud(3_000, 3, [100.0, 0.0, 0.0]), // a line
    ];
    // Far outliers stretch the Morton box.
    let mut outliers = cloud(10_000, 4, [1.0, 1.0, 1.0]);
    outliers.extend(cloud(30, 5, [1e5, 1e5, 1e5]));
    clouds.push(outliers);
    // A lattice: exact ties everywhere.
    let mut lattice = Vec::new();
    for z in 0..20 {
        for y in 0..20 {
            for x in 0..20 {
                lattice.push(Vec3::new(x as f32, y as f32, z as f32));
            }
        }
    }
    clouds.push(lattice);
    // Heavy duplication: 100 distinct positions repeated.
    let base = cloud(100, 6, [5.0, 5.0, 5.0]);
    clouds.push((0..4_000).map(|i| base[(i * 37) % 100]).collect());
    for (c, pts) in clouds.iter().enumerate() {
        for k in [2, 150, 700.min(pts.len() - 1)] {
            let dense = farthest_point_sampling_dense(pts, k).unwrap();
            let pruned = farthest_point_sampling(pts, k).unwrap();
            assert_eq!(pruned, dense, "cloud {c}, k = {k}");
        }
    }
    // Through the duplicate phase to the end.
    let dup = &clouds[5];
    let all = dup.len() - 1;
    assert_eq!(
        farthest_point_sampling(dup, all).unwrap(),
        farthest_point_sampling_dense(dup, all).unwrap()
    );
}
