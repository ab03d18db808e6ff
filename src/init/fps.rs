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
//! The textbook algorithm updates the running minimum distance of all `N` points after every
//! pick: `O(N·k)` work. [`farthest_point_sampling_dense`] does exactly that (in parallel over
//! fixed chunks of [`DENSE_CHUNK`] points) and is kept as the oracle.
//!
//! [`farthest_point_sampling`] returns the same indices with far less work. The points are
//! ordered along a Morton (Z-order) curve and cut into buckets of [`BUCKET`] consecutive
//! points, each with its bounding box and the maximum (and arg-max) of its running minima;
//! groups of [`GROUP`] buckets carry the union box and the best of their summaries.
//! When a point is picked, a bucket is skipped if the squared distance from the new point to
//! its box is at least the bucket's maximum running minimum: then no point in it can get
//! closer to the chosen set than it already is. The box bound is computed with the same f64
//! operations in the same order as the point distances, and rounding is monotone, so the bound
//! never exceeds a computed point distance and the skip is exact (not a heuristic). The global
//! pick is the best bucket summary (larger distance, then lower original index). Worst case
//! `O(N·k)` (e.g. every point equidistant); on scene-like clouds only the buckets near the new
//! point are touched once the covering radius has shrunk, so a step costs `O(N/(BUCKET·GROUP))`
//! group tests, the box tests of a few groups and a few bucket updates. A group is skipped when
//! its box bound is at least its best running minimum: its buckets' boxes lie inside its box,
//! so their bounds are at least as large, and their maxima at most as large.
//!
//! Memory is `O(N)`: the coordinates in f64 in Morton order (24 bytes per point), the original
//! index (8), its position (8) and the running minimum (8), plus one summary per bucket.
//!
//! Buckets are updated in parallel with rayon when a step touches at least
//! [`PARALLEL_MIN_POINTS`] points (the early steps), sequentially otherwise. Every running
//! minimum and bucket summary is computed by one thread with the same operations, and the
//! global pick is a sequential scan, so the result is identical for any number of threads.
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

/// Points per spatial bucket of [`farthest_point_sampling`].
pub const BUCKET: usize = 64;

/// Buckets per group: the second level of boxes, tested before the buckets inside.
pub const GROUP: usize = 32;

/// The identity of [`better`].
const NO_CANDIDATE: (f64, usize) = (f64::NEG_INFINITY, usize::MAX);

/// A step of [`farthest_point_sampling`] updates its buckets in parallel when they hold at
/// least this many points.
pub const PARALLEL_MIN_POINTS: usize = 1 << 14;

/// Points per parallel work item of [`farthest_point_sampling_dense`]. Clouds of at most this
/// many points are processed sequentially (the result is the same either way).
pub const DENSE_CHUNK: usize = 8192;

/// Marks a chosen point in the running-minimum array: below every real squared distance, so it
/// is never the arg-max and `min` keeps it.
const CHOSEN: f64 = -1.0;

/// Errors of [`farthest_point_sampling`].
#[derive(Clone, Debug, PartialEq, Error)]
#[non_exhaustive]
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
/// (ties, duplicates, `k ≥ N`, precision) and the bucket pruning that makes it fast.
///
/// # Errors
///
/// [`FpsError::NonFinitePoint`] if any coordinate is NaN or infinite.
pub fn farthest_point_sampling(points: &[Vec3], k: usize) -> Result<Vec<usize>, FpsError> {
    if let Some(trivial) = trivial_cases(points, k)? {
        return Ok(trivial);
    }
    let n = points.len();

    // Morton order (ties by index: a deterministic permutation).
    let order = morton_order(points);
    let coords: Vec<[f64; 3]> = order.iter().map(|&i| to_f64(points[i])).collect();
    let mut position = vec![0usize; n];
    for (pos, &i) in order.iter().enumerate() {
        position[i] = pos;
    }
    let mut buckets: Vec<Bucket> = coords
        .chunks(BUCKET)
        .zip(order.chunks(BUCKET))
        .map(|(c, o)| Bucket::new(c, o))
        .collect();
    let mut groups: Vec<Bucket> = buckets.chunks(GROUP).map(Bucket::union).collect();
    let mut min_d2 = vec![f64::INFINITY; n];
    let mut active = vec![false; buckets.len()];
    let mut active_list: Vec<usize> = Vec::with_capacity(buckets.len());

    let mut chosen = Vec::with_capacity(k);
    let mut current = 0usize;
    loop {
        chosen.push(current);
        let pos = position[current];
        min_d2[pos] = CHOSEN;
        if chosen.len() == k {
            break;
        }
        let centre = coords[pos];
        // Which buckets can change: the one holding the new point (its summary named it) and
        // those whose box is closer than their largest running minimum; a group's box and
        // summary bound those of its buckets, so a group failing the test is skipped whole.
        let chosen_bucket = pos / BUCKET;
        let mut work = 0usize;
        active_list.clear();
        for (g, group) in groups.iter().enumerate() {
            if g != chosen_bucket / GROUP && group.lower_bound(centre) >= group.best.0 {
                continue;
            }
            for (b, bucket) in buckets.iter().enumerate().skip(g * GROUP).take(GROUP) {
                if b == chosen_bucket || bucket.lower_bound(centre) < bucket.best.0 {
                    active_list.push(b);
                    work += bucket.len;
                }
            }
        }
        if work >= PARALLEL_MIN_POINTS {
            for &b in &active_list {
                active[b] = true;
            }
            buckets
                .par_iter_mut()
                .zip(min_d2.par_chunks_mut(BUCKET))
                .enumerate()
                .filter(|(b, _)| active[*b])
                .for_each(|(b, (bucket, m))| {
                    let r = b * BUCKET..b * BUCKET + m.len();
                    bucket.best = update_bucket(&coords[r.clone()], &order[r], m, centre);
                });
            for &b in &active_list {
                active[b] = false;
            }
        } else {
            for &b in &active_list {
                let r = b * BUCKET..(b * BUCKET + BUCKET).min(n);
                buckets[b].best = update_bucket(&coords[r.clone()], &order[r.clone()], &mut min_d2[r], centre);
            }
        }
        // Refresh the summaries of the groups that changed (the list is in increasing order).
        let mut last_group = usize::MAX;
        for &b in &active_list {
            let g = b / GROUP;
            if g != last_group {
                last_group = g;
                let members = &buckets[g * GROUP..((g + 1) * GROUP).min(buckets.len())];
                groups[g].best = members.iter().map(|m| m.best).fold(NO_CANDIDATE, better);
            }
        }
        current = groups.iter().map(|g| g.best).fold(NO_CANDIDATE, better).1;
    }
    Ok(chosen)
}

/// The textbook `O(N·k)` farthest point sampling: after every pick, the running minima of all
/// points are updated (in parallel over chunks of [`DENSE_CHUNK`] points). Same conventions and
/// the same result as [`farthest_point_sampling`], which it serves as the oracle for.
///
/// # Errors
///
/// [`FpsError::NonFinitePoint`] if any coordinate is NaN or infinite.
pub fn farthest_point_sampling_dense(points: &[Vec3], k: usize) -> Result<Vec<usize>, FpsError> {
    if let Some(trivial) = trivial_cases(points, k)? {
        return Ok(trivial);
    }
    let n = points.len();
    let coords: Vec<[f64; 3]> = points.iter().map(|&p| to_f64(p)).collect();
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
        let (_, next) = if n <= DENSE_CHUNK {
            update_chunk(&coords, &mut min_d2, 0, centre)
        } else {
            min_d2
                .par_chunks_mut(DENSE_CHUNK)
                .enumerate()
                .map(|(c, chunk)| {
                    let start = c * DENSE_CHUNK;
                    update_chunk(&coords[start..start + chunk.len()], chunk, start, centre)
                })
                .reduce(|| NO_CANDIDATE, better)
        };
        current = next;
    }
    Ok(chosen)
}

/// Validation and the cases that need no sampling (`k = 0`, `k ≥ N`).
fn trivial_cases(points: &[Vec3], k: usize) -> Result<Option<Vec<usize>>, FpsError> {
    if let Some(index) = points.iter().position(|p| !p.is_finite()) {
        return Err(FpsError::NonFinitePoint {
            index,
            point: points[index].to_array(),
        });
    }
    if k >= points.len() {
        return Ok(Some((0..points.len()).collect()));
    }
    if k == 0 {
        return Ok(Some(Vec::new()));
    }
    Ok(None)
}

pub(crate) fn to_f64(p: Vec3) -> [f64; 3] {
    [p.x as f64, p.y as f64, p.z as f64]
}

/// Squared distance, the one expression every distance and bound of this module uses.
#[inline]
pub(crate) fn squared(dx: f64, dy: f64, dz: f64) -> f64 {
    dx * dx + dy * dy + dz * dz
}

/// A bucket of consecutive points in Morton order.
#[derive(Clone, Debug)]
pub(crate) struct Bucket {
    len: usize,
    lo: [f64; 3],
    hi: [f64; 3],
    /// The largest running minimum in the bucket, the original index holding it (lowest on
    /// ties), as `(squared distance, index)`.
    best: (f64, usize),
}

impl Bucket {
    pub(crate) fn new(coords: &[[f64; 3]], order: &[usize]) -> Self {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for p in coords {
            for a in 0..3 {
                lo[a] = lo[a].min(p[a]);
                hi[a] = hi[a].max(p[a]);
            }
        }
        let first = order.iter().copied().min().expect("buckets are not empty");
        Self {
            len: coords.len(),
            lo,
            hi,
            best: (f64::INFINITY, first),
        }
    }

    /// The group of `members`: the union of their boxes and the best of their summaries.
    fn union(members: &[Bucket]) -> Self {
        let mut group = Bucket {
            len: 0,
            lo: [f64::INFINITY; 3],
            hi: [f64::NEG_INFINITY; 3],
            best: NO_CANDIDATE,
        };
        for m in members {
            group.len += m.len;
            for a in 0..3 {
                group.lo[a] = group.lo[a].min(m.lo[a]);
                group.hi[a] = group.hi[a].max(m.hi[a]);
            }
            group.best = better(group.best, m.best);
        }
        group
    }

    /// A lower bound of the computed squared distance from `c` to every point of the box:
    /// per axis the gap `max(lo − c, c − hi, 0)` is at most the computed `|p − c|` (rounding is
    /// monotone), and `squared` is monotone in each argument.
    #[inline]
    pub(crate) fn lower_bound(&self, c: [f64; 3]) -> f64 {
        let gap = |a: usize| (self.lo[a] - c[a]).max(c[a] - self.hi[a]).max(0.0);
        squared(gap(0), gap(1), gap(2))
    }
}

/// Lowers the running minima of one bucket with the distance to `centre` and returns its new
/// summary `(largest running minimum, lowest original index holding it)`.
fn update_bucket(coords: &[[f64; 3]], order: &[usize], min_d2: &mut [f64], centre: [f64; 3]) -> (f64, usize) {
    let mut best = NO_CANDIDATE;
    for ((m, p), &i) in min_d2.iter_mut().zip(coords).zip(order) {
        let d2 = squared(p[0] - centre[0], p[1] - centre[1], p[2] - centre[2]);
        // Chosen points hold CHOSEN < 0 ≤ d2 and keep it.
        if d2 < *m {
            *m = d2;
        }
        if *m > best.0 || (*m == best.0 && i < best.1) {
            best = (*m, i);
        }
    }
    best
}

/// Lowers the running minima of one chunk (dense version) and returns the chunk's best
/// candidate `(squared distance, global index)` (lowest index among equal distances).
fn update_chunk(coords: &[[f64; 3]], min_d2: &mut [f64], start: usize, centre: [f64; 3]) -> (f64, usize) {
    let mut best = NO_CANDIDATE;
    for (i, (m, p)) in min_d2.iter_mut().zip(coords).enumerate() {
        let d2 = squared(p[0] - centre[0], p[1] - centre[1], p[2] - centre[2]);
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
/// the candidates (no NaN occurs), so any reduction order gives the same result.
pub(crate) fn better(a: (f64, usize), b: (f64, usize)) -> (f64, usize) {
    if a.0 > b.0 || (a.0 == b.0 && a.1 < b.1) { a } else { b }
}

/// Indices of `points` sorted along a Morton curve of 21 bits per axis over the cloud's
/// bounding box (ties by index). Only the speed depends on this order, never the result.
fn morton_order(points: &[Vec3]) -> Vec<usize> {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in points {
        let p = to_f64(*p);
        for a in 0..3 {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
    }
    const CELLS: f64 = ((1u32 << 21) - 1) as f64;
    let scale: [f64; 3] = std::array::from_fn(|a| {
        let extent = hi[a] - lo[a];
        if extent > 0.0 { CELLS / extent } else { 0.0 }
    });
    let mut keyed: Vec<(u64, usize)> = points
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let p = to_f64(*p);
            let q = |a: usize| ((p[a] - lo[a]) * scale[a]).clamp(0.0, CELLS) as u64;
            (spread_bits(q(0)) | spread_bits(q(1)) << 1 | spread_bits(q(2)) << 2, i)
        })
        .collect();
    keyed.par_sort_unstable();
    keyed.into_iter().map(|(_, i)| i).collect()
}

/// Spreads the low 21 bits of `x` to every third bit.
pub(crate) fn spread_bits(x: u64) -> u64 {
    let mut x = x & 0x1f_ffff;
    x = (x | x << 32) & 0x001f_0000_0000_ffff;
    x = (x | x << 16) & 0x001f_0000_ff00_00ff;
    x = (x | x << 8) & 0x100f_00f0_0f00_f00f;
    x = (x | x << 4) & 0x10c3_0c30_c30c_30c3;
    x = (x | x << 2) & 0x1249_2492_4924_9249;
    x
}
