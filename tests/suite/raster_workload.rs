//! Workload statistics: nearest-rank quantiles.

use bbsplat::testing_internals::raster::quantile;

#[test]
fn nearest_rank_quantiles() {
    let v = [1, 2, 3, 4, 5, 6, 7, 8, 9, 10];
    assert_eq!(quantile(&v, 0.5), 5);
    assert_eq!(quantile(&v, 0.9), 9);
    assert_eq!(quantile(&v, 0.1), 1);
    assert_eq!(quantile::<u32>(&[], 0.5), 0);
}
