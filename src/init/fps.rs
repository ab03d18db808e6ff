//! Farthest point sampling (FPS): pick `k` points of a cloud that are spread as evenly as
//! possible, to reduce an SfM cloud to the primitive budget (spec §8.1).
//!
//! # Conventions
//!
//! - **Start** at index 0 (as the reference, pytorch3d `sample_farthest_points` with
//!   `random_start_point = False`).
//! - **Greedy rule**: each next point maximises the Euclidean distance to the set already
//!   chosen, i.e. `argmax_i min_{j ∈ chosen} |p_i − p_j|`. **Ties** go to the lowest index.
//! - **Distances** are squared Euclidean distances computed in **f64** from the f32
//!   coordinates. The coordinate differences of two f32 values are exact in f64 (for points
//!   within a factor 2²⁹ of each other in magnitude) and the squares and sums carry 53-bit
//!   precision, so near-ties are decided by the geometry rather than by f32 rounding, and the
//!   result does not depend on which distance is written first. Squared distances order like
//!   distances, so no square root is taken.
//! - **Order of the result**: the indices in the order they were chosen (the first is 0).
//! - **`k ≥ N`**: every index `0..N` in index order (nothing needs to be dropped; the set is the
//!   one FPS would return, the order is not the FPS order). `k = 0` or `N = 0`: empty.
//! - **Duplicates**: a point already chosen is never chosen again. Once every distinct position
//!   has been chosen, all remaining points are at distance 0 from the chosen set and are taken
//!   in increasing index order (the tie rule). The result therefore always holds `min(k, N)`
//!   distinct indices. (pytorch3d instead re-selects index 0 once all distances are 0, which
//!   produces repeated indices.)
//! - **Non-finite coordinates** (NaN, ±∞) are rejected with [`FpsError::NonFinitePoint`]
//!   naming the first offending index, whatever `k` is.
//!
//! # Cost and determinism
//!
//! `O(N·k)` time and `O(N)` memory: a copy of the coordinates in f64 (24 bytes per point) and
//! the running minimum squared distance of every point to the chosen set (8 bytes per point).
//! Each step updates the running minima with the newest chosen point and finds the arg-max in
//! the same pass, in parallel over fixed chunks of [`CHUNK`] points with rayon. Every running
//! minimum is computed by one thread with the same operations, and the per-chunk candidates are
//! combined with a total order (larger distance first, then lower index), so the result is
//! identical for any number of threads and any work split.
//!
//! ```
//! use bbsplat::init::fps::farthest_point_sampling;
//! use glam::Vec3;
//! let points = [Vec3::ZERO, Vec3::new(0.1, 0.0, 0.0), Vec3::new(5.0, 0.0, 0.0), Vec3::new(2.0, 0.0, 0.0)];
//! // Start at 0, then the farthest (index 2), then the one farthest from both (index 3).
//! assert_eq!(farthest_point_sampling(&points, 3).unwrap(), vec![0, 2, 3]);
//! assert_eq!(farthest_point_sampling(&points, 9).unwrap(), vec![0, 1, 2, 3]);
//! ```

use glam::Vec3;
use rayon::prelude::*;
use thiserror::Error;

/// Number of points per parallel work item. Clouds of at most this many points are processed
/// sequentially (the result is the same either way).
pub const CHUNK: usize = 8192;

/// Marks a chosen point in the running-minimum array: below every real squared distance, so it
/// is never the arg-max and `min` keeps it.
const CHOSEN: f64 = -1.0;

/// Errors of [`farthest_point_sampling`].
#[derive(Clone, Debug, PartialEq, Error)]
pub enum FpsError {
    /// A coordinate of the point at `index` is NaN or infinite.
    #[error("point {index} has a non-finite coordinate {point:?}: farthest point sampling needs finite points")]
    NonFinitePoint {
        /// Index of the first offending point in the input slice.
        index: usize,
        /// Its coordinates (x, y, z).
        point: [f32; 3],
    },
}

/// Indices of `k` points of `points` chosen by farthest point sampling from index 0, in the
/// order they were chosen. See the [module documentation](self) for the exact conventions
/// (ties, duplicates, `k ≥ N`, precision).
///
/// # Errors
///
/// [`FpsError::NonFinitePoint`] if any coordinate is NaN or infinite.
pub fn farthest_point_sampling(points: &[Vec3], k: usize) -> Result<Vec<usize>, FpsError> {
    if let Some(index) = points.iter().position(|p| !p.is_finite()) {
        return Err(FpsError::NonFinitePoint {
            index,
            point: points[index].to_array(),
        });
    }
    let n = points.len();
    if k >= n {
        return Ok((0..n).collect());
    }
    if k == 0 {
        return Ok(Vec::new());
    }

    let coords: Vec<[f64; 3]> = points.iter().map(|p| [p.x as f64, p.y as f64, p.z as f64]).collect();
    let mut min_d2 = vec![f64::INFINITY; n];
    let mut chosen = Vec::with_capacity(k);
    let mut current = 0usize;
    loop {
        chosen.push(current);
        min_d2[current] = CHOSEN;
        if chosen.len() == k {
            break;
        }
        let centre = coords[current];
        let (_, next) = if n <= CHUNK {
            update_chunk(&coords, &mut min_d2, 0, centre)
        } else {
            min_d2
                .par_chunks_mut(CHUNK)
                .enumerate()
                .map(|(c, chunk)| {
                    let start = c * CHUNK;
                    update_chunk(&coords[start..start + chunk.len()], chunk, start, centre)
                })
                .reduce(|| (f64::NEG_INFINITY, usize::MAX), better)
        };
        current = next;
    }
    Ok(chosen)
}

/// Lowers the running minima of one chunk with the distance to `centre` and returns the chunk's
/// best candidate `(squared distance, global index)` (lowest index among equal distances).
fn update_chunk(coords: &[[f64; 3]], min_d2: &mut [f64], start: usize, centre: [f64; 3]) -> (f64, usize) {
    let mut best = (f64::NEG_INFINITY, usize::MAX);
    for (i, (m, p)) in min_d2.iter_mut().zip(coords).enumerate() {
        let dx = p[0] - centre[0];
        let dy = p[1] - centre[1];
        let dz = p[2] - centre[2];
        let d2 = dx * dx + dy * dy + dz * dz;
        // Chosen points hold CHOSEN < 0 ≤ d2 and keep it.
        if d2 < *m {
            *m = d2;
        }
        if *m > best.0 {
            best = (*m, start + i);
        }
    }
    best
}

/// The better of two candidates: larger squared distance, then lower index. A total order on
/// the candidates (no NaN occurs), so the parallel reduction does not depend on its tree shape.
fn better(a: (f64, usize), b: (f64, usize)) -> (f64, usize) {
    if a.0 > b.0 || (a.0 == b.0 && a.1 < b.1) { a } else { b }
}

#[cfg(test)]
mod tests {
    use super::*;

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
    fn chunked_path_matches_sequential_path() {
        // More than one chunk: compare with a plain sequential loop on the same rule.
        let mut rng = crate::rng::Rng::new(5);
        let pts: Vec<Vec3> = (0..CHUNK * 2 + 17)
            .map(|_| Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0)))
            .collect();
        let k = 40;
        let got = farthest_point_sampling(&pts, k).unwrap();
        let coords: Vec<[f64; 3]> = pts.iter().map(|p| [p.x as f64, p.y as f64, p.z as f64]).collect();
        let mut min_d2 = vec![f64::INFINITY; pts.len()];
        let mut want = vec![0usize];
        min_d2[0] = CHOSEN;
        while want.len() < k {
            let c = coords[*want.last().unwrap()];
            let (_, next) = update_chunk(&coords, &mut min_d2, 0, c);
            min_d2[next] = CHOSEN;
            want.push(next);
        }
        assert_eq!(got, want);
    }
}
