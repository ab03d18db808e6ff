//! The k-d tree 3-NN statistic equals the brute-force oracle bit for bit, on awkward clouds,
//! and does not depend on the number of threads.

use bbsplat::init::knn::{mean_sq_dist_3nn, mean_sq_dist_3nn_brute};
use bbsplat::model::RawBillboards;
use bbsplat::rng::Rng;
use glam::Vec3;

use bbsplat::strategies::box_cloud as cloud;

fn check(points: &[Vec3], what: &str) {
    let tree = mean_sq_dist_3nn(points);
    let brute = mean_sq_dist_3nn_brute(points);
    assert_eq!(tree.len(), points.len(), "{what}");
    for (i, (t, b)) in tree.iter().zip(&brute).enumerate() {
        assert_eq!(
            t.to_bits(),
            b.to_bits(),
            "{what}: point {i} ({:?}): tree {t} vs brute {b}",
            points[i]
        );
    }
}

#[test]
fn tree_equals_brute_force_on_random_clouds() {
    for seed in 0..6u64 {
        let n = 50 + 400 * seed as usize;
        check(
            &cloud(n, seed, [10.0, 10.0, 10.0]),
            &format!("uniform, seed {seed}, n {n}"),
        );
        check(
            &cloud(n, seed + 100, [10.0, 10.0, 0.0]),
            &format!("planar, seed {seed}"),
        );
        // Very different scales per axis and far from the origin (f32 spacing matters).
        let shifted: Vec<Vec3> = cloud(n, seed + 200, [1e-3, 5.0, 1e4])
            .into_iter()
            .map(|p| p + Vec3::new(1e4, -3e3, 7.0))
            .collect();
        check(&shifted, &format!("anisotropic shifted, seed {seed}"));
    }
}

#[test]
fn tree_equals_brute_force_with_duplicates_and_ties() {
    // Heavy duplication: 40 distinct positions repeated, some many times (more than a leaf).
    let base = cloud(40, 7, [3.0, 3.0, 3.0]);
    let dup: Vec<Vec3> = (0..3000).map(|i| base[(i * i + 3 * i) % 40]).collect();
    check(&dup, "duplicates");
    // 100 copies of a single point plus a few others.
    let mut stack = vec![Vec3::new(1.0, 2.0, 3.0); 100];
    stack.extend(cloud(20, 8, [1.0, 1.0, 1.0]));
    check(&stack, "one point stacked 100 times");
    // An integer lattice: every distance is tied many times.
    let mut lattice = Vec::new();
    for z in 0..12 {
        for y in 0..12 {
            for x in 0..12 {
                lattice.push(Vec3::new(x as f32, y as f32, z as f32) * 0.5);
            }
        }
    }
    check(&lattice, "lattice");
    let all_same = vec![Vec3::splat(-2.5); 37];
    check(&all_same, "all identical");
    assert!(mean_sq_dist_3nn(&all_same).iter().all(|&d| d == 0.0));
}

#[test]
fn tree_equals_brute_force_on_collinear_and_tiny_clouds() {
    let line: Vec<Vec3> = (0..2000).map(|i| Vec3::new(0.37 * i as f32, 0.0, 0.0)).collect();
    check(&line, "evenly spaced line");
    let mut rng = Rng::new(9);
    let dir = Vec3::new(1.0, 2.0, -0.5).normalize();
    let random_line: Vec<Vec3> = (0..1500).map(|_| dir * rng.range(-50.0, 50.0)).collect();
    check(&random_line, "random points on a slanted line");
    for n in 0..=6 {
        for seed in 0..5u64 {
            let pts = cloud(n, 300 + seed, [2.0, 2.0, 2.0]);
            check(&pts, &format!("{n} points, seed {}", 300 + seed));
        }
    }
    assert_eq!(mean_sq_dist_3nn(&[]), Vec::<f32>::new());
    assert_eq!(mean_sq_dist_3nn(&[Vec3::ONE]), vec![0.0]);
    // Two points: one neighbour each.
    assert_eq!(
        mean_sq_dist_3nn(&[Vec3::ZERO, Vec3::new(0.0, 3.0, 0.0)]),
        vec![9.0, 9.0]
    );
    // Four points: exactly three neighbours each.
    let d = mean_sq_dist_3nn(&[Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z]);
    assert_eq!(d[0], 1.0);
    assert!((d[1] - (1.0 + 2.0 + 2.0) / 3.0).abs() < 1e-7);
}

#[test]
fn non_finite_points_are_ignored() {
    let mut pts = cloud(200, 11, [1.0, 1.0, 1.0]);
    pts[3] = Vec3::new(f32::NAN, 0.0, 0.0);
    pts[50] = Vec3::new(0.0, f32::INFINITY, 0.0);
    check(&pts, "with NaN and inf");
    let d = mean_sq_dist_3nn(&pts);
    assert_eq!((d[3], d[50]), (0.0, 0.0));
    let finite: Vec<Vec3> = pts.iter().copied().filter(|p| p.is_finite()).collect();
    let d_finite = mean_sq_dist_3nn(&finite);
    let kept: Vec<f32> = d
        .iter()
        .enumerate()
        .filter(|(i, _)| *i != 3 && *i != 50)
        .map(|(_, &v)| v)
        .collect();
    assert_eq!(kept, d_finite);
}

#[test]
fn result_is_independent_of_thread_count() {
    let mut pts = cloud(30_000, 12, [5.0, 5.0, 2.0]);
    let head = pts[..500].to_vec();
    pts.extend(head);
    let run = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| mean_sq_dist_3nn(&pts))
    };
    let one = run(1);
    assert_eq!(one, run(2));
    assert_eq!(one, run(4));
}

#[test]
fn from_points_uses_the_tree_statistic() {
    let pts = cloud(500, 13, [1.0, 1.0, 1.0]);
    let m = RawBillboards::from_points(&pts, &vec![[0.3; 3]; pts.len()], 16, 5);
    let d = mean_sq_dist_3nn_brute(&pts);
    for (i, &di) in d.iter().enumerate() {
        assert_eq!(m.log_scales[i].x, di.max(1e-7).sqrt().ln(), "point {i}");
        assert_eq!(m.log_scales[i].x, m.log_scales[i].y);
    }
    // A single point gets the 1e-7 floor.
    let one = RawBillboards::from_points(&[Vec3::ONE], &[[0.5; 3]], 16, 0);
    assert_eq!(one.log_scales[0].x, 1e-7f32.sqrt().ln());
}
