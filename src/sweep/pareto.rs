//! Pareto fronts of (cost, quality) points: lower cost and higher quality are better.

use std::cmp::Ordering;

/// Indices of the non-dominated points of `points = [(cost, quality)]`, sorted by increasing
/// cost (ties by index).
///
/// Point `i` is dominated when some `j` has `cost_j ≤ cost_i` and `quality_j ≥ quality_i` with
/// at least one strict inequality. Consequences: exact duplicates do not dominate each other and
/// are all on the front; of several points with the same cost only those with the best quality
/// can be on it; of several with the same quality only the cheapest. A point with a NaN
/// coordinate is never on the front and dominates nothing. Infinities compare as usual.
/// `O(n log n)`.
///
/// ```
/// use bbsplat::sweep::pareto_front;
/// // (seconds, PSNR dB)
/// let runs = [(10.0, 20.0), (20.0, 19.0), (30.0, 25.0), (30.0, 24.0), (f64::NAN, 40.0)];
/// assert_eq!(pareto_front(&runs), vec![0, 2]);
/// ```
pub fn pareto_front(points: &[(f64, f64)]) -> Vec<usize> {
    let mut order: Vec<usize> = (0..points.len())
        .filter(|&i| !points[i].0.is_nan() && !points[i].1.is_nan())
        .collect();
    // Cost ascending, then quality descending, then index: the first point of each equal-cost
    // group has the group's best quality.
    order.sort_by(|&a, &b| {
        let (pa, pb) = (points[a], points[b]);
        pa.0.partial_cmp(&pb.0)
            .unwrap_or(Ordering::Equal)
            .then(pb.1.partial_cmp(&pa.1).unwrap_or(Ordering::Equal))
            .then(a.cmp(&b))
    });
    let mut front = Vec::new();
    // Best quality among points of strictly smaller cost.
    let mut best_cheaper = f64::NEG_INFINITY;
    let mut have_cheaper = false;
    let mut k = 0;
    while k < order.len() {
        let cost = points[order[k]].0;
        let group_best = points[order[k]].1;
        let mut end = k;
        while end < order.len() && points[order[end]].0 == cost {
            end += 1;
        }
        if !have_cheaper || group_best > best_cheaper {
            front.extend(order[k..end].iter().copied().filter(|&i| points[i].1 == group_best));
            best_cheaper = group_best;
        }
        have_cheaper = true;
        k = end;
    }
    front
}
