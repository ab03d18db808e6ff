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

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn brute_force(points: &[(f64, f64)]) -> Vec<usize> {
        let ok = |p: (f64, f64)| !p.0.is_nan() && !p.1.is_nan();
        let mut front: Vec<usize> = (0..points.len())
            .filter(|&i| ok(points[i]))
            .filter(|&i| {
                let (ci, qi) = points[i];
                !(0..points.len()).any(|j| {
                    let (cj, qj) = points[j];
                    ok(points[j]) && cj <= ci && qj >= qi && (cj < ci || qj > qi)
                })
            })
            .collect();
        front.sort_by(|&a, &b| points[a].0.partial_cmp(&points[b].0).unwrap().then(a.cmp(&b)));
        front
    }

    #[test]
    fn empty_and_single() {
        assert!(pareto_front(&[]).is_empty());
        assert_eq!(pareto_front(&[(1.0, 1.0)]), vec![0]);
        assert!(pareto_front(&[(f64::NAN, 1.0)]).is_empty());
        assert!(pareto_front(&[(1.0, f64::NAN)]).is_empty());
    }

    #[test]
    fn duplicates_are_all_kept() {
        assert_eq!(pareto_front(&[(1.0, 5.0), (1.0, 5.0), (2.0, 4.0)]), vec![0, 1]);
    }

    #[test]
    fn equal_cost_keeps_best_quality_only() {
        assert_eq!(pareto_front(&[(1.0, 4.0), (1.0, 5.0), (2.0, 6.0)]), vec![1, 2]);
    }

    #[test]
    fn equal_quality_keeps_cheapest_only() {
        assert_eq!(pareto_front(&[(3.0, 5.0), (1.0, 5.0), (2.0, 5.0)]), vec![1]);
    }

    #[test]
    fn nan_neither_joins_nor_dominates() {
        // The NaN-cost point has the best quality but must not hide (2, 3).
        assert_eq!(pareto_front(&[(f64::NAN, 99.0), (2.0, 3.0), (1.0, f64::NAN)]), vec![1]);
    }

    #[test]
    fn infinities_compare_as_usual() {
        let pts = [(1.0, f64::NEG_INFINITY), (2.0, 10.0), (f64::INFINITY, f64::INFINITY)];
        assert_eq!(pareto_front(&pts), vec![0, 1, 2]);
    }

    proptest! {
        #[test]
        fn matches_brute_force(
            raw in prop::collection::vec((0u8..8, 0u8..8, 0u8..20), 0..40)
        ) {
            // Small integer grids force many ties and duplicates; code 0 of the third value
            // injects a NaN.
            let points: Vec<(f64, f64)> = raw
                .iter()
                .map(|&(c, q, n)| match n {
                    0 => (f64::NAN, q as f64),
                    1 => (c as f64, f64::NAN),
                    _ => (c as f64, q as f64),
                })
                .collect();
            prop_assert_eq!(pareto_front(&points), brute_force(&points));
        }
    }
}
