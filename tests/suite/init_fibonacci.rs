//! The Fibonacci sky sphere: points on the sphere, spacing, the small cases, the sky-count rule
//! and the sky radius (reference and robust).

use bbsplat::init::fibonacci::{
    SKY_POINTS, SKY_POINTS_SMALL, SkyRadius, fibonacci_sphere, sky_point_count, sky_radius, sky_radius_reference,
    sky_sphere,
};
use bbsplat::rng::Rng;
use bbsplat::strategies::seeded_config;
use glam::Vec3;
use proptest::prelude::*;

/// Smallest pairwise distance, by brute force in f64.
fn min_pairwise(points: &[Vec3]) -> f64 {
    let p: Vec<[f64; 3]> = points.iter().map(|v| [v.x as f64, v.y as f64, v.z as f64]).collect();
    let mut best = f64::INFINITY;
    for i in 0..p.len() {
        for j in i + 1..p.len() {
            let d = (p[i][0] - p[j][0]).powi(2) + (p[i][1] - p[j][1]).powi(2) + (p[i][2] - p[j][2]).powi(2);
            best = best.min(d);
        }
    }
    best.sqrt()
}

/// The fraction of the ideal spacing √(4π/n) that the closest pair must keep (n ≥ 2). The
/// closest pair is the pole and its neighbour at ≈ 2/√n = 0.564·√(4π/n); the smallest ratio
/// measured for 2 ≤ n ≤ 4096 is recorded in docs/numerics-init-loss.md.
const SPACING_FRACTION: f64 = 0.55;

#[test]
fn points_lie_on_the_sphere() {
    for &(n, radius, centre) in &[
        (1usize, 1.0f32, Vec3::ZERO),
        (2, 3.0, Vec3::new(1.0, -2.0, 0.5)),
        (3, 0.5, Vec3::ZERO),
        (1000, 250.0, Vec3::new(10.0, 20.0, -30.0)),
        (10_000, 1.0e4, Vec3::ZERO),
        (10_000, 7.5, Vec3::new(-3.0, 2.0, 1.0)),
    ] {
        let pts = fibonacci_sphere(n, radius, centre);
        assert_eq!(pts.len(), n);
        for (i, p) in pts.iter().enumerate() {
            let d = (p.as_dvec3() - centre.as_dvec3()).length();
            let rel = (d - radius as f64).abs() / radius as f64;
            assert!(rel <= 1e-5, "n = {n}, point {i}: |p − c| = {d}, radius {radius}");
        }
    }
}

#[test]
fn the_smallest_cases() {
    assert!(fibonacci_sphere(0, 1.0, Vec3::ZERO).is_empty());
    let c = Vec3::new(1.0, 2.0, 3.0);
    assert_eq!(fibonacci_sphere(1, 2.0, c), vec![c + Vec3::new(0.0, 2.0, 0.0)]);
    let two = fibonacci_sphere(2, 2.0, c);
    assert_eq!(two[0], c + Vec3::new(0.0, 2.0, 0.0));
    // The south pole: r = √(1 − 1) = 0, so x = z = 0 exactly.
    assert_eq!(two[1], c + Vec3::new(0.0, -2.0, 0.0));
    let three = fibonacci_sphere(3, 1.0, Vec3::ZERO);
    assert_eq!(three[1].y, 0.0);
    assert!((three[1].length() - 1.0).abs() < 1e-6);
}

#[test]
fn matches_the_formula() {
    // Spec §8: y = 1 − 2i/(n−1), r = √(1 − y²), θ = i·π(√5 − 1), (cos θ·r, y, sin θ·r).
    let n = 777;
    let pts = fibonacci_sphere(n, 1.0, Vec3::ZERO);
    for (i, p) in pts.iter().enumerate() {
        let y = 1.0 - 2.0 * i as f64 / (n - 1) as f64;
        let r = (1.0 - y * y).sqrt();
        let theta = i as f64 * std::f64::consts::PI * (5f64.sqrt() - 1.0);
        let want = [theta.cos() * r, y, theta.sin() * r];
        for (axis, (&got, &w)) in p.to_array().iter().zip(&want).enumerate() {
            assert!((got as f64 - w).abs() < 1e-6, "point {i} axis {axis}: {got} vs {w}");
        }
    }
}

#[test]
fn spacing_is_near_the_ideal() {
    let mut worst = (f64::INFINITY, 0usize);
    let sizes = (2..=300).chain([401, 512, 1000, 1500, 2048, 3000, 4096]);
    for n in sizes {
        let radius = 3.0;
        let pts = fibonacci_sphere(n, radius, Vec3::ZERO);
        let ratio = min_pairwise(&pts) / ((4.0 * std::f64::consts::PI / n as f64).sqrt() * radius as f64);
        if ratio < worst.0 {
            worst = (ratio, n);
        }
        assert!(
            ratio >= SPACING_FRACTION,
            "n = {n}: closest pair at {ratio:.3} of the ideal spacing"
        );
    }
    println!("smallest closest-pair / √(4π/n)·r: {:.4} at n = {}", worst.0, worst.1);
}

#[test]
fn spread_is_even_in_longitude() {
    // Octant counts: each of the 8 octants holds n/8 points up to a few percent.
    let n = 10_000;
    let pts = fibonacci_sphere(n, 1.0, Vec3::ZERO);
    let mut counts = [0usize; 8];
    for p in &pts {
        let o = (p.x > 0.0) as usize + 2 * (p.y > 0.0) as usize + 4 * (p.z > 0.0) as usize;
        counts[o] += 1;
    }
    for c in counts {
        assert!(
            (c as f64 - n as f64 / 8.0).abs() < 0.01 * n as f64 / 8.0 + 2.0,
            "{counts:?}"
        );
    }
}

#[test]
fn sky_point_count_boundaries() {
    for (initial, sky) in [
        (0, 0),
        (9_999, 0),
        (10_000, SKY_POINTS_SMALL),
        (15_000, 2_000),
        (20_000, 2_000),
        (20_001, SKY_POINTS),
        (150_000, 10_000),
        (usize::MAX, 10_000),
    ] {
        assert_eq!(sky_point_count(initial), sky, "{initial} initial points");
    }
}

fn cube_cloud(n: usize, half: f32, seed: u64) -> Vec<Vec3> {
    let mut rng = Rng::new(seed);
    (0..n)
        .map(|_| Vec3::new(rng.range(-half, half), rng.range(-half, half), rng.range(-half, half)))
        .collect()
}

#[test]
fn robust_radius_ignores_far_outliers() {
    let mut cloud = cube_cloud(20_000, 5.0, 1);
    let clean = sky_radius(&cloud);
    assert_eq!(
        clean,
        sky_radius_reference(&cloud),
        "no far tail: same as the reference"
    );
    // 0.5 % outliers, 1e3 to 1e6 away in random directions.
    let mut rng = Rng::new(2);
    for _ in 0..100 {
        let d = Vec3::new(rng.normal(), rng.normal(), rng.normal()).normalize();
        cloud.push(d * 10f32.powf(rng.range(3.0, 6.0)));
    }
    let reference = sky_radius_reference(&cloud);
    let robust = sky_radius(&cloud);
    assert!(reference > 500.0, "{reference}");
    // Beyond every inlier (L∞ ≤ 5) and not much further.
    assert!((5.0..=5.5).contains(&robust), "{robust}");
    // The enclosing rule contains every point; the reference rule is the largest L∞ norm.
    let enclosing = SkyRadius::Enclosing.radius(&cloud);
    assert!(cloud.iter().all(|p| p.length() <= enclosing));
    assert_eq!(
        reference,
        cloud.iter().map(|p| p.abs().max_element()).fold(0.0, f32::max)
    );
    // Beyond 1 % outliers the 99th percentile is an outlier: the rule's breakdown point.
    let mut flooded = cube_cloud(1_000, 5.0, 3);
    flooded.extend(std::iter::repeat_n(Vec3::new(1.0e4, 0.0, 0.0), 20));
    assert_eq!(sky_radius(&flooded), 1.0e4);
    let strict = SkyRadius::Robust {
        quantile: 0.95,
        margin: 1.1,
    };
    assert!(strict.radius(&flooded) <= 5.5);
}

#[test]
fn radius_edge_cases() {
    for rule in [SkyRadius::Reference, SkyRadius::Enclosing, SkyRadius::DEFAULT_ROBUST] {
        assert_eq!(rule.radius(&[]), 0.0);
        assert_eq!(rule.radius(&[Vec3::NAN]), 0.0);
        // Non-finite points are ignored.
        let r = rule.radius(&[Vec3::new(3.0, -4.0, 0.0), Vec3::new(f32::INFINITY, 0.0, 0.0)]);
        assert!(r == 4.0 || r == 5.0, "{rule:?}: {r}");
    }
    assert_eq!(SkyRadius::Enclosing.radius(&[Vec3::new(3.0, -4.0, 0.0)]), 5.0);
    // Quantile 0 is the smallest norm, 1 the largest (then capped).
    let pts = [Vec3::splat(1.0), Vec3::splat(2.0), Vec3::splat(3.0)];
    let rule = |q| SkyRadius::Robust {
        quantile: q,
        margin: 1.0,
    };
    assert_eq!(rule(0.0).radius(&pts), 1.0);
    assert_eq!(rule(0.5).radius(&pts), 2.0);
    assert_eq!(rule(1.0).radius(&pts), 3.0);
    assert_eq!(rule(f32::NAN).radius(&pts), 3.0);
}

#[test]
fn sky_sphere_follows_the_rules() {
    let small = cube_cloud(15_000, 2.0, 4);
    let sky = sky_sphere(&small, SkyRadius::Reference);
    assert_eq!(sky.len(), 2_000);
    let r = sky_radius_reference(&small);
    assert!(sky.iter().all(|p| (p.length() - r).abs() <= 1e-5 * r));
    assert!(sky_sphere(&small[..9_000], SkyRadius::DEFAULT_ROBUST).is_empty());
}

proptest! {
    #![proptest_config(seeded_config(64))]

    #[test]
    fn random_spheres(n in 0usize..3000, radius in 0.01f32..1.0e4, centre in proptest::array::uniform3(-100.0f32..100.0)) {
        let centre = Vec3::from_array(centre);
        let pts = fibonacci_sphere(n, radius, centre);
        prop_assert_eq!(pts.len(), n);
        // Rounding of the f32 coordinates: half an ulp of |centre| + radius per axis.
        let slack = 1e-5 * radius as f64 + 4.0 * f32::EPSILON as f64 * centre.abs().max_element() as f64;
        for p in &pts {
            let d = (p.as_dvec3() - centre.as_dvec3()).length();
            prop_assert!((d - radius as f64).abs() <= slack, "{} vs {}", d, radius);
        }
        // North to south.
        prop_assert!(pts.windows(2).all(|w| w[0].y >= w[1].y));
    }
}
