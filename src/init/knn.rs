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
//! [`mean_sq_dist_3nn`] uses a k-d tree ([`kiddo`]); [`mean_sq_dist_3nn_brute`] is the `O(N²)`
//! oracle. The tree only proposes candidates: a first query returns the 5 nearest items by the
//! tree's own arithmetic (which may differ from ours in the last bits and, on ties, in which
//! item is returned); the largest distance `r` of the first 4 is widened by `1e-12` relative.
//! If the 5th lies beyond that radius, the first 4 are the candidates; otherwise (ties, and
//! duplicates) every item within the radius is collected by a second query. Every point whose distance in *our* arithmetic is
//! among the 3 smallest is inside that radius (both computations of a sum of three non-negative
//! squares are within a few ulps, i.e. `≤ 1e-15` relative, of the exact value), so the final
//! selection, done in our arithmetic over the candidates, is exactly the brute-force one.
//! Which tied items the tree returns changes nothing: only the multiset of distances matters.
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

use glam::Vec3;
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use rayon::prelude::*;
use std::num::NonZeroUsize;

/// Number of neighbours averaged.
pub const NEIGHBOURS: usize = 3;

/// Relative widening of the tree's 4th-nearest distance before the exact re-selection.
const WIDEN: f64 = 1e-12;

#[inline]
fn sq_dist(a: [f64; 3], b: [f64; 3]) -> f64 {
    let (dx, dy, dz) = (a[0] - b[0], a[1] - b[1], a[2] - b[2]);
    dx * dx + dy * dy + dz * dz
}

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
    let mut out = vec![0.0f32; points.len()];
    if finite.len() <= NEIGHBOURS + 1 {
        // Too few points for the tree to help: every other point is a neighbour.
        for (a, &(i, p)) in finite.iter().enumerate() {
            let mut d: Vec<f64> = finite
                .iter()
                .enumerate()
                .filter(|&(b, _)| b != a)
                .map(|(_, &(_, q))| sq_dist(p, q))
                .collect();
            out[i] = mean_of_smallest(&mut d);
        }
        return out;
    }
    let coords: Vec<[f64; 3]> = finite.iter().map(|&(_, p)| p).collect();
    let tree: ImmutableKdTree<f64, 3> = ImmutableKdTree::new_from_slice(&coords).expect("finite points build a tree");
    let five = NonZeroUsize::new(NEIGHBOURS + 2).expect("non-zero");
    let values: Vec<f32> = (0..coords.len())
        .into_par_iter()
        .map(|a| {
            let p = coords[a];
            // Sorted by the tree's distance: the 4 nearest (self or a duplicate included) and
            // the 5th, which tells whether the 4th is separated from the rest.
            let nearest = tree.query(&p).nearest_n::<SquaredEuclidean<f64>>(five).execute();
            let r = nearest[..NEIGHBOURS + 1]
                .iter()
                .map(|n| n.distance)
                .fold(0.0f64, f64::max);
            let radius = r + r * WIDEN;
            let separated = nearest.len() > NEIGHBOURS + 1 && nearest[NEIGHBOURS + 1].distance > radius;
            let items: Vec<usize> = if separated {
                nearest[..NEIGHBOURS + 1].iter().map(|n| n.item as usize).collect()
            } else {
                tree.query(&p)
                    .within::<SquaredEuclidean<f64>>(radius)
                    .unsorted()
                    .execute()
                    .iter()
                    .map(|c| c.item as usize)
                    .collect()
            };
            let mut d: Vec<f64> = items
                .into_iter()
                .filter(|&b| b != a)
                .map(|b| sq_dist(p, coords[b]))
                .collect();
            mean_of_smallest(&mut d)
        })
        .collect();
    for (&(i, _), v) in finite.iter().zip(values) {
        out[i] = v;
    }
    out
}
