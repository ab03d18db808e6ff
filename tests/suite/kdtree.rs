//! The k-d tree's K nearest equal a brute-force scan's, `(distance, item)` pair for pair, on
//! spread, flat, collinear, duplicated and lattice points, with and without the skipped item.

use bbsplat::kdtree::{KdTree, LEAF, sq_dist};
use bbsplat::strategies::box_cloud;
use proptest::prelude::*;

/// The `k` smallest `(sq_dist, item)` pairs in lexicographic order, by scanning every item.
fn brute(points: &[[f64; 3]], q: [f64; 3], k: usize, skip: Option<usize>) -> Vec<(f64, usize)> {
    let mut all: Vec<(f64, usize)> = (0..points.len())
        .filter(|&i| Some(i) != skip)
        .map(|i| (sq_dist(q, points[i]), i))
        .collect();
    all.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    all.truncate(k);
    all
}

fn check_all<const K: usize>(points: &[[f64; 3]], queries: &[[f64; 3]], what: &str) {
    let tree = KdTree::new(points);
    assert_eq!(tree.len(), points.len());
    for (qi, &q) in queries.iter().enumerate() {
        let skip = (qi % 2 == 0 && !points.is_empty()).then_some(qi % points.len().max(1));
        let got = tree.nearest::<K>(q, skip);
        let want = brute(points, q, K, skip);
        assert_eq!(
            got.as_slice(),
            &want[..],
            "{what}: query {qi} {q:?}, K {K}, skip {skip:?}"
        );
    }
}

fn to_f64(points: Vec<glam::Vec3>) -> Vec<[f64; 3]> {
    points.into_iter().map(|p| p.as_dvec3().to_array()).collect()
}

#[test]
fn nearest_equal_a_scan_on_awkward_point_sets() {
    let spread = to_f64(box_cloud(3000, 1, [5.0, 5.0, 5.0]));
    let flat = to_f64(box_cloud(2000, 2, [5.0, 5.0, 0.0]));
    let line: Vec<[f64; 3]> = (0..1000).map(|i| [0.25 * i as f64, 0.0, 0.0]).collect();
    let base = to_f64(box_cloud(30, 3, [1.0, 1.0, 1.0]));
    // Each position many times, more than a leaf holds.
    let duplicated: Vec<[f64; 3]> = (0..(40 * LEAF)).map(|i| base[(i * 7 + i / 3) % 30]).collect();
    let mut lattice = Vec::new();
    for z in 0..8 {
        for y in 0..8 {
            for x in 0..8 {
                lattice.push([x as f64, y as f64, z as f64]);
            }
        }
    }
    for (points, what) in [
        (&spread, "spread"),
        (&flat, "flat"),
        (&line, "collinear"),
        (&duplicated, "duplicated"),
        (&lattice, "lattice (all ties)"),
    ] {
        // The points themselves and points between and beyond them.
        let mut queries: Vec<[f64; 3]> = points.iter().step_by(7).copied().collect();
        queries.extend(to_f64(box_cloud(100, 9, [12.0, 12.0, 12.0])));
        check_all::<1>(points, &queries, what);
        check_all::<3>(points, &queries, what);
        check_all::<6>(points, &queries, what);
    }
}

#[test]
fn small_and_empty_trees_return_what_they_hold() {
    let tree = KdTree::new(&[]);
    assert!(tree.is_empty());
    assert!(tree.nearest::<3>([0.0; 3], None).as_slice().is_empty());
    let two = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]];
    let tree = KdTree::new(&two);
    assert_eq!(tree.nearest::<3>([0.2, 0.0, 0.0], None).items(), vec![0, 1]);
    assert_eq!(tree.nearest::<3>([0.2, 0.0, 0.0], Some(0)).items(), vec![1]);
    for n in 0..=(2 * LEAF + 3) {
        let points = to_f64(box_cloud(n, n as u64, [1.0, 1.0, 1.0]));
        check_all::<4>(
            &points,
            &to_f64(box_cloud(20, 99, [1.5, 1.5, 1.5])),
            &format!("n = {n}"),
        );
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]
    /// Random clouds snapped to a coarse grid (many exact ties) and random queries.
    #[test]
    fn nearest_equal_a_scan_on_random_snapped_clouds(
        raw in prop::collection::vec((-20i32..20, -20i32..20, -3i32..3), 1..400),
        queries in prop::collection::vec((-30i32..30, -30i32..30, -6i32..6), 1..20),
    ) {
        let points: Vec<[f64; 3]> = raw.iter().map(|&(x, y, z)| [x as f64 * 0.5, y as f64 * 0.5, z as f64]).collect();
        let queries: Vec<[f64; 3]> = queries.iter().map(|&(x, y, z)| [x as f64 * 0.3, y as f64 * 0.3, z as f64 * 0.5]).collect();
        check_all::<3>(&points, &queries, "snapped");
        check_all::<1>(&points, &queries, "snapped");
    }
}
