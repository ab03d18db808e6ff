//! Mean squared distance to the 3 nearest neighbours, the statistic that sets the initial
//! billboard size (spec §1.1, simple-knn `distCUDA2`).
//!
//! # Conventions
//!
//! - For point `i`, the value is the mean of the `k = min(3, M − 1)` smallest squared
//!   distances from `i` to the *other* finite points (`M` = number of finite points).
//!   Duplicates of `i` count as neighbours at distance 0; `i` itself does not.
//! - **Arithmetic**: squared distances are computed in **f64** from the f32 coordinates as
//!   `dx·dx + dy·dy + dz·dz` (in that order; the differences are exact in f64), the `k`
//!   smallest are summed in increasing order in f64, divided by `k` and rounded once to f32.
//!   Both functions below use this exact expression, so they agree bit for bit.
//! - **Degenerate input**: a point with no finite neighbour (a cloud of one point) and every
//!   non-finite point (NaN or ±∞ coordinate) gets `0.0`; non-finite points are never anyone's
//!   neighbour. (`RawBillboards::from_points` floors the value at `1e-7`, as the reference.)
//!
//! [`mean_sq_dist_3nn`] uses the crate's k-d tree ([`crate::kdtree`]), which ranks points by
//! [`crate::kdtree::sq_dist`], the expression above, and finds the `k` nearest exactly: the
//! distances it returns are the brute-force oracle's [`mean_sq_dist_3nn_brute`] (`O(N²)`)
//! smallest ones, so the two agree bit for bit. Which of several tied items it returns changes
//! nothing: only the multiset of distances matters.
//!
//! Determinism: each point's value is computed by one thread from the same candidates with the
//! same operations, so the output is identical for any number of rayon threads.
//!
//! ```
//! use bbsplat::init::knn::{mean_sq_dist_3nn, mean_sq_dist_3nn_brute};
//! use glam::Vec3;
//! let pts = [Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z, Vec3::splat(5.0)];
//! let d = mean_sq_dist_3nn(&pts);
//! assert_eq!(d[0], 1.0); // three neighbours at distance 1
//! assert_eq!(d, mean_sq_dist_3nn_brute(&pts));
//! assert_eq!(mean_sq_dist_3nn(&[Vec3::ONE]), vec![0.0]); // no neighbour
//! ```

use crate::kdtree::{KdTree, sq_dist};
use glam::Vec3;
use rayon::prelude::*;

/// Number of neighbours averaged.
pub const NEIGHBOURS: usize = 3;

fn to_f64(p: Vec3) -> [f64; 3] {
    [p.x as f64, p.y as f64, p.z as f64]
}

/// Mean of the (up to) 3 smallest values of `d` (which is modified: partially sorted).
fn mean_of_smallest(d: &mut [f64]) -> f32 {
    let k = NEIGHBOURS.min(d.len());
    if k == 0 {
        return 0.0;
    }
    if d.len() > k {
        d.select_nth_unstable_by(k - 1, f64::total_cmp);
    }
    let smallest = &mut d[..k];
    smallest.sort_unstable_by(f64::total_cmp);
    (smallest.iter().sum::<f64>() / k as f64) as f32
}

/// The brute-force oracle, `O(N²)` (parallel over query points). Same conventions and the same
/// result, bit for bit, as [`mean_sq_dist_3nn`].
pub fn mean_sq_dist_3nn_brute(points: &[Vec3]) -> Vec<f32> {
    let coords: Vec<Option<[f64; 3]>> = points.iter().map(|p| p.is_finite().then(|| to_f64(*p))).collect();
    (0..points.len())
        .into_par_iter()
        .map(|i| {
            let Some(p) = coords[i] else { return 0.0 };
            let mut d: Vec<f64> = coords
                .iter()
                .enumerate()
                .filter(|&(j, q)| j != i && q.is_some())
                .map(|(_, q)| sq_dist(p, q.expect("filtered")))
                .collect();
            mean_of_smallest(&mut d)
        })
        .collect()
}

/// Mean squared distance to the 3 nearest other points, for every point, with a k-d tree:
/// `O(N log N)`. See the [module documentation](self) for the exact conventions.
pub fn mean_sq_dist_3nn(points: &[Vec3]) -> Vec<f32> {
    // Finite points only, with their original index (the tree's item is the position in
    // `finite`).
    let finite: Vec<(usize, [f64; 3])> = points
        .iter()
        .enumerate()
        .filter(|(_, p)| p.is_finite())
        .map(|(i, p)| (i, to_f64(*p)))
        .collect();
    let coords: Vec<[f64; 3]> = finite.iter().map(|&(_, p)| p).collect();
    let tree = KdTree::new(&coords);
    let values: Vec<f32> = (0..coords.len())
        .into_par_iter()
        .map(|a| mean_of_smallest(&mut tree.nearest::<NEIGHBOURS>(coords[a], Some(a)).distances()))
        .collect();
    let mut out = vec![0.0f32; points.len()];
    for (&(i, _), v) in finite.iter().zip(values) {
        out[i] = v;
    }
    out
}
